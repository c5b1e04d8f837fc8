"""camdirector_client.client end to end, over real loopback sockets to the fake director.

Every behaviour is checked over both transports: a grpc server and a ZeroMQ ROUTER.
"""

from __future__ import annotations

import socket
import threading
import time

import grpc
import numpy as np
import pytest

import camdirector_client as cd
from camdirector.v1 import director_pb2 as pb

from .fake_director import SLOW_TIME_S, FakeDirector, FakeGrpcServer, FakeZmqServer

TARGETS = [pb.Target(id="hero"), pb.Target(id="villain")]
TIMEOUT_S = 0.25  # client timeout in the timeout tests; the fake's slow replies take 0.5 s


@pytest.fixture(scope="module", params=["grpc", "zmq"])
def server(request):
    core = FakeDirector(slow_reply_s=2 * TIMEOUT_S)
    with (FakeGrpcServer if request.param == "grpc" else FakeZmqServer)(core) as fake:
        yield fake


@pytest.fixture
def client(server):
    with cd.connect(server.url) as client:
        yield client


def test_session_round_trip(server, client):
    with client.create_session(targets=TARGETS, seed=3, record=True) as session:
        assert session.id in server.core.sessions
        assert session.recording_path == f"{session.id}.cdrec"
        assert server.core.sessions[session.id]["request"].seed == 3
        update = session.frame(1, 0.5)
        assert (update.frame, update.time_s, update.stale) == (1, 0.5, False)
        assert cd.pose_from_msg(update.pose).position[0] == 1.0
        assert session.frame(1, 0.5).stale
        assert session.close() == 2
        assert session.close() == 2  # idempotent, no second RPC
    assert session.id not in server.core.sessions


def test_create_session_from_request(client):
    request = pb.CreateSessionRequest(targets=TARGETS, lens=pb.Lens(vertical_fov_deg=30))
    with client.create_session(request) as session:
        assert session.id
    with pytest.raises(TypeError):
        client.create_session(request, seed=1)


def test_frame_carries_states_and_packed(client):
    ids, packed = cd.pack_states(["hero", "villain"], [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], np.tile([0, 0, 0, 1.0], (2, 1)))
    with client.create_session(targets=TARGETS) as session:
        update = session.frame(1, 0.0, packed=(ids, packed))
        assert update.shot_id == 2
        np.testing.assert_array_equal(cd.pose_from_msg(update.pose).position, [1, 2, 3])
        update = session.frame(2, 0.1, states={"hero": cd.transform_msg([0, 0, 0])}, packed=(ids, packed))
        assert update.shot_id == 3
        assert session.send(pb.FrameUpdate(frame=3, time_s=0.2)).frame == 3  # session_id filled in


def test_stream_answers_in_order(client):
    with client.create_session(targets=TARGETS) as session:
        updates = (session.frame_update(i, i / 60) for i in range(1, 201))
        answers = list(session.stream(updates))
        assert [a.frame for a in answers] == list(range(1, 201))
        assert not any(a.stale for a in answers)
        # A session outlives its stream; updates without a session id get the session's.
        answers = list(session.stream([pb.FrameUpdate(frame=200), pb.FrameUpdate(frame=201)]))
        assert [(a.frame, a.stale) for a in answers] == [(200, True), (201, False)]
        assert session.close() == 202


def test_stream_stops_early(client):
    with client.create_session(targets=TARGETS) as session:
        stream = session.stream(session.frame_update(i, 0.0) for i in range(1, 10_000))
        assert [next(stream).frame for _ in range(3)] == [1, 2, 3]
        stream.close()
        assert session.frame(20_000, 1.0).frame == 20_000


def test_stream_reraises_the_callers_error(client):
    def updates():
        yield session.frame_update(1, 0.0)
        raise KeyError("engine lost its state")

    with client.create_session(targets=TARGETS) as session:
        with pytest.raises(KeyError, match="engine lost its state"):
            list(session.stream(updates()))


