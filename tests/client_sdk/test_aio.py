"""camdirector_client.aio end to end, over real loopback sockets to the fake director.

Each test runs its own event loop with ``asyncio.run`` (no pytest plugin needed).
"""

from __future__ import annotations

import asyncio
import time

import grpc
import numpy as np
import pytest

import camdirector_client as cd
from camdirector.v1 import director_pb2 as pb

from .fake_director import SLOW_TIME_S, FakeDirector, FakeGrpcServer, FakeZmqServer

TARGETS = [pb.Target(id="hero")]
TIMEOUT_S = 0.25  # client timeout in the timeout test; the fake's slow replies take 0.5 s


@pytest.fixture(scope="module", params=["grpc", "zmq"])
def server(request):
    core = FakeDirector(slow_reply_s=2 * TIMEOUT_S)
    with (FakeGrpcServer if request.param == "grpc" else FakeZmqServer)(core) as fake:
        yield fake


def run(coroutine_function, *args):
    return asyncio.run(asyncio.wait_for(coroutine_function(*args), timeout=10.0))


def test_session_round_trip(server):
    async def main():
        async with cd.connect_async(server.url) as client:
            async with client.create_session(targets=TARGETS, record=True) as session:
                assert session.id in server.core.sessions
                assert session.recording_path.endswith(".cdrec")
                ids, packed = cd.pack_states(["hero"], [[1.0, 2.0, 3.0]], [[0, 0, 0, 1.0]])
                update = await session.frame(1, 0.25, packed=(ids, packed))
                assert (update.frame, update.time_s, update.shot_id) == (1, 0.25, 1)
                np.testing.assert_array_equal(cd.pose_from_msg(update.pose).position, [1, 2, 3])
                assert (await session.send(pb.FrameUpdate(frame=1))).stale
                await session.update_style({"gaze_room_m": 4.0})
                assert server.core.styles[session.id].gaze_room_m == 4.0
            assert session.id not in server.core.sessions
            assert await session.close() == 2  # idempotent: closed on leaving the block
            plain = await client.create_session(pb.CreateSessionRequest(targets=TARGETS))
            assert await plain.close() == 0

    run(main)


def test_stream_answers_in_order(server):
    async def updates(session, frames):
        for frame in frames:
            await asyncio.sleep(0)
            yield session.frame_update(frame, frame / 60)

    async def main():
        async with cd.connect_async(server.url) as client:
            async with client.create_session(targets=TARGETS) as session:
                answers = [a.frame async for a in session.stream(updates(session, range(1, 151)))]
                assert answers == list(range(1, 151))
                sync_source = [pb.FrameUpdate(frame=151), pb.FrameUpdate(frame=150)]
                answers = [(a.frame, a.stale) async for a in session.stream(sync_source)]
                assert answers == [(151, False), (150, True)]
                assert await session.close() == 152

    run(main)


def test_stream_reraises_the_callers_error(server):
    async def main():
        async def updates():
            yield session.frame_update(1, 0.0)
            raise KeyError("engine lost its state")

        async with cd.connect_async(server.url) as client:
            async with client.create_session(targets=TARGETS) as session:
                with pytest.raises(KeyError, match="engine lost its state"):
                    _ = [a async for a in session.stream(updates())]

    run(main)


def test_errors_carry_status_and_message(server):
    async def main():
        async with cd.connect_async(server.url) as client:
            with pytest.raises(cd.DirectorError) as caught:
                await client.create_session(targets=[])
            assert caught.value.code is grpc.StatusCode.INVALID_ARGUMENT
            assert caught.value.message == "a session needs one or two targets"
            session = await client.create_session(targets=TARGETS)
            await session.close()
            with pytest.raises(cd.DirectorError) as caught:
                await session.frame(1, 0.0)
            assert caught.value.code is grpc.StatusCode.NOT_FOUND
            assert caught.value.message == f"unknown session {session.id!r}"
            with pytest.raises(cd.DirectorError) as caught:
                _ = [a async for a in session.stream([pb.FrameUpdate(frame=2)])]
            assert caught.value.code is grpc.StatusCode.NOT_FOUND

    run(main)


def test_timeout_then_client_still_works(server):
    async def main():
        async with cd.connect_async(server.url, timeout_s=TIMEOUT_S) as client:
            session = await client.create_session(targets=TARGETS)
            started = time.monotonic()
            with pytest.raises(cd.DirectorError) as caught:
                await session.frame(1, SLOW_TIME_S)
            assert caught.value.code is grpc.StatusCode.DEADLINE_EXCEEDED
            assert TIMEOUT_S * 0.8 < time.monotonic() - started < TIMEOUT_S * 1.8
            await asyncio.sleep(TIMEOUT_S * 1.2)  # the late reply has come and gone
            assert [(await session.frame(f, 0.0)).frame for f in (2, 3)] == [2, 3]
            assert await session.close() == 3

    run(main)


def test_cancelled_call_leaves_the_client_usable(server):
    async def main():
        async with cd.connect_async(server.url, timeout_s=5.0) as client:
            session = await client.create_session(targets=TARGETS)
            slow = asyncio.ensure_future(session.frame(1, SLOW_TIME_S))
            await asyncio.sleep(0.05)
            slow.cancel()
            with pytest.raises(asyncio.CancelledError):
                await slow
            assert (await session.frame(2, 0.0)).frame == 2

    run(main)


def test_concurrent_sessions(server):
    async def drive(client):
        async with client.create_session(targets=TARGETS) as session:
            frames = [(await session.frame(f, f / 60)).frame for f in range(1, 41)]
            assert frames == list(range(1, 41))
            return await session.close()

    async def main():
        async with cd.connect_async(server.url) as client:
            assert await asyncio.gather(*(drive(client) for _ in range(4))) == [40] * 4

    run(main)


def test_closed_client_raises(server):
    async def main():
        client = cd.connect_async(server.url)
        session = await client.create_session(targets=TARGETS)
        await client.close()
        for call in (lambda: client.create_session(targets=TARGETS), lambda: session.frame(1, 0.0), session.close):
            with pytest.raises(cd.DirectorError) as caught:
                await call()
            assert caught.value.code is grpc.StatusCode.CANCELLED

    run(main)
