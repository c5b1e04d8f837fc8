"""The frame's wire, Python against compiled (issue 43): decoding the demo scene's frames
(worker/codec.py frame_from_msg against frame_from_wire, native/src/wire.rs) and encoding their
replies (camera_update_msg and SerializeToString against camera_update_wire and
SerializeToString), and what a FRAMING_ONLY demo session costs through a SessionTable on each
frame path.

    python -m load_tests.wire_native [--frames 2000] [--json FILE]

Two sessions of the demo scene load_tests.frame_profile streams (its walker and the moving
obstacles of a 34.7 s walk: 10 packed states, 965 bytes a frame; FRAMING_ONLY) on two
SessionTables, one per frame path (the server's `frame_path`; checkpoints and recording off), fed
the same frames at 60 Hz through the worker's Dispatcher (bytes in, bytes out), one frame to each
in turn. Per frame, timed alone with perf_counter_ns:

- decode_python / decode_native: frame_from_msg on the parsed frame, and frame_from_wire on its
  bytes (which the worker has already parsed, as here);
- encode_python / encode_native: the compiled session's state of that frame written as
  SessionTable._frame and frame_bytes write it: the reply made, compute_ms set, serialized;
- floors, timed the same way in the same frames: `empty_python`, a Python function that does
  nothing, and `empty_native`, _native.theta_max (one subtraction: a compiled call's own cost).

And each session's own figures per frame: `compute_ms` as its reply carries it (the codec, the
stages, the bookkeeping up to the reply; no checkpoint append here), the part of it outside the
stage laps (`compute_minus_stages`: where the wire and the bookkeeping are), and the wall time of
Dispatcher.handle_bytes (`table_wall`: the parse, the lookup, the serialization, the rest of
frame_bytes). The compiled path also runs the compiled TORIC rig (pipeline/toric/compiled_rig.py),
so its compute_ms falls by the rig's part too. Reported: median and p99 of each (µs) and the
speed-up of each pair (report.speedup: Python's median over the compiled one's, raw and with each
side's floor taken off). Prints JSON (and writes it to --json); asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import camdirector._native as native
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.camera import Lens
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker import codec
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.table import SessionTable
from load_tests.report import emit, speedup, summary

WARM_UP_FRAMES = 100  # imports, caches, the compiled Scene's build on its first frame
# The walk of load_tests.frame_profile's scene (its 2,000 frames and 20 warm-up, and a second),
# s: how many obstacles the demo scene has depends on it; frames past its end hold the walker still.
SCENE_S = 2020 / 60.0 + 1.0
SESSION_ID = "5f0c0d6a9c8e4a7f8a1b2c3d4e5f6a7b"  # 32 hex digits, as the server names a session
SIDES = {"python": "python", "native": "compiled"}  # the report's side -> the frame path


def _empty(_: float) -> None:
    """The Python floor: a call that does nothing."""


def _timed_ns(call: Callable[..., object], *args: object) -> int:
    start = time.perf_counter_ns()
    call(*args)
    return time.perf_counter_ns() - start


def _encode_python(state, compute_ms: float) -> bytes:
    reply = codec.camera_update_msg(state, compute_ms=0.0)
    reply.compute_ms = compute_ms
    return reply.SerializeToString()


def _encode_native(state, compute_ms: float) -> bytes:
    reply = codec.camera_update_wire(state)
    reply.compute_ms = compute_ms
    return reply.SerializeToString()


def measure(frames: int, data_dir: Path) -> tuple[dict[str, list[float]], tuple[int, int]]:
    """(name -> per-frame microseconds over `frames` frames after the warm-up, (the last frame's
    states, its bytes))."""
    scene = build_demo_scene(seed=7, duration_s=SCENE_S)
    tables: dict[str, SessionTable] = {}
    for side, frame_path in SIDES.items():
        settings = ServerSettings(data_dir=str(data_dir / side), checkpoint_store="off", frame_path=frame_path)
        tables[side] = SessionTable(settings)
        tables[side].create(SESSION_ID, session_request(scene, Lens()))
    session = tables["native"].get(SESSION_ID).session
    movable, static = session.movable_ids, session.static_ids
    names = [f"{what}_{side}" for what in ("decode", "encode", "compute", "compute_minus_stages", "table_wall") for side in SIDES]
    times_us: dict[str, list[float]] = {name: [] for name in [*names, "empty_python", "empty_native"]}
    for update in frame_updates(scene, frames + WARM_UP_FRAMES):
        update.session_id = SESSION_ID
        payload = update.SerializeToString()
        sample: dict[str, float] = {}
        for side, table in tables.items():
            requests = Dispatcher(table)
            start = time.perf_counter_ns()
            body, _ = requests.handle_bytes("frame", SESSION_ID, payload)
            sample[f"table_wall_{side}"] = (time.perf_counter_ns() - start) / 1e3
            reply = pb.CameraUpdate.FromString(body)
            sample[f"compute_{side}"] = reply.compute_ms * 1e3
            sample[f"compute_minus_stages_{side}"] = (reply.compute_ms - sum(reply.diagnostics.stage_ms.values())) * 1e3
        state = tables["native"].get(SESSION_ID).session.last_state
        ns = {
            "decode_python": _timed_ns(codec.frame_from_msg, update, movable, static),
            "decode_native": _timed_ns(codec.frame_from_wire, payload, update, movable, static),
            "encode_python": _timed_ns(_encode_python, state, 0.5),
            "encode_native": _timed_ns(_encode_native, state, 0.5),
            "empty_python": _timed_ns(_empty, update.time_s),
            "empty_native": _timed_ns(native.theta_max, update.time_s),
        }
        sample.update({name: t / 1e3 for name, t in ns.items()})
        for name, value in sample.items():
            times_us[name].append(value)
    for table in tables.values():
        table.close_all()
    return {name: values[WARM_UP_FRAMES:] for name, values in times_us.items()}, (len(update.packed_ids), len(payload))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000, help="timed frames")
    parser.add_argument("--json", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as data_dir:
        per_frame_us, (states, request_bytes) = measure(args.frames, Path(data_dir))
    per_frame = {name: summary(values) for name, values in per_frame_us.items()}
    cases = ("decode", "encode", "compute", "compute_minus_stages", "table_wall")
    result = {
        "benchmark": "wire_native",
        "frames": args.frames,
        "states_per_frame": states,
        "request_bytes": request_bytes,
        "per_frame_us": per_frame,
        "speedup": {case: speedup(per_frame, case) for case in cases},
    }
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
