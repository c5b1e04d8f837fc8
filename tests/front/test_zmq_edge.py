"""The compiled edge's ZeroMQ side (native/src/zmq_edge.rs, front/edge.py) answers as the Python
front does: the same camera for the same Frame requests from DEALER and REQ clients, the same reply
to each kind of bad request, keys over CURVE, revocation and the tenant's frame rate, while a routed
session's Frame requests never reach the front's Python (camdirector_edge_frames)."""

from __future__ import annotations

import time

import httpx
import pytest
import zmq

from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from tests.front.fronts import FRONTS, counted, edge_frames, metric, servers_on_each_front, without_timings
from tests.service import wire_client as wc

LIMIT = 1 << 20  # the servers' max_message_bytes


def _req_call(address: str, rpc: str, request) -> list[bytes]:
    """One request from a REQ socket (its empty delimiter frame added by libzmq)."""
    sock = zmq.Context.instance().socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, 30000)
    sock.connect(address)
    sock.send_multipart([rpc.encode(), request.SerializeToString()])
    reply = sock.recv_multipart()
    sock.close()
    return reply


@pytest.fixture(scope="module")
def servers():
    yield from servers_on_each_front("--zmq-front", "--max-message-bytes", str(LIMIT), transports=("zmq", "http"))


def test_a_session_framed_through_the_edge_as_through_the_python_front(servers):
    """The edge serves ZeroMQ without gRPC here (transports zmq and http only)."""
    cameras = {}
    for front, server in servers.items():
        client = wc.ZmqRaw(server.zmq)
        session_id = client.call("CreateSession", wc.two_target_request(seed=3)).session_id
        before = metric(server, "camdirector_edge_frames_total")
        dealer = client.stream(list(wc.walk(session_id, 40)))
        req = []
        for update in wc.walk(session_id, 10, start_frame=41):
            code, body = _req_call(server.zmq, "Frame", update)
            assert code == b"0"
            req.append(pb.CameraUpdate.FromString(body))
        cameras[front] = [without_timings(u) for u in dealer + req]
        # the first frame goes through the front, which lets the caller in and routes the session
        assert edge_frames(server) - before == (0 if front == "python" else 49)
        assert counted(server, session_id) == (50, ["zmq"])
        client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        client.close()
    assert [u.frame for u in cameras["compiled"]] == list(range(1, 51))
    assert cameras["compiled"] == cameras["inline"] == cameras["python"]


def test_each_kind_of_bad_request_gets_the_python_fronts_reply(servers):
    answers = {}
    for front, server in servers.items():
        client = wc.ZmqRaw(server.zmq)
        first = client.call("CreateSession", wc.two_target_request()).session_id
        second = client.call("CreateSession", wc.two_target_request()).session_id
        assert len(client.stream(list(wc.walk(first, 3)))) == 3  # routed: its caller let in
        garbage = b"\xff\xff\xff\xff garbage"
        cases = {
            "garbage": [b"Frame", garbage],
            "empty session id": [b"Frame", pb.FrameUpdate(frame=4).SerializeToString()],
            "unknown session": [b"Frame", pb.FrameUpdate(session_id="0" * 32, frame=1).SerializeToString()],
            "a bad frame of a routed session": [
                b"Frame",
                pb.FrameUpdate(session_id=first, frame=4, time_s=float("nan")).SerializeToString(),
            ],
            "over the message limit": [
                b"Frame",
                pb.FrameUpdate(session_id=first, frame=4, packed_ids=["x" * (LIMIT + 10)]).SerializeToString(),
            ],
            "one frame": [b"Frame"],
            "five frames": [b"Frame", b"", b"", b"", b""],
            "an unknown RPC": [b"Framed", next(iter(wc.walk(first, 1, start_frame=4))).SerializeToString()],
            "a stale frame of a routed session": [b"Frame", next(iter(wc.walk(second, 1, start_frame=5))).SerializeToString()],
        }
        answers[front] = {}
        for case, frames in cases.items():
            code, message = client.send_raw(frames)
            if code == b"0":
                answers[front][case] = ("0", pb.CameraUpdate.FromString(message).frame)
            else:  # the servers' session ids differ: named by role
                answers[front][case] = (code.decode(), message.decode().replace(first, "FIRST").replace(second, "SECOND"))
        # the sessions lost nothing: both go on where they were
        assert [u.frame for u in client.stream(list(wc.walk(first, 3, start_frame=20)))] == [20, 21, 22]
        assert [u.frame for u in client.stream(list(wc.walk(second, 2, start_frame=6)))] == [6, 7]
        client.close()
    assert answers["compiled"] == answers["inline"] == answers["python"]
    assert answers["compiled"]["garbage"][0] == "3"  # INVALID_ARGUMENT
    assert answers["compiled"]["a bad frame of a routed session"][0] == "3"
    assert answers["compiled"]["over the message limit"][0] == "8"  # RESOURCE_EXHAUSTED
    assert answers["compiled"]["unknown session"][0] == "5"  # NOT_FOUND
    assert answers["compiled"]["an unknown RPC"][0] == "12"  # UNIMPLEMENTED


