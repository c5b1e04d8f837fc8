"""The TORIC rig in FRAMING_ONLY, Python against compiled: what one frame's rig.run costs (FRAMING,
MOTION and VISIBILITY) in pipeline/toric/rig.py's ToricRig and in compiled_rig.py's
CompiledToricRig (FramingCore, MotionCore and the native Scene; issue 43).

    python -m load_tests.toric_rig_native [--frames 3000] [--json FILE]

Two sessions of the demo scene (its walker among the moving obstacles, FRAMING_ONLY) on two
SessionTables, one per frame path (the server's `frame_path`), fed the same frames at 60 Hz, one
frame to each in turn. Each rig's `run` is timed alone with perf_counter_ns around the call
(INGEST, the codec and the table's bookkeeping are outside it). The floor, timed the same way in
the same frames: `empty_python`, a Python function that does nothing, and `empty_native`,
_native.theta_max (one subtraction: a compiled call's own cost). Reported: median and p99 of the
per-frame microseconds of each side's rig.run and of its three stages as the rig laps them
(the frame's stage_ms, on the session's perf_counter), the speed-up of each (report.speedup:
Python's median over the compiled one's, raw and with each side's floor taken off), and the
largest difference of the two sides' positions over the run. Prints JSON (and writes it to --json); asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import camdirector._native as native
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.camera import Lens
from camdirector.server_settings import ServerSettings
from camdirector.worker.table import SessionTable
from load_tests.report import emit, speedup, summary

WARM_UP_FRAMES = 100  # imports, caches, the compiled Scene's build on its first frame
STAGES = ("framing", "motion", "visibility")  # the rig's laps in the frame's stage_ms


def _empty(_: float) -> None:
    """The Python floor: a call that does nothing."""


def _timed(run: Callable[..., None], times_ns: list[int]) -> Callable[..., None]:
    """`run` with each call's perf_counter_ns appended to times_ns."""

    def timed(*args: object) -> None:
        start = time.perf_counter_ns()
        run(*args)
        times_ns.append(time.perf_counter_ns() - start)

    return timed


def measure(frames: int, data_dir: Path) -> tuple[dict[str, list[float]], float]:
    """(name -> per-frame microseconds of each side's rig.run, its stages' laps and the floors,
    the largest difference of the two sides' positions, metres) over `frames` frames after the
    warm-up."""
    scene = build_demo_scene(seed=7, duration_s=(frames + WARM_UP_FRAMES) / 60.0 + 1.0)
    times_ns: dict[str, list[int]] = {name: [] for name in ("rig_run_python", "rig_run_native", "empty_python", "empty_native")}
    tables = {}
    for side, frame_path in (("python", "python"), ("native", "compiled")):
        settings = ServerSettings(data_dir=str(data_dir / side), checkpoint_store="off", frame_path=frame_path)
        table = tables[side] = SessionTable(settings)
        table.create("s", session_request(scene, Lens()))
        rig = table.get("s").session.rig
        rig.run = _timed(rig.run, times_ns[f"rig_run_{side}"])  # type: ignore[method-assign]
    stage_ms: dict[str, list[float]] = {f"{stage}_{side}": [] for stage in STAGES for side in ("python", "native")}
    clock, worst_m = time.perf_counter_ns, 0.0
    for update in frame_updates(scene, frames + WARM_UP_FRAMES):
        update.session_id = "s"
        positions = []
        for side, table in tables.items():
            table.frame(update)
            state = table.get("s").session.last_state
            positions.append(state.pose.position_world)
            for stage in STAGES:
                stage_ms[f"{stage}_{side}"].append(state.stage_ms[stage])
        start = clock()
        _empty(update.time_s)
        times_ns["empty_python"].append(clock() - start)
        start = clock()
        native.theta_max(update.time_s)
        times_ns["empty_native"].append(clock() - start)
        worst_m = max(worst_m, float(np.abs(positions[0] - positions[1]).max()))
    for table in tables.values():
        table.close_all()
    per_frame_us = {name: [t / 1e3 for t in values[WARM_UP_FRAMES:]] for name, values in times_ns.items()}
    per_frame_us.update({name: [t * 1e3 for t in values[WARM_UP_FRAMES:]] for name, values in stage_ms.items()})
    return per_frame_us, worst_m


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=3000, help="timed frames")
    parser.add_argument("--json", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as data_dir:
        per_frame_us, worst_m = measure(args.frames, Path(data_dir))
    per_frame = {name: summary(values) for name, values in per_frame_us.items()}
    result = {
        "benchmark": "toric_rig_native",
        "frames": args.frames,
        "per_frame_us": per_frame,
        "speedup": {name: speedup(per_frame, name) for name in ("rig_run", *STAGES)},
        "max_position_diff_m": worst_m,
    }
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
