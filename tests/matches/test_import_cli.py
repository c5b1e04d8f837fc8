"""`camdirector import-match` (matches/import_cli.py) with --map: the map is sized for the same
player as `camdirector level add` sizes a level for, a failed import adds nothing (no level, no
file), and every error names the file it is about and what is wrong with it."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from camdirector.__main__ import main
from camdirector.geometry import quake_frame
from camdirector.precompute.tracks.registry import LevelRegistry
from camdirector.precompute.tracks.track_settings import PLAYER_HEIGHT_M, PLAYER_RADIUS_M
from tests.geometry.test_bsp import write_bsp

DEMO = Path(__file__).resolve().parents[1] / "data" / "real_matches" / "1on1_milton_vs_mushi_tron_20240616-1719.mvd.gz"


@pytest.fixture()
def files(tmp_path) -> dict[str, Path]:
    """A real duel's demo, a good map (a room written as a BSP), a bad one and random bytes as a demo."""
    out = {"demo": tmp_path / "duel.mvd.gz", "map": tmp_path / "room.bsp", "bad_map": tmp_path / "broken.bsp"}
    out["demo"].write_bytes(DEMO.read_bytes())
    out["map"].write_bytes(write_bsp())
    out["bad_map"].write_bytes(np.random.default_rng(3).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    out["junk"] = tmp_path / "junk.mvd"
    out["junk"].write_bytes(np.random.default_rng(4).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    return out


def _levels(data_dir: Path) -> list[str]:
    if not data_dir.exists():
        return []
    with LevelRegistry(data_dir) as registry:
        return [record.name for record in registry.list()]


def test_level_add_and_import_match_size_a_map_for_one_player(files, tmp_path, monkeypatch, capsys):
    """Both commands precompute the map for PLAYER_HEIGHT_M and PLAYER_RADIUS_M, the Quake player
    that import-match's matches carry: one map, one camera graph, whichever adds it."""
    sizes = {}
    original = LevelRegistry.add_level

    def recording_add_level(self, name, level_path, *args, **kwargs):
        sizes[name] = (kwargs["agent_height_m"], kwargs["agent_radius_m"])
        return original(self, name, level_path, *args, **kwargs)

    monkeypatch.setattr(LevelRegistry, "add_level", recording_add_level)
    assert main(["level", "add", "by_level_add", str(files["map"]), "--data-dir", str(tmp_path / "data")]) == 0
    args = ["import-match", str(files["demo"]), "--map", str(files["map"]), "--data-dir", str(tmp_path / "data")]
    assert main([*args, "--out", str(tmp_path / "m.npz")]) == 0, capsys.readouterr().err
    assert sizes == {"by_level_add": (PLAYER_HEIGHT_M, PLAYER_RADIUS_M), "room": (PLAYER_HEIGHT_M, PLAYER_RADIUS_M)}
    assert (quake_frame.PLAYER_HEIGHT_M, quake_frame.PLAYER_RADIUS_M) == (PLAYER_HEIGHT_M, PLAYER_RADIUS_M)
    with LevelRegistry(tmp_path / "data") as registry:
        graphs = [registry.load(name) for name in ("by_level_add", "room")]
    assert graphs[0].agent_height_m == graphs[1].agent_height_m == PLAYER_HEIGHT_M
    np.testing.assert_array_equal(graphs[0].nodes_world, graphs[1].nodes_world)


def test_a_bad_demo_with_a_good_map_adds_no_level_and_writes_no_file(files, tmp_path, capsys):
    data_dir, out = tmp_path / "data", tmp_path / "out" / "m.npz"
    args = ["import-match", str(files["junk"]), "--map", str(files["map"]), "--data-dir", str(data_dir), "--out", str(out)]
    assert main(args) == 2
    assert f"{files['junk']}: " in capsys.readouterr().err
    assert _levels(data_dir) == [] and not out.exists() and not out.parent.exists()


def test_an_unwritable_match_file_adds_no_level(files, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    data_dir, out = tmp_path / "data", blocker / "m.npz"
    args = ["import-match", str(files["demo"]), "--map", str(files["map"]), "--data-dir", str(data_dir), "--out", str(out)]
    assert main(args) == 2
    assert f"{out}" in capsys.readouterr().err
    assert _levels(data_dir) == [] and blocker.read_text() == "not a folder"


def test_a_bad_map_is_reported_under_its_own_name(files, tmp_path, capsys):
    data_dir, out = tmp_path / "data", tmp_path / "m.npz"
    args = ["import-match", str(files["demo"]), "--map", str(files["bad_map"]), "--data-dir", str(data_dir), "--out", str(out)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"camdirector import-match: {files['bad_map']}: ") and "BSP" in err, err
    assert str(files["demo"]) not in err and len(err.splitlines()) == 1
    assert not data_dir.exists() and not out.exists() and not out.with_name("m.npz.part").exists()


def test_random_bytes_are_not_an_mvd_demo(files, tmp_path, capsys):
    assert main(["import-match", str(files["junk"]), "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"camdirector import-match: {files['junk']}: ") and "not an MVD demo" in err, err
    assert "truncated" not in err and len(err.splitlines()) == 1


def test_a_demo_cut_short_is_still_called_truncated(files, tmp_path, capsys):
    cut = tmp_path / "cut.mvd"
    cut.write_bytes(gzip.decompress(DEMO.read_bytes())[:100_000])
    assert main(["import-match", str(cut), "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"camdirector import-match: {cut}: ") and "truncated" in err and "not an MVD" not in err, err


def test_a_missing_demo_names_the_file_once(tmp_path, capsys):
    missing = tmp_path / "missing.mvd.gz"
    assert main(["import-match", str(missing), "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err
    assert err == f"camdirector import-match: {missing}: No such file or directory\n"