def frames_until_refused(caller: wc.ZmqRaw, frames, most: int = 600) -> tuple[list[float], list[bytes]]:
    """Frames sent one after another until one is refused: each answered frame's reply time in
    seconds since the first was sent, and the refusal (code, message)."""
    answered_s: list[float] = []
    start_s = time.monotonic()
    for _ in range(most):
        reply = caller.send_raw([b"Frame", next(frames).SerializeToString(), caller.key_frame[0]])
        if reply[0] != b"0":
            return answered_s, reply
        answered_s.append(time.monotonic() - start_s)
    raise AssertionError(f"{most} frames in {answered_s[-1]:.1f} s and none refused")


@pytest.mark.parametrize("front", FRONTS)
def test_keys_revocation_and_the_tenants_frame_rate_hold_on_the_edge(front, tmp_path):
    """Over CURVE: no key, a viewer's key, frames beyond the tenant's rate and a key revoked after
    its session was routed get the Python front's replies; the session goes on within the rate."""
    with ServerProcess(
        "--workers",
        "1",
        "--zmq-front",
        front,
        "--tenant-max-fps",
        "30",
        "--data-dir",
        str(tmp_path),
        transports=("zmq", "http"),
        auth=True,
    ) as server:
        http = f"http://{server.http}"
        admin = {"Authorization": f"Bearer {server.admin_key}"}

        def key(role: str) -> dict:
            return httpx.post(f"{http}/v1/keys", json={"role": role}, headers=admin).json()

        def client(key: str | None) -> wc.ZmqRaw:
            return wc.ZmqRaw(server.zmq, key=key, server_key=server.zmq_server_key)

        engine = key("engine")
        caller = client(engine["key"])
        session_id = caller.call("CreateSession", wc.two_target_request()).session_id
        assert len(caller.stream(list(wc.walk(session_id, 2)))) == 2  # routed, its caller let in
        frames = iter(wc.walk(session_id, 100_000, start_frame=3))
        stranger = client(None)
        assert stranger.send_raw([b"Frame", next(frames).SerializeToString()]) == [
            b"16",
            b"no key: send 'authorization: Bearer KEY' (docs/security.md)",
        ]
        viewer = client(key("viewer")["key"])
        code, message = viewer.send_raw([b"Frame", next(frames).SerializeToString(), *viewer.key_frame])
        assert code == b"7" and b"viewer" in message  # PERMISSION_DENIED
        time.sleep(1.1)  # a full bucket: one second's frames
        answered_s, refused = frames_until_refused(caller, frames)
        # The bucket refills at 30 a second while the burst runs, as fast as this machine sends it:
        # each answered frame is held against the frames the rate allows by its reply, and the first
        # refusal comes only once a full bucket's worth has been answered.
        assert len(answered_s) >= 30
        assert all(k + 1 <= 30 + 30 * at_s for k, at_s in enumerate(answered_s)), answered_s
        assert refused == [b"8", f"session {session_id} sends more than 30 frames a second, its tenant's limit".encode()]
        time.sleep(1.1)
        assert caller.send_raw([b"Frame", next(frames).SerializeToString(), caller.key_frame[0]])[0] == b"0"
        assert httpx.delete(f"{http}/v1/keys/{engine['id']}", headers=admin).status_code == 200
        deadline = time.monotonic() + 5
        while (reply := caller.send_raw([b"Frame", next(frames).SerializeToString(), caller.key_frame[0]]))[0] == b"0":
            assert time.monotonic() < deadline, "the revoked key still frames"
            time.sleep(0.05)
        assert reply == [b"16", f"key {engine['id']} was revoked".encode()]
        if front == "compiled":
            assert metric(server, "camdirector_edge_frames_total", admin) > 30
        for sock in (caller, stranger, viewer):
            sock.close()
        assert server.alive()
