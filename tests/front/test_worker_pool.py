"""The front's end of the socket pair against a real worker process: requests, replies, a frame's
metrics and errors cross the binary framing (worker/main.py) intact, a request far larger than
the socket's buffer gets its answer without blocking the other calls, and the requests of one turn
of the event loop go in one write; the channel's reply parser fed by hand, cut anywhere."""

from __future__ import annotations

import asyncio
import threading

import grpc
import pytest

from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.errors import DirectorError
from camdirector.front.worker_pool import WorkerPool, _Channel
from camdirector.geometry.camera import Lens
from camdirector.infra.channels import REPLY, decode_reply_tail, encode_create, encode_reply
from camdirector.pipeline.toric.compiled_maps import maps_thread
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


def _replies(count: int, body_bytes: int) -> tuple[list[tuple[int, bytes]], bytes]:
    """`count` replies (request id, body), and their bytes on the wire."""
    replies = [(i, bytes([i % 251]) * (body_bytes + i)) for i in range(count)]
    return replies, b"".join(encode_reply(i, 0, body, None) for i, body in replies)


@pytest.mark.parametrize("cut", [1, 7, REPLY.size, REPLY.size + 1, 1000, 1 << 20])
def test_the_channel_reads_replies_however_the_bytes_arrive(cut):
    """Replies split anywhere, several in one arrival, one of 300 KB over hundreds of arrivals:
    each read whole, once, in order (the channel's parser alone, fed by hand)."""
    replies, wire = _replies(5, 100)
    large, large_wire = _replies(1, 300_000)
    wire += large_wire.replace(REPLY.pack(0, 0, 0, 0.0, 0, 0, 300_000), REPLY.pack(5, 0, 0, 0.0, 0, 0, 300_000), 1)
    replies.append((5, large[0][1]))
    read: list[tuple[int, bytes]] = []
    channel = _Channel(lambda header, tail: read.append((header[0], decode_reply_tail(header, tail)[0])), lambda: None)
    for at in range(0, len(wire), cut):
        channel.data_received(wire[at : at + cut])
    assert read == replies


def test_requests_of_one_turn_go_in_one_write_and_are_all_answered(tmp_path):
    """200 requests made in one turn of the event loop reach a real worker in one write, and
    each gets its own answer."""

    async def run():
        pool = WorkerPool(ServerSettings(workers=1, data_dir=str(tmp_path)))
        await pool.start()
        try:
            channel = pool._workers[0].channel
            assert channel.transport is not None
            writes = []
            write = channel.transport.writelines
            channel.transport.writelines = lambda buffers: (writes.append(len(buffers)), write(buffers))  # type: ignore[method-assign]
            scene = build_demo_scene(seed=7, duration_s=1.0)
            unknown = [pool.call(0, "frame", f"{i:032x}", _first_frame(scene, f"{i:032x}")) for i in range(100)]
            pings = [pool.call(0, "ping", "", b"") for _ in range(100)]
            results = await asyncio.gather(*unknown, *pings, return_exceptions=True)
            return list(writes), results  # before stop() writes its own request
        finally:
            await pool.stop()

    writes, results = asyncio.run(run())
    assert writes == [600]  # 200 requests, three buffers each, one write
    assert all(isinstance(r, DirectorError) and r.code == grpc.StatusCode.NOT_FOUND for r in results[:100])
    assert results[100:] == [(b"", None)] * 100


class _Edge:
    """The one call WorkerPool.hand_inline_to makes of the compiled edge, recorded."""

    def __init__(self):
        self.handed = []

    def set_inline(self, slot, answer, idle):
        self.handed.append((slot, answer, idle))


def test_the_front_tables_idle_work_waits_for_the_edges_idle_moments(tmp_path):
    """With `workers=0` and the compiled edge, the front's table leaves a snapshot due and an
    ANTICIPATION session's deferred maps for the moments the edge's thread has nothing else to do
    (WorkerPool.idle_inline, called from native/src/edge.rs as it is about to sleep), as a worker
    does between requests; never while the loop's thread holds the table. (The compiled maps hand
    a deferred update to their maps thread; kept busy here, it has not begun this one, which the
    edge's moments take back: compiled_maps.py.)"""
    pool = WorkerPool(ServerSettings(workers=0, data_dir=str(tmp_path), checkpoint_every_frames=10))
    edge = _Edge()
    pool.hand_inline_to(edge)
    assert edge.handed == [(0, pool.answer_inline, pool.idle_inline)]
    scene = build_demo_scene(seed=7, duration_s=1.0)
    request = session_request(scene, Lens(), pb.ANTICIPATION).SerializeToString()
    asyncio.run(pool.call(0, "create", SESSION_ID, encode_create("default", request)))
    busy = threading.Event()
    blocker = maps_thread().submit(busy.wait)
    try:
        for update in frame_updates(scene, 10):
            update.session_id = SESSION_ID
            assert pool.answer_inline(SESSION_ID, update.SerializeToString()) is not None
        table = pool._inline.table
        assert table.checkpoints.load(SESSION_ID).seq == 0  # the snapshot due at the 10th frame waits
        with pool._inline_lock:  # the loop's thread has the table: the edge's moment does nothing
            assert pool.idle_inline() is False
        assert table.checkpoints.load(SESSION_ID).seq == 0
        pieces = 1
        while pool.idle_inline():
            pieces += 1
        assert pieces >= 2  # the deferred maps (ANTICIPATION), then the snapshot
    finally:
        busy.set()
    blocker.result()
    checkpoint = table.checkpoints.load(SESSION_ID)
    assert (checkpoint.seq, checkpoint.entries) == (10, [])
    assert not table.idle_work()
    asyncio.run(pool.stop())


def test_the_edges_idle_moments_leave_a_session_bound_to_the_loops_thread_alone(tmp_path):
    """A session on GL occlusion maps (their EGL context is the making thread's: thread_bound) is
    computed on the loop's thread; the edge's idle moments neither compute its deferred maps nor
    count them as waiting (which would call the edge back at once, again and again)."""
    pool = WorkerPool(ServerSettings(workers=0, data_dir=str(tmp_path)))
    pool.hand_inline_to(_Edge())
    scene = build_demo_scene(seed=7, duration_s=1.0)
    request = session_request(scene, Lens(), pb.ANTICIPATION)
    request.style.map_backend = pb.MAP_BACKEND_GL
    asyncio.run(pool.call(0, "create", SESSION_ID, encode_create("default", request.SerializeToString())))
    session = pool._inline.table.held[SESSION_ID].session
    assert session.rig.thread_bound
    waited = []
    for update in frame_updates(scene, 40):
        update.session_id = SESSION_ID
        payload = update.SerializeToString()
        assert pool.answer_inline(SESSION_ID, payload) is None  # the edge hands its frames to the loop
        asyncio.run(pool.call(0, "frame", SESSION_ID, payload))
        waited.append(session.has_deferred_work)
        assert pool.idle_inline() is False
        assert session.has_deferred_work == waited[-1]
    assert any(waited)  # there was deferred work to leave alone
    asyncio.run(pool.stop())
