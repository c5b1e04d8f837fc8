"""The compiled gRPC edge (front/edge.py, native/src/edge.rs) answers as the Python front does:
the same camera for the same frames, streamed or sent as Frame calls, the same status and message
for each kind of bad stream or call, keys, revocation and the tenant's frame rate, over TLS too,
while a routed session's frames never reach the front's Python (camdirector_edge_frames)."""

from __future__ import annotations

import re
import socket
import ssl
import threading
import time

import grpc
import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from tests.front.fronts import FRONTS, counted, edge_frames, metric, servers_on_each_front, without_timings
from tests.service import wire_client as wc


def _ended(client: wc.GrpcRaw, frames) -> tuple[str, str, int]:
    """(status code name, message, replies before it) of a stream."""
    replies = 0
    try:
        for _ in client.stub.StreamFrames(iter(frames), timeout=30, metadata=client.metadata):
            replies += 1
    except grpc.RpcError as exc:
        return exc.code().name, exc.details(), replies
    return "OK", "", replies


@pytest.fixture(scope="module")
def servers():
    yield from servers_on_each_front("--grpc-front", "--max-message-bytes", str(1 << 20), transports=("grpc", "http"))


def test_a_session_streams_through_the_edge_as_through_the_python_front(servers):
    cameras = {}
    for front, server in servers.items():
        client = wc.GrpcRaw(server.grpc)
        session_id = client.call("CreateSession", wc.two_target_request(seed=3)).session_id
        before = metric(server, "camdirector_edge_frames_total")
        first = client.stream(list(wc.walk(session_id, 40)))
        second = client.stream(list(wc.walk(session_id, 20, start_frame=41)))  # a second stream of the session
        unary = [client.call("Frame", update) for update in wc.walk(session_id, 10, start_frame=61)]
        cameras[front] = [without_timings(u) for u in first + second + unary]
        # each stream's first frame opens it through the front; the rest, and the Frame calls, go straight to the worker
        assert edge_frames(server) - before == (0 if front == "python" else 68)
        assert counted(server, session_id) == (70, ["grpc"])
        client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        client.close()
    assert [u.frame for u in cameras["compiled"]] == list(range(1, 71))
    assert cameras["compiled"] == cameras["inline"] == cameras["python"]


def test_each_kind_of_bad_stream_gets_the_python_fronts_status_and_message(servers):
    answers = {}
    for front, server in servers.items():
        client = wc.GrpcRaw(server.grpc)
        first = client.call("CreateSession", wc.two_target_request()).session_id
        second = client.call("CreateSession", wc.two_target_request()).session_id
        garbage = b"\xff\xff\xff\xff garbage"
        cases = {
            "garbage first": [garbage],
            "garbage after routing": [*(u.SerializeToString() for u in wc.walk(first, 3)), garbage],
            "empty session id": [pb.FrameUpdate(frame=1).SerializeToString()],
            "unknown session": [pb.FrameUpdate(session_id="0" * 32, frame=1).SerializeToString()],
            "two sessions": [
                *(u.SerializeToString() for u in wc.walk(first, 3, start_frame=4)),
                *(u.SerializeToString() for u in wc.walk(second, 1)),
            ],
            "a bad frame after routing": [
                *(u.SerializeToString() for u in wc.walk(first, 2, start_frame=7)),
                pb.FrameUpdate(session_id=first, frame=9, time_s=float("nan")).SerializeToString(),
            ],
            "over the message limit": [
                pb.FrameUpdate(session_id=first, frame=10, packed_ids=["x" * (2 << 20)]).SerializeToString()
            ],
        }
        raw = grpc.insecure_channel(server.grpc, options=[("grpc.max_send_message_length", 64 << 20)])
        stream = raw.stream_stream("/camdirector.v1.Director/StreamFrames")
        answers[front] = {}
        for case, payloads in cases.items():
            try:
                replies = list(stream(iter(payloads), timeout=30))
                answers[front][case] = ("OK", "", len(replies))
            except grpc.RpcError as exc:  # the servers' session ids differ: named by role
                message = exc.details().replace(first, "FIRST").replace(second, "SECOND")
                answers[front][case] = (exc.code().name, message, None)
        frame_call = raw.unary_unary("/camdirector.v1.Director/Frame")
        unary_cases = {
            "Frame: garbage": garbage,
            "Frame: empty session id": pb.FrameUpdate(frame=11).SerializeToString(),
            "Frame: unknown session": pb.FrameUpdate(session_id="0" * 32, frame=11).SerializeToString(),
            "Frame: a bad frame": pb.FrameUpdate(session_id=first, frame=11, time_s=float("nan")).SerializeToString(),
            "Frame: over the message limit": cases["over the message limit"][0],
        }
        for case, payload in unary_cases.items():
            try:
                answers[front][case] = ("OK", "", len(frame_call(payload, timeout=30)))
            except grpc.RpcError as exc:
                message = exc.details().replace(first, "FIRST").replace(second, "SECOND")
                answers[front][case] = (exc.code().name, message, None)
        raw.close()
        # the sessions lost nothing: both go on where they were
        assert [u.frame for u in client.stream(list(wc.walk(first, 3, start_frame=20)))] == [20, 21, 22]
        assert [u.frame for u in client.stream(list(wc.walk(second, 2, start_frame=2)))] == [2, 3]
        client.close()
    assert answers["compiled"] == answers["inline"] == answers["python"]
    assert answers["compiled"]["two sessions"][0] == "INVALID_ARGUMENT"
    assert answers["compiled"]["garbage after routing"][0] == "INVALID_ARGUMENT"
    assert answers["compiled"]["over the message limit"][0] == "RESOURCE_EXHAUSTED"
    assert answers["compiled"]["unknown session"][0] == "NOT_FOUND"
    assert answers["compiled"]["Frame: a bad frame"][0] == "INVALID_ARGUMENT"