def test_errors_carry_status_and_message(client):
    with pytest.raises(cd.DirectorError) as caught:
        client.create_session(targets=[])
    assert caught.value.code is grpc.StatusCode.INVALID_ARGUMENT
    assert caught.value.message == "a session needs one or two targets"
    session = client.create_session(targets=TARGETS)
    session.close()
    for call in (
        lambda: session.frame(1, 0.0),
        lambda: session.update_style({}),
        lambda: list(session.stream([pb.FrameUpdate(frame=1)])),
    ):
        with pytest.raises(cd.DirectorError) as caught:
            call()
        assert caught.value.code is grpc.StatusCode.NOT_FOUND
        assert caught.value.message == f"unknown session {session.id!r}"


def test_update_style(server, client):
    with client.create_session(targets=TARGETS) as session:
        session.update_style(pb.Style(visibility=pb.ANTICIPATION, gaze_room_m=1.0))
        assert server.core.styles[session.id].visibility == pb.ANTICIPATION
        session.update_style({"max_speed_m_s": 3.0})
        assert server.core.styles[session.id].max_speed_m_s == 3.0
        assert not server.core.styles[session.id].HasField("gaze_room_m")


def test_with_block_error_is_not_hidden_by_close(server, client):
    with pytest.raises(RuntimeError, match="game crashed"):
        with client.create_session(targets=TARGETS) as session:
            del server.core.sessions[session.id]  # closing will fail with NOT_FOUND
            raise RuntimeError("game crashed")


def test_timeout_then_client_still_works(server):
    with cd.connect(server.url, timeout_s=TIMEOUT_S) as client:
        session = client.create_session(targets=TARGETS)
        started = time.monotonic()
        with pytest.raises(cd.DirectorError) as caught:
            session.frame(1, SLOW_TIME_S)
        assert caught.value.code is grpc.StatusCode.DEADLINE_EXCEEDED
        assert TIMEOUT_S * 0.8 < time.monotonic() - started < TIMEOUT_S * 1.8
        time.sleep(TIMEOUT_S * 1.2)  # the late reply has come and gone
        for frame in (2, 3):
            assert session.frame(frame, 0.0).frame == frame  # never the late reply to frame 1
        assert session.close() == 3


def test_unreachable_server_fails_fast_enough():
    with cd.connect("tcp://127.0.0.1:9", timeout_s=0.1) as client:
        with pytest.raises(cd.DirectorError) as caught:
            client.create_session(targets=TARGETS)
        assert caught.value.code is grpc.StatusCode.DEADLINE_EXCEEDED
    with cd.connect("grpc://127.0.0.1:9", timeout_s=1.0) as client:
        with pytest.raises(cd.DirectorError) as caught:
            client.create_session(targets=TARGETS)
        assert caught.value.code in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED)


def test_closed_client_raises(server):
    client = cd.connect(server.url)
    session = client.create_session(targets=TARGETS)
    client.close()
    for call in (lambda: client.create_session(targets=TARGETS), lambda: session.frame(1, 0.0), session.close):
        with pytest.raises(cd.DirectorError) as caught:
            call()
        assert caught.value.code is grpc.StatusCode.CANCELLED


def test_sessions_on_threads(client):
    errors: list[BaseException] = []

    def run():
        try:
            with client.create_session(targets=TARGETS) as session:
                for frame in range(1, 51):
                    assert session.frame(frame, frame / 60).frame == frame
                assert session.close() == 50
        except BaseException as error:  # noqa: BLE001 - reported below
            errors.append(error)

    threads = [threading.Thread(target=run) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []


def test_a_new_client_reaches_a_server_started_where_another_client_was_refused():
    """A client of this process meets a closed port and stays open; a server then starts on that
    port (a node restarted on its port, a port given out again): a new client reaches it at once.
    With gRPC's process-wide subchannel pool the new client took over the first one's connection,
    waiting to reconnect, and its first call was refused (UNAVAILABLE "Connection refused")."""
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    stale = cd.connect(f"grpc://127.0.0.1:{port}", timeout_s=5.0)
    try:
        with pytest.raises(cd.DirectorError) as refused:
            stale.create_session(targets=TARGETS)
        assert refused.value.code == grpc.StatusCode.UNAVAILABLE
        with FakeGrpcServer(port=port) as server, cd.connect(server.url, timeout_s=5.0) as fresh:
            session = fresh.create_session(targets=TARGETS)
            assert session.id in server.core.sessions
    finally:
        stale.close()
