"""What checkpoints cost a frame, and what a restore costs (worker/checkpointing.py).

    python -m load_tests.checkpoint_bench [--frames 600] [--json F]

One session table in this process answers the demo scene's frames (FRAMING_ONLY and
ANTICIPATION) with checkpoints off (the baseline, measured in the same run), in a folder (the
default), and in Redis (Debian's redis-server started on a free loopback port). Prints JSON: per
mode and store, the frame's median and p99 (ms) and their ratio to the baseline, the snapshot's
size (bytes), and the restore of the session by a second table after 1.5 snapshot periods
(create, snapshot, inputs since: ms).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import camdirector_client as cd
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.services import RedisServer
from camdirector.geometry.camera import Lens
from camdirector.server_settings import ServerSettings
from camdirector.worker.checkpoint_stores import dumps_state
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.table import SessionTable
from load_tests.report import emit


def _frames(scene, n: int) -> list[bytes]:
    """The demo's first n frames for session "s", serialized."""
    out = []
    for update in frame_updates(scene, n):
        update.session_id = "s"
        out.append(update.SerializeToString())
    return out


def _measure(create: bytes, frames: list[bytes], timed: int, store: str, every: int) -> dict:
    """The first `timed` frames timed; then, with checkpoints, 1.5 snapshot periods more and a
    second table (another worker) restoring the session for the frame after them."""
    with tempfile.TemporaryDirectory() as folder:
        settings = ServerSettings(data_dir=folder, checkpoint_store=store, checkpoint_every_frames=every, max_triangles=10**7)
        table = SessionTable(settings)
        requests = Dispatcher(table)
        requests.handle_bytes("create", "s", create)
        times_ms = []
        for payload in frames[:timed]:
            t0 = time.perf_counter()
            requests.handle_bytes("frame", "s", payload)
            times_ms.append((time.perf_counter() - t0) * 1e3)
        out = {"frame_ms_p50": float(np.median(times_ms)), "frame_ms_p99": float(np.percentile(times_ms, 99))}
        if store != "off":
            held = table.held["s"]
            out["snapshot_bytes"] = len(dumps_state((held.session, held.style_msg), held.session.creation_objects()))
            for payload in frames[timed:-1]:
                requests.handle_bytes("frame", "s", payload)
            other = SessionTable(settings)
            other.checkpoints.owner = "bench/2"
            t0 = time.perf_counter()
            Dispatcher(other).handle_bytes("frame", "s", frames[-1])
            out["restore_and_frame_ms"] = (time.perf_counter() - t0) * 1e3
            other.close_all()
        table.close_all()
        return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=600)
    parser.add_argument("--every", type=int, default=60, help="checkpoint_every_frames")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    scene = build_demo_scene()
    frames = _frames(scene, args.frames + args.every + args.every // 2 + 1)
    report = {"frames": args.frames, "checkpoint_every_frames": args.every, "modes": {}}
    with tempfile.TemporaryDirectory() as folder:
        redis = RedisServer(Path(folder)).start()
        try:
            for mode in ("FRAMING_ONLY", "ANTICIPATION"):
                create = session_request(
                    scene, Lens(vertical_fov_deg=50.0, aspect=16 / 9), getattr(cd.pb, mode)
                ).SerializeToString()
                rows = {
                    name: _measure(create, frames, args.frames, store, args.every)
                    for name, store in (("off", "off"), ("folder", ""), ("redis", redis.url))
                }
                for name in ("folder", "redis"):
                    rows[name]["ratio_p50_vs_off"] = rows[name]["frame_ms_p50"] / rows["off"]["frame_ms_p50"]
                report["modes"][mode] = rows
        finally:
            redis.stop()
    emit(report, args.json)


if __name__ == "__main__":
    main()
