"""Recordings made before the package move (tests/data/recordings/README.md) replay bit for bit:
every rig and visibility mode answers today what it answered then."""
from __future__ import annotations

from pathlib import Path

import pytest

from camdirector.worker.recording import read_entries, replay
from tests.precompute.tracks.tiny_levels import corridor
from tests.service.tracks_sessions import cli_add_level, obj_text

RECORDINGS = Path(__file__).resolve().parents[1] / "data" / "recordings"
TORIC_AND_MATCH = ["framing_only", "reactive", "raycast", "anticipation", "match"]


def _replayed(name: str, data_dir: Path) -> dict:
    path = RECORDINGS / f"{name}.cdrec"
    kinds = [entry.WhichOneof("entry") for entry in read_entries(path)]
    assert kinds[0] == "create" and kinds.count("camera") >= 120   # a real session, not an empty file
    return replay(path, data_dir=data_dir).as_dict()


@pytest.mark.parametrize("name", TORIC_AND_MATCH)
def test_a_recording_from_before_the_move_replays_bit_for_bit(name, tmp_path):
    report = _replayed(name, tmp_path)
    assert report["ok"], report
    assert report["frames"] == 240


def test_a_tracks_recording_from_before_the_move_replays_bit_for_bit(tmp_path):
    """The level is precomputed again from the same file, as a user's registry would hold it."""
    level_file = tmp_path / "corridor.obj"
    level_file.write_text(obj_text(corridor()))
    cli_add_level(tmp_path, "corridor", level_file)
    report = _replayed("tracks", tmp_path)
    assert report["ok"], report
    assert report["frames"] == 120
