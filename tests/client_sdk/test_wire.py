"""camdirector_client.wire: URLs, request builders, ZeroMQ replies."""

from __future__ import annotations

import grpc
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import camdirector_client as cd
from camdirector.v1 import director_pb2 as pb
from camdirector_client import wire


@pytest.mark.parametrize(
    ("url", "transport", "address"),
    [
        ("grpc://127.0.0.1:50051", "grpc", "127.0.0.1:50051"),
        ("grpc://[::1]:50051", "grpc", "[::1]:50051"),
        ("grpcs://director.example:443", "grpc", "director.example:443"),
        ("tcp://localhost:5555", "zmq", "tcp://localhost:5555"),
    ],
)
def test_parse_url(url, transport, address):
    assert wire.parse_url(url) == wire.Endpoint(transport, address, tls=url.startswith("grpcs://"))


@pytest.mark.parametrize("url", ["127.0.0.1:50051", "http://h:1", "grpc://", "tcp://host", ""])
def test_parse_url_rejects(url):
    with pytest.raises(ValueError):
        wire.parse_url(url)


def test_connect_validates_arguments():
    with pytest.raises(ValueError, match="timeout_s"):
        cd.connect("grpc://127.0.0.1:1", timeout_s=0)
    with pytest.raises(ValueError, match="max_message_bytes"):
        cd.connect("grpc://127.0.0.1:1", max_message_bytes=0)


def test_grpc_channel_options():
    options = dict(wire.grpc_channel_options(1000, [("grpc.max_receive_message_length", 5), ("grpc.x", 1)]))
    assert options == {
        "grpc.max_send_message_length": 1000,
        "grpc.max_receive_message_length": 5,
        "grpc.x": 1,
        "grpc.use_local_subchannel_pool": 1,  # its own connections (test_client.py: a new client and a restarted server)
        **wire.DEFAULT_RETRY.grpc_options(),  # reconnecting and pinging as often as calls are tried again
    }
    assert options["grpc.initial_reconnect_backoff_ms"] == 100 and options["grpc.keepalive_time_ms"] == 1000


def test_create_session_request_from_keywords():
    target = pb.Target(id="hero")
    msg = wire.create_session_request(
        None,
        objects=None,
        targets=[target],
        lens=pb.Lens(vertical_fov_deg=40),
        style={"gaze_room_m": 1.5},
        seed=7,
        record=True,
    )
    assert [t.id for t in msg.targets] == ["hero"] and not msg.objects
    assert msg.lens.vertical_fov_deg == 40 and msg.style.gaze_room_m == 1.5
    assert (msg.seed, msg.record) == (7, True)
    tracks = wire.create_session_request(
        None,
        objects=None,
        targets=[target],
        lens=None,
        seed=0,
        record=False,
        style={"rig": "RIG_TRACKS", "shot_size": "SHOT_SIZE_MEDIUM"},
        level_id="arena",
    )
    assert tracks.level_id == "arena" and tracks.style.rig == pb.RIG_TRACKS


def test_create_session_request_refuses_request_and_keywords():
    request = pb.CreateSessionRequest(seed=3)
    kwargs = dict(objects=None, targets=None, lens=None, style=None, seed=0, record=False)
    assert wire.create_session_request(request, **kwargs) is request
    with pytest.raises(TypeError, match="either"):
        wire.create_session_request(request, **{**kwargs, "seed": 1})


