"""The front's end of the socket pair against a real worker process: requests, replies, a frame's
metrics and errors cross the binary framing (worker/main.py) intact, and a request far
larger than the pool's stream buffer gets its answer without blocking the other calls."""

from __future__ import annotations

import asyncio

import grpc
import pytest

from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.errors import DirectorError
from camdirector.front.worker_pool import WorkerPool
from camdirector.geometry.camera import Lens
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.table import FrameMetrics

SESSION_ID = "0123456789abcdef0123456789abcdef"


def _first_frame(scene, session_id: str) -> bytes:
    update = next(frame_updates(scene, 1))
    update.session_id = session_id
    return update.SerializeToString()


async def _exchange(tmp_path):
    pool = WorkerPool(ServerSettings(workers=1, data_dir=str(tmp_path)))
    await pool.start()  # pings the worker: the ping op answers
    try:
        scene = build_demo_scene(seed=7, duration_s=1.0)
        body, metrics = await pool.call(0, "create", SESSION_ID, session_request(scene, Lens()).SerializeToString())
        created = pb.CreateSessionResponse.FromString(body)
        frame_body, frame_metrics = await pool.call(0, "frame", SESSION_ID, _first_frame(scene, SESSION_ID))
        with pytest.raises(DirectorError) as unknown:
            await pool.call(0, "frame", "f" * 32, _first_frame(scene, "f" * 32))
        # 8 MiB of garbage, 8x the stream buffer: refused by the worker's parser, and a ping sent
        # behind it is answered after it (one reader per worker, replies matched by request id)
        big = pool.call(0, "create", "b" * 32, b"\xff" * (8 << 20))
        ping = pool.call(0, "ping", "", b"")
        big_result, ping_result = await asyncio.gather(big, ping, return_exceptions=True)
        return created, metrics, pb.CameraUpdate.FromString(frame_body), frame_metrics, unknown.value, big_result, ping_result
    finally:
        await pool.stop()


def test_requests_replies_metrics_and_errors_cross_to_a_real_worker(tmp_path):
    created, create_metrics, update, metrics, unknown, big, ping = asyncio.run(_exchange(tmp_path))
    assert created.session_id == SESSION_ID and create_metrics is None
    assert isinstance(metrics, FrameMetrics) and not metrics.stale
    assert metrics.compute_ms == pytest.approx(update.compute_ms)  # the same number the client is sent
    assert set(metrics.stage_ms) >= {"ingest", "framing"} and all(ms >= 0 for ms in metrics.stage_ms.values())
    assert unknown.code == grpc.StatusCode.NOT_FOUND and "unknown session" in unknown.message
    assert isinstance(big, DirectorError) and big.code == grpc.StatusCode.INVALID_ARGUMENT
    assert ping == (b"", None)
