"""Recordings made before the package move (tests/data/recordings/README.md) replay bit for bit:
every rig and visibility mode answers today what it answered then, on the Python frame path that
made them (the compiled path agrees with it within 1e-9, not to the bit).

Bit for bit is defined on the kind of machine that made them: numpy's SIMD paths, OpenBLAS's
kernels, glibc's libm, llvmpipe's JIT and Embree's ISA are chosen by the CPU, and their last bits
differ between CPUs (the demo's own trajectory differs between this project's machines;
tests/worker/machine_kinds.py plays other CPUs' kernels). `machine.json` beside the recordings
says which machine made them; elsewhere the test skips and says why. The compiled path's
recordings replay on any machine (test_recordings_across_machines.py)."""

from __future__ import annotations

import json
import platform
import subprocess
from pathlib import Path

import numpy as np
import pytest

from camdirector.worker.recording import read_entries
from camdirector.worker.replay import replay
from tests.precompute.tracks.tiny_levels import corridor
from tests.service.tracks_sessions import cli_add_level, obj_text

RECORDINGS = Path(__file__).resolve().parents[1] / "data" / "recordings"
TORIC_AND_MATCH = ["framing_only", "reactive", "raycast", "anticipation", "match"]


def machine() -> dict:
    """What decides the last bits of a frame's floats on this machine (module docstring)."""
    cpu = next(
        (
            line.split(":", 1)[1].strip()
            for line in Path("/proc/cpuinfo").read_text().splitlines()
            if line.startswith("model name")
        ),
        platform.processor(),
    )
    mesa = (
        subprocess.run(["dpkg-query", "-W", "-f", "${Version}", "libgl1-mesa-dri"], capture_output=True, text=True).stdout
        if Path("/usr/bin/dpkg-query").exists()
        else ""
    )
    return {
        "cpu": cpu,
        "numpy_simd": np.show_config(mode="dicts")["SIMD Extensions"]["found"],
        "numpy": np.__version__,
        "mesa": mesa,
    }


@pytest.fixture(autouse=True)
def same_kind_of_machine():
    made_on = json.loads((RECORDINGS / "machine.json").read_text())
    here = machine()
    if here != made_on:
        pytest.skip(
            f"the recordings were made on {made_on}, this machine is {here}: a bit-for-bit replay is "
            "only defined on the kind of machine that made them"
        )


def _replayed(name: str, data_dir: Path) -> dict:
    path = RECORDINGS / f"{name}.cdrec"
    kinds = [entry.WhichOneof("entry") for entry in read_entries(path)]
    assert kinds[0] == "create" and kinds.count("camera") >= 120  # a real session, not an empty file
    return replay(path, data_dir=data_dir, frame_path="python").as_dict()


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
