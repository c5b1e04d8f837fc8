"""The TORIC rig's FRAMING and MOTION stages (FRAMING_ONLY), Python against compiled: what one
frame costs in pipeline/toric/framing.py's Framing and camera_motion.py's ToricMotion and in their
twins camdirector._native.FramingCore and MotionCore (native/src/framing.rs, motion.rs, issue 43).

    python -m load_tests.framing_motion_native [--frames 3000] [--json FILE]

Cases, each a stream of --frames frames of the demo scene's walker at 60 Hz: `one_target` (the
walker alone: B is its gaze-room point) and `two_targets` (a second target circling it). Per
frame, each side runs FRAMING and MOTION as the rig does (Python: Framing.run and ToricMotion.run
on a fresh ToricFrame; compiled: FramingCore.run and MotionCore.run), timed alone with
perf_counter_ns; the frame's FrameState is made outside the timing (the rig is handed it). Then,
separately, the frame's framing error from its pose (`error`, which the rig calls in VISIBILITY).
The floor, timed the same way in the same frames: `empty_python`, a Python function that does
nothing, and `empty_native`, _native.theta_max (one subtraction: a compiled call's own cost).
Reported per case and side: median and p99 of the per-frame microseconds; ratios: python over
native medians (the speed-up), raw and with each side's floor taken off. Prints JSON (and writes
it to --json); asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from camdirector import _native as native
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.camera import Lens
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style
from camdirector.pipeline.toric.camera_motion import ToricMotion
from camdirector.pipeline.toric.frame import ToricFrame
from camdirector.pipeline.toric.framing import Framing
from load_tests.report import emit, speedup, summary

DT_S = 1.0 / 60.0


def _empty(_: float) -> None:
    """The Python floor: a call that does nothing."""


def scene_aims(targets: int, frames: int) -> list[list[np.ndarray]]:
    """The aim points of each frame: the demo walker, and with two targets one circling it."""
    scene = build_demo_scene(seed=7, duration_s=min(120.0, frames * DT_S + 1.0))
    out = []
    for i in range(frames):
        a = scene.aim_point_world(i * DT_S)
        angle = 0.7 * i * DT_S
        b = a + np.array([3.0 * math.cos(angle), 0.5 * math.sin(0.3 * i * DT_S), 3.0 * math.sin(angle)])
        out.append([a] if targets == 1 else [a, b])
    return out


def measure(native, aims: list[list[np.ndarray]], rotation: np.ndarray) -> dict[str, list[float]]:
    """name -> per-frame microseconds of each side's stages, error and floor over the frames."""
    lens, style = Lens(), Style()
    framing, motion = Framing(lens, style, rotation), ToricMotion(style, lens)
    framing_core, motion_core = native.FramingCore(lens, style, rotation), native.MotionCore(style, lens)
    names = ("stages_python", "stages_native", "error_python", "error_native", "empty_python", "empty_native")
    times_ns: dict[str, list[int]] = {name: [] for name in names}
    clock = time.perf_counter_ns
    for i, frame_aims in enumerate(aims):
        dt_s = DT_S if i else 0.0
        state = FrameState(frame=i, time_s=i * DT_S, dt_s=dt_s, aim_points_world=frame_aims)
        start = clock()
        toric = ToricFrame()
        framing.run(state, toric)
        motion.run(state, toric)
        times_ns["stages_python"].append(clock() - start)
        start = clock()
        a, b, gaze, torus, _ = framing_core.run(frame_aims, dt_s)
        _, _, pose, _ = motion_core.run(torus, gaze, dt_s)
        times_ns["stages_native"].append(clock() - start)
        assert state.pose is not None and pose is not None  # the scene never degenerates
        start = clock()
        framing.error(state.pose, toric)
        times_ns["error_python"].append(clock() - start)
        start = clock()
        framing_core.error(pose[0], pose[1], a, b, gaze)
        times_ns["error_native"].append(clock() - start)
        start = clock()
        _empty(dt_s)
        times_ns["empty_python"].append(clock() - start)
        start = clock()
        native.theta_max(dt_s)
        times_ns["empty_native"].append(clock() - start)
    return {name: [t / 1e3 for t in values] for name, values in times_ns.items()}


def ratios(per_frame: dict[str, dict]) -> dict[str, dict]:
    """Per measure: its speed-up (report.speedup)."""
    return {name: speedup(per_frame, name) for name in ("stages", "error")}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=3000, help="timed frames per case")
    parser.add_argument("--json", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    rotation = build_demo_scene(seed=7).avatar.transform.rotation_xyzw
    result: dict = {"benchmark": "framing_motion_native", "frames": args.frames, "cases": {}}
    for case, targets in (("one_target", 1), ("two_targets", 2)):
        aims = scene_aims(targets, args.frames)
        measure(native, aims[: min(200, len(aims))], rotation)  # warm-up: imports, caches, first allocations
        per_frame = {name: summary(values) for name, values in measure(native, aims, rotation).items()}
        result["cases"][case] = {"per_frame_us": per_frame, "speedup": ratios(per_frame)}
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
