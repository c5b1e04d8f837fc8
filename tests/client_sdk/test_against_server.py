"""The SDK against a real server process, sync and async, over gRPC and ZeroMQ."""

from __future__ import annotations

import asyncio

import grpc
import numpy as np
import pytest

import camdirector_client as cd
from camdirector.version import PROTOCOL
from camdirector.worker.recording import read_entries
from tests.service.wire_client import two_target_request


@pytest.fixture(params=["grpc", "zmq"])
def url(request, server):
    return server.url(request.param)


def _packed_walk(n: int):
    for i in range(1, n + 1):
        t = i / 60
        yield (
            i,
            t,
            cd.pack_states(
                ["a", "cart"], np.array([[np.sin(t), 0.9, t], [-2 + t, 0.5, 2.0]]), np.array([[0, 0, 0, 1.0], [0, 0, 0, 1.0]])
            ),
        )


def test_sync_session_frames_stream_style_close(url):
    with cd.connect(url) as client:
        with client.create_session(two_target_request(seed=4)) as session:
            updates = [session.frame(i, t, packed=p) for i, t, p in _packed_walk(30)]
            assert [u.frame for u in updates] == list(range(1, 31))
            streamed = list(session.stream(session.frame_update(i + 30, t + 0.5, packed=p) for i, t, p in _packed_walk(30)))
            assert [u.frame for u in streamed] == list(range(31, 61))
            pose = cd.pose_from_msg(streamed[-1].pose)
            assert pose.matrix().shape == (4, 4) and abs(np.linalg.det(pose.matrix()[:3, :3]) - 1) < 1e-9
            session.update_style({"screen_a": {"x": -0.5}, "screen_b": {"x": 0.5}})
            assert session.frame(61, 1.1).cut
        assert session.close() == 61
        with pytest.raises(cd.DirectorError) as err:
            session.frame(62, 1.2)
        assert err.value.code == grpc.StatusCode.NOT_FOUND


def test_async_session(url):
    async def main():
        async with cd.connect_async(url) as client:
            async with client.create_session(two_target_request(seed=4)) as session:
                updates = [await session.frame(i, t, packed=p) for i, t, p in _packed_walk(20)]
                with pytest.raises(cd.DirectorError) as err:
                    await session.frame(21, 0.4, states=[cd.pb.ObjectState(id="ghost")])
                assert err.value.code == grpc.StatusCode.NOT_FOUND and "ghost" in err.value.message
                return updates

    updates = asyncio.run(main())
    assert [u.frame for u in updates] == list(range(1, 21)) and updates[0].cut


def test_match_session_take_shot_sync_and_async(url):
    from tests.service.test_match_sessions import frames, match_request

    request = match_request(delay_s=0.0)
    with cd.connect(url) as client:
        kwargs = dict(targets=request.targets, style=request.style, delay_s=0.5, seed=3)
        with client.create_session(**kwargs) as session:
            list(session.stream(frames("", 30)))
            shot = session.take_shot(["a0"])
            assert list(shot.subject_ids) == ["a0"] and shot.kind == cd.pb.SHOT_FOLLOW
            replies = list(session.stream(frames("", 30, start=30)))
            assert list(replies[-1].shot.subject_ids) == ["a0"]
            assert not session.take_shot(release=True).subject_ids
            with pytest.raises(cd.DirectorError) as err:
                session.take_shot(["nobody"])
            assert err.value.code == grpc.StatusCode.NOT_FOUND

    async def run_async():
        async with cd.connect_async(url) as client:
            async with client.create_session(**kwargs) as session:
                for update in frames("", 20):
                    await session.send(update)
                shot = await session.take_shot(["a0", "b0"], cd.pb.SHOT_GROUP)
                assert shot.kind == cd.pb.SHOT_GROUP

    asyncio.run(run_async())


def _said_protocol(server, session) -> int:
    """The client_protocol the server received: its recording's CreateSessionRequest (the session closed)."""
    return next(read_entries(server.data_dir / "recordings" / session.recording_path)).create.client_protocol


def test_sync_and_async_sessions_say_the_protocol(url, server):
    request = two_target_request(seed=4, record=True)  # client_protocol 0: the SDK says its own
    with cd.connect(url) as client:
        with client.create_session(request) as from_request:
            pass
        with client.create_session(targets=request.targets, objects=request.objects, record=True) as from_keywords:
            pass
    assert _said_protocol(server, from_request) == _said_protocol(server, from_keywords) == PROTOCOL

    async def run_async():
        async with cd.connect_async(url) as client:
            async with client.create_session(two_target_request(record=True)) as session:
                return session

    assert _said_protocol(server, asyncio.run(run_async())) == PROTOCOL


def _refused_as_newer(error: cd.DirectorError) -> bool:
    return (
        error.code == grpc.StatusCode.FAILED_PRECONDITION
        and f"protocol {PROTOCOL + 1}," in error.message
        and f"protocol {PROTOCOL}:" in error.message
        and "upgrade the server" in error.message
    )


def test_a_request_claiming_a_newer_protocol_is_refused_and_the_client_goes_on(url):
    newer = two_target_request(client_protocol=PROTOCOL + 1)  # said by the caller: the SDK keeps it
    with cd.connect(url) as client:
        with pytest.raises(cd.DirectorError) as refused:
            client.create_session(newer)
        assert _refused_as_newer(refused.value), refused.value
        with client.create_session(two_target_request()) as session:
            assert session.frame(1, 1 / 60).frame == 1

    async def run_async():
        async with cd.connect_async(url) as client:
            with pytest.raises(cd.DirectorError) as refused:
                await client.create_session(newer)
            async with client.create_session(two_target_request()) as session:
                return refused.value, (await session.frame(1, 1 / 60)).frame

    error, answered = asyncio.run(run_async())
    assert _refused_as_newer(error) and answered == 1, error


def test_an_sdk_of_a_newer_protocol_is_told_so(url, monkeypatch):
    """The SDK's own PROTOCOL raised in-process, as in a later release: over ZeroMQ, with no
    metadata, the request's client_protocol alone tells the server."""
    monkeypatch.setattr(cd.wire, "PROTOCOL", PROTOCOL + 1)
    with cd.connect(url) as client, pytest.raises(cd.DirectorError) as refused:
        client.create_session(two_target_request())
    assert _refused_as_newer(refused.value), refused.value