def test_frame_update_states_and_packed():
    transform = cd.transform_msg([1, 2, 3])
    by_id = wire.frame_update("s1", 4, 0.5, states={"a": transform, "b": transform})
    assert [s.id for s in by_id.states] == ["a", "b"] and by_id.states[1].transform.position.z == 3
    as_messages = wire.frame_update("s1", 4, 0.5, states=[pb.ObjectState(id="c")])
    assert [s.id for s in as_messages.states] == ["c"]
    ids, packed = cd.pack_states(["a", "b"], np.ones((2, 3)), np.ones((2, 4)))
    for transforms in (packed, packed.reshape(2, 10), packed.tolist()):
        msg = wire.frame_update("s1", 4, 0.5, packed=(ids, transforms))
        assert (msg.session_id, msg.frame, msg.time_s) == ("s1", 4, 0.5)
        assert list(msg.packed_ids) == ids and list(msg.packed_transforms) == packed.tolist()
    with pytest.raises(ValueError, match="need 20 doubles"):
        wire.frame_update("s1", 4, 0.5, packed=(ids, packed[:-1]))


def test_zmq_reply_payload():
    assert wire.zmq_reply_payload([b"0", b"body"]) == b"body"
    with pytest.raises(cd.DirectorError) as caught:
        wire.zmq_reply_payload([b"5", b"unknown session"])
    assert (caught.value.code, caught.value.message) == (grpc.StatusCode.NOT_FOUND, "unknown session")
    with pytest.raises(cd.DirectorError, match="malformed reply: 1 frames") as caught:
        wire.zmq_reply_payload([b"0"])
    assert caught.value.code is grpc.StatusCode.INTERNAL


@settings(deadline=None, max_examples=60)
@given(
    st.integers(0, 2**64 - 1),
    st.floats(allow_nan=False),
    st.lists(st.text(max_size=8), max_size=20),
    st.data(),
)
def test_encode_frame_update_parses_as_frame_update(frame, time_s, ids, data):
    doubles = data.draw(hnp.arrays(np.float64, (len(ids), 10), elements=st.floats(allow_nan=False)))
    states = {"hero": cd.transform_msg([1, 2, 3], [0, 0, 0, 1])} if data.draw(st.booleans()) else None
    encoded = wire.encode_frame_update("s1", frame, time_s, states, (ids, doubles))
    expected = wire.frame_update("s1", frame, time_s, states, (ids, doubles))
    assert pb.FrameUpdate.FromString(encoded) == expected
    unpacked = wire.frame_update("s1", frame, time_s, states).SerializeToString()
    assert wire.encode_frame_update("s1", frame, time_s, states) == unpacked


def test_frame_deadlines_expire_when_a_stream_answers_nothing_for_the_timeout_not_when_frames_queue(monkeypatch):
    """A live server answering a backlog of frames is not hung however long its oldest frame has
    waited; one that answers nothing for timeout_s with frames in flight is (issue 41: the watchdog
    timing each frame from its sending cut unpaced streams of live servers)."""
    now = [100.0]
    monkeypatch.setattr(wire.time, "monotonic", lambda: now[0])
    deadlines = wire.FrameDeadlines(1.0)
    assert deadlines.wait_s() == 1.0  # nothing in flight
    for frame in range(1, 301):  # a caller ahead of the server: 300 frames queued at once
        deadlines.sent(frame)
    for _ in range(200):  # answered one every 10 ms: the oldest waits 2 s, but answers keep coming
        now[0] += 0.01
        deadlines.answered()
        assert deadlines.wait_s() == pytest.approx(1.0)
    assert deadlines.expired is None
    now[0] += 0.6
    assert deadlines.wait_s() == pytest.approx(0.4)
    now[0] += 0.4  # 1 s without an answer, frames in flight: hung
    assert deadlines.wait_s() == 0.0
    assert deadlines.expired is not None and "frame 201 was not answered" in deadlines.expired.message


def test_frame_deadlines_count_a_frame_sent_after_the_last_answer_from_its_sending(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(wire.time, "monotonic", lambda: now[0])
    deadlines = wire.FrameDeadlines(3.0)
    deadlines.sent(1)
    now[0] = 1.0
    deadlines.answered()
    now[0] = 10.0  # a paced caller's next frame, long after the last answer
    deadlines.sent(2)
    now[0] = 12.0
    assert deadlines.wait_s() == pytest.approx(1.0)
    assert deadlines.expired is None
