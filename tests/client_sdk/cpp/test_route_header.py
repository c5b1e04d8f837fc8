"""Against small Director servers of the tests' own, which show what a real one cannot on demand:

- every gRPC call of a session carries its `x-camdirector-route` key, the header by which a
  balancer sends all the calls of a session to one node (deploy/haproxy.py): CreateSession,
  the frame streams, UpdateStyle, TakeShot, the session created again after NOT_FOUND,
  CloseSession, and cd_client_destroy's close (the server records each call's metadata); each
  carries the protocol the SDK speaks, `camdirector-protocol`, too;
- UNAVAILABLE on every call for a while over a working connection (a balancer with no healthy
  node, a node restoring its sessions) does not make the SDK give the session up: it goes on with
  the same id once the server answers again."""

from __future__ import annotations

import re
import threading
import time
from concurrent import futures

import grpc
import pytest

from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc as pb_grpc
from camdirector.version import PROTOCOL
from tests.client_sdk.cpp.conftest import run_json

ROUTE_HEADER = "x-camdirector-route"
PROTOCOL_HEADER = "camdirector-protocol"
KEY = re.compile(r"[0-9a-f]{32}")


class RecordingDirector(pb_grpc.DirectorServicer):
    """Answers every call, and records (method, session id, route key) for each. After TakeShot
    it forgets the session: its stream ends UNAVAILABLE, the next one NOT_FOUND (as a server that
    lost it), so the SDK creates it again."""

    def __init__(self):
        self.lock = threading.Lock()
        self.calls: list[tuple[str, str, str | None]] = []
        self.created = 0
        self.forgotten: set[str] = set()
        self.protocols: set[str | None] = set()  # every call's PROTOCOL_HEADER

    def _record(self, method: str, session_id: str, context) -> None:
        metadata = dict(context.invocation_metadata())
        with self.lock:
            self.calls.append((method, session_id, metadata.get(ROUTE_HEADER)))
            self.protocols.add(metadata.get(PROTOCOL_HEADER))

    def CreateSession(self, request, context):
        with self.lock:
            self.created += 1
            session_id = f"session-{self.created}"
        self._record("CreateSession", session_id, context)
        return pb.CreateSessionResponse(session_id=session_id)

    def StreamFrames(self, request_iterator, context):
        answered = False
        for update in request_iterator:
            if not answered:
                self._record("StreamFrames", update.session_id, context)
            if update.session_id in self.forgotten:
                if answered:  # forgotten while this stream ran: the stream breaks
                    context.abort(grpc.StatusCode.UNAVAILABLE, "the server lost the session")
                context.abort(grpc.StatusCode.NOT_FOUND, f"unknown session id {update.session_id!r}")
            yield pb.CameraUpdate(
                frame=update.frame, time_s=update.time_s, pose=pb.CameraPose(rotation=pb.Quat(w=1.0), vertical_fov_deg=50.0)
            )
            answered = True

    def UpdateStyle(self, request, context):
        self._record("UpdateStyle", request.session_id, context)
        return pb.UpdateStyleResponse()

    def TakeShot(self, request, context):
        self._record("TakeShot", request.session_id, context)
        with self.lock:
            self.forgotten.add(request.session_id)
        return pb.TakeShotResponse()

    def CloseSession(self, request, context):
        self._record("CloseSession", request.session_id, context)
        return pb.CloseSessionResponse(frames=1)


class OutageDirector(RecordingDirector):
    """After `outage_after` answered frames, answers every call UNAVAILABLE for `outage_s` (the
    stream then running included), as a balancer does while it has no healthy node."""

    def __init__(self, outage_after: int = 60, outage_s: float = 2.5):
        super().__init__()
        self.answered = 0
        self.outage_after, self.outage_s = outage_after, outage_s
        self.outage_until: float | None = None
        self.create_tries = 0

    def _down(self, context) -> None:
        with self.lock:
            if self.outage_until is None and self.answered >= self.outage_after:
                self.outage_until = time.monotonic() + self.outage_s
            down = self.outage_until is not None and time.monotonic() < self.outage_until
        if down:
            context.abort(grpc.StatusCode.UNAVAILABLE, "no server available")

    def CreateSession(self, request, context):
        with self.lock:
            self.create_tries += 1
        self._down(context)
        return super().CreateSession(request, context)

    def StreamFrames(self, request_iterator, context):
        self._record("StreamFrames", "", context)
        for update in request_iterator:
            self._down(context)
            with self.lock:
                self.answered += 1
            yield pb.CameraUpdate(
                frame=update.frame, time_s=update.time_s, pose=pb.CameraPose(rotation=pb.Quat(w=1.0), vertical_fov_deg=50.0)
            )

    def CloseSession(self, request, context):
        self._record("CloseSession", request.session_id, context)
        return pb.CloseSessionResponse(frames=self.answered)


def _serve(director):
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=8))
    pb_grpc.add_DirectorServicer_to_server(director, server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    return server, f"127.0.0.1:{port}"


@pytest.fixture
def recording_server():
    director = RecordingDirector()
    server, address = _serve(director)
    yield director, address
    server.stop(grace=None)


def test_unavailable_on_every_call_for_a_while_keeps_the_session(sdk_bin):
    director = OutageDirector()
    server, address = _serve(director)
    try:
        report = run_json(sdk_bin / "sdk_check", "stream", address, "--until", "resumed", "--timeout", "20", timeout_s=60)
    finally:
        server.stop(grace=None)
    assert report["seen"] and report["answered_after"] >= 60, report
    assert report["first_session_id"] == report["last_session_id"] == "session-1", report
    assert [e["kind"] for e in report["events"]] == ["STREAMING", "DISCONNECTED", "RESUMED"], report["events"]
    stats = report["stats"]
    assert stats["recreations"] == 0 and stats["streams_opened"] >= 4, stats  # refused several times meanwhile
    # The run of refusals made the SDK try to create the session again; refused too, it kept the first.
    assert director.create_tries >= 2 and director.created == 1, (director.create_tries, director.calls)


def test_every_call_of_a_session_carries_the_same_route_key(sdk_bin, recording_server):
    director, address = recording_server
    report = run_json(sdk_bin / "sdk_check", "calls", address, timeout_s=60)
    assert report["streamed"] and report["update_style"] == "OK" and report["take_shot"] == "OK", report
    assert report["answered_after_recreation"], report
    assert report["events"] == ["STREAMING", "DISCONNECTED", "RECREATED"], report
    assert report["first_session_id"] == "session-1" and report["recreated_session_id"] == "session-2", report
    assert report["close"] == "OK" and report["other_session_id"] == "session-3", report

    calls = director.calls
    first = [c for c in calls if c[1] in ("session-1", "session-2")]
    methods = [c[0] for c in first]
    # Every kind of call, the NOT_FOUND stream and the recreation included.
    assert methods.count("CreateSession") == 2 and methods.count("StreamFrames") >= 3, calls
    assert {"UpdateStyle", "TakeShot", "CloseSession"} <= set(methods), calls
    keys = {c[2] for c in first}
    assert len(keys) == 1, calls  # one key for the session, kept when it was created again
    key = keys.pop()
    assert key is not None and KEY.fullmatch(key), key
    assert director.protocols == {str(PROTOCOL)}, director.protocols

    other = [c for c in calls if c[1] == "session-3"]
    assert [c[0] for c in other][0] == "CreateSession" and other[-1][0] == "CloseSession", calls  # destroy's
    other_keys = {c[2] for c in other}
    assert len(other_keys) == 1 and KEY.fullmatch(other_keys.pop() or "") and other[0][2] != key, calls