def test_unary_calls_health_and_reflection_pass_through_the_edge(servers):
    server = servers["compiled"]
    channel = grpc.insecure_channel(server.grpc)
    from grpc_health.v1 import health_pb2, health_pb2_grpc

    health = health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(service="camdirector.v1.Director"))
    assert health.status == health_pb2.HealthCheckResponse.SERVING
    from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc

    listed = reflection_pb2_grpc.ServerReflectionStub(channel).ServerReflectionInfo(
        iter([reflection_pb2.ServerReflectionRequest(list_services="")])
    )
    names = {s.name for reply in listed for s in reply.list_services_response.service}
    assert "camdirector.v1.Director" in names
    client = wc.GrpcRaw(server.grpc)
    call = client.stub.CreateSession.with_call(wc.two_target_request(), timeout=30)
    assert dict(call[1].initial_metadata())["camdirector-protocol"]
    session_id = call[0].session_id
    assert client.call("Frame", next(iter(wc.walk(session_id, 1)))).frame == 1
    with pytest.raises(wc.RpcFailed) as refused:
        client.call("CloseSession", pb.CloseSessionRequest(session_id="nope"))
    assert refused.value.code == grpc.StatusCode.NOT_FOUND
    streamed = client.stub.StreamFrames(iter(list(wc.walk(session_id, 2, start_frame=2))), timeout=30)
    assert [u.frame for u in streamed] == [2, 3]
    assert dict(streamed.initial_metadata())["camdirector-version"]
    client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    client.close()
    channel.close()


def _h2_frame(kind: int, stream: int, payload: bytes = b"", flags: int = 0) -> bytes:
    """One HTTP/2 frame: length (24 bits), type, flags, stream id, payload (RFC 9113 section 4.1)."""
    return len(payload).to_bytes(3, "big") + bytes((kind, flags)) + stream.to_bytes(4, "big") + payload


@pytest.mark.parametrize("front", FRONTS)
def test_a_reset_of_a_stream_the_client_never_opened_leaves_its_connection_up(servers, front):
    # gRPC's C core resets a call cancelled before its HEADERS went out (grpc/grpc 38758): h2 took
    # that for a protocol error and sent GOAWAY, failing the C++ SDK's CloseSession on the same
    # connection; grpc.aio ignores it, and the edge must too. The reset arrives split mid-header.
    host, port = servers[front].grpc.rsplit(":", 1)
    ping = b"camdir42"
    with socket.create_connection((host, int(port)), timeout=10) as conn:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        reset = _h2_frame(0x3, 3, (0x8).to_bytes(4, "big"))  # RST_STREAM CANCEL on idle stream 3
        conn.sendall(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + _h2_frame(0x4, 0) + reset[:5])
        time.sleep(0.1)
        conn.sendall(reset[5:] + _h2_frame(0x6, 0, ping))
        received, frames = b"", []
        while not any((kind == 0x6 and flags & 1) or kind == 0x7 for kind, flags, _ in frames):  # a PING's ACK, or GOAWAY
            chunk = conn.recv(65536)
            assert chunk, f"the {front} front closed the connection after {frames}"
            received += chunk
            while len(received) >= 9 and len(received) >= 9 + int.from_bytes(received[:3], "big"):
                length = int.from_bytes(received[:3], "big")
                frames.append((received[3], received[4], received[9 : 9 + length]))
                received = received[9 + length :]
    goaway = [payload for kind, _, payload in frames if kind == 0x7]
    assert not goaway, f"GOAWAY, error code {int.from_bytes(goaway[0][4:8], 'big')}"
    assert (0x6, 1, ping) in frames  # the PING sent after the reset answered on the same connection


@pytest.mark.parametrize("front", FRONTS)
def test_keys_revocation_and_the_tenants_frame_rate_hold_on_the_edge(front, tmp_path):
    """No key, a viewer's key, a key revoked mid-stream and frames beyond the tenant's rate end the
    stream as the Python front ends it; within the rate a stream goes on."""
    with ServerProcess(
        "--workers",
        "1",
        "--grpc-front",
        front,
        "--tenant-max-fps",
        "30",
        "--data-dir",
        str(tmp_path),
        transports=("grpc", "http"),
        auth=True,
    ) as server:
        http = f"http://{server.http}"

        def key(role: str) -> dict:
            return httpx.post(
                f"{http}/v1/keys", json={"role": role}, headers={"Authorization": f"Bearer {server.admin_key}"}
            ).json()

        engine = key("engine")
        client = wc.GrpcRaw(server.grpc, key=engine["key"])
        session_id = client.call("CreateSession", wc.two_target_request()).session_id
        assert _ended(wc.GrpcRaw(server.grpc), wc.walk(session_id, 2))[:2] == (
            "UNAUTHENTICATED",
            "no key: send 'authorization: Bearer KEY' (docs/security.md)",
        )
        code, message, _ = _ended(wc.GrpcRaw(server.grpc, key=key("viewer")["key"]), wc.walk(session_id, 2))
        assert code == "PERMISSION_DENIED" and "viewer" in message
        # a burst beyond 30 frames a second: the bucket holds one second's frames
        start_s = time.monotonic()
        code, message, replies = _ended(client, wc.walk(session_id, 60))
        assert (code, message) == (
            "RESOURCE_EXHAUSTED",
            f"session {session_id} sends more than 30 frames a second, its tenant's limit",
        )
        # the bucket refills while the burst runs, as fast as this machine streams it
        assert 30 <= replies <= 30 + 30 * (time.monotonic() - start_s)
        time.sleep(1.1)

        def paced(first: int):
            for n, update in enumerate(wc.walk(session_id, 100_000, start_frame=first)):
                if n == 20:
                    threading.Thread(
                        target=lambda: httpx.delete(
                            f"{http}/v1/keys/{engine['id']}", headers={"Authorization": f"Bearer {server.admin_key}"}
                        )
                    ).start()
                time.sleep(1 / 25)
                yield update

        code, message, replies = _ended(client, paced(100))
        assert (code, message) == ("UNAUTHENTICATED", f"key {engine['id']} was revoked")
        assert 20 <= replies < 45  # within the revocation's round trip and the poll (0.25 s)
        client.close()


def test_over_tls_the_edge_answers_a_trusting_client_and_refuses_a_plaintext_one(tls_files):
    with ServerProcess(
        "--workers",
        "1",
        "--tls-cert",
        str(tls_files.cert),
        "--tls-key",
        str(tls_files.key),
        transports=("grpc", "http"),
        auth=True,
    ) as server:
        trusted = wc.GrpcRaw(server.grpc, key=server.admin_key, ca_file=tls_files.ca_cert)
        session_id = trusted.call("CreateSession", wc.two_target_request()).session_id
        assert [u.frame for u in trusted.stream(list(wc.walk(session_id, 20)))] == list(range(1, 21))
        plain = wc.GrpcRaw(server.grpc, key=server.admin_key)
        code, _, replies = _ended(plain, wc.walk(session_id, 2, start_frame=21))
        assert (code, replies) == ("UNAVAILABLE", 0)
        plain.close()
        time.sleep(0.6)
        trusting = ssl.create_default_context(cafile=str(tls_files.ca_cert))
        metrics = httpx.get(
            f"https://{server.http}/metrics", verify=trusting, headers={"Authorization": f"Bearer {server.admin_key}"}
        ).text
        assert re.search(r"^camdirector_edge_frames_total 19\.0$", metrics, re.M)  # the first opened the stream
        trusted.close()
