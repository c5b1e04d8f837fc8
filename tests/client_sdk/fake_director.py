"""A tiny stand-in for the director server, for the SDK's transport tests and overhead benchmark.

One core (:class:`FakeDirector`) answers every RPC; two front ends serve it on real loopback
sockets: a grpc server (``DirectorServicer``) and a ZeroMQ ROUTER on a thread, speaking the
envelope of ``camdirector_client.wire``. The camera answers are made up but checkable:

- ``CameraUpdate.frame`` / ``time_s`` echo the request; ``shot_id`` counts the states and packed
  ids it carried; ``pose.position`` is the first packed position, or (frame, 0, 0);
- a frame not newer than the last is answered ``stale``;
- an unknown session is NOT_FOUND, a session without targets INVALID_ARGUMENT;
- a frame with ``time_s == SLOW_TIME_S`` is answered after ``slow_reply_s`` (to test timeouts).

Run ``python -m client_sdk.fake_director`` from tests/ to serve both on fixed ports.
"""

from __future__ import annotations

import itertools
import threading
import time
from concurrent import futures

import grpc
import zmq

from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc

SLOW_TIME_S = -1.0


class FakeError(Exception):
    def __init__(self, code: grpc.StatusCode, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


class FakeDirector:
    """Session bookkeeping shared by both front ends; thread-safe."""

    def __init__(self, slow_reply_s: float = 0.5) -> None:
        self.slow_reply_s = slow_reply_s
        self._ids = itertools.count(1)
        self._lock = threading.Lock()
        self.sessions: dict[str, dict] = {}
        self.styles: dict[str, pb.Style] = {}

    def create_session(self, request: pb.CreateSessionRequest) -> pb.CreateSessionResponse:
        if not request.targets:
            raise FakeError(grpc.StatusCode.INVALID_ARGUMENT, "a session needs one or two targets")
        with self._lock:
            session_id = f"s{next(self._ids)}"
            self.sessions[session_id] = {"last": None, "frames": 0, "request": request}
        name = f"{session_id}.cdrec" if request.record else ""  # as the server names it: by id, no path
        return pb.CreateSessionResponse(session_id=session_id, recording_path=name)

    def _session(self, session_id: str) -> dict:
        try:
            return self.sessions[session_id]
        except KeyError:
            raise FakeError(grpc.StatusCode.NOT_FOUND, f"unknown session {session_id!r}") from None

    def frame(self, update: pb.FrameUpdate) -> pb.CameraUpdate:
        with self._lock:
            session = self._session(update.session_id)
            stale = session["last"] is not None and update.frame <= session["last"]
            if not stale:
                session["last"] = update.frame
            session["frames"] += 1
        reply = pb.CameraUpdate(
            frame=update.frame,
            time_s=update.time_s,
            stale=stale,
            shot_id=len(update.states) + len(update.packed_ids),
            message="stale frame" if stale else "",
        )
        reply.pose.vertical_fov_deg = 50.0
        reply.pose.rotation.w = 1.0
        if update.packed_transforms:
            px, py, pz = update.packed_transforms[0:3]
            reply.pose.position.x, reply.pose.position.y, reply.pose.position.z = px, py, pz
        else:
            reply.pose.position.x = float(update.frame)
        return reply

    def update_style(self, request: pb.UpdateStyleRequest) -> pb.UpdateStyleResponse:
        with self._lock:
            self._session(request.session_id)
            self.styles[request.session_id] = request.style
        return pb.UpdateStyleResponse()

    def close_session(self, request: pb.CloseSessionRequest) -> pb.CloseSessionResponse:
        with self._lock:
            session = self._session(request.session_id)
            del self.sessions[request.session_id]
        return pb.CloseSessionResponse(frames=session["frames"])


# --- gRPC --------------------------------------------------------------------------------------


class _Servicer(director_pb2_grpc.DirectorServicer):
    def __init__(self, core: FakeDirector) -> None:
        self.core = core

    def _unary(self, method, request, context):
        try:
            return method(request)
        except FakeError as error:
            context.abort(error.code, error.message)

    def CreateSession(self, request, context):
        return self._unary(self.core.create_session, request, context)

    def Frame(self, request, context):
        if request.time_s == SLOW_TIME_S:
            time.sleep(self.core.slow_reply_s)
        return self._unary(self.core.frame, request, context)

    def StreamFrames(self, request_iterator, context):
        for update in request_iterator:
            yield self._unary(self.core.frame, update, context)

    def UpdateStyle(self, request, context):
        return self._unary(self.core.update_style, request, context)

    def CloseSession(self, request, context):
        return self._unary(self.core.close_session, request, context)


class FakeGrpcServer:
    """The fake on a grpc server at ``grpc://127.0.0.1:<port>`` (port picked by the OS)."""

    def __init__(self, core: FakeDirector | None = None, port: int = 0) -> None:
        self.core = core or FakeDirector()
        self._server = grpc.server(futures.ThreadPoolExecutor(max_workers=4))
        director_pb2_grpc.add_DirectorServicer_to_server(_Servicer(self.core), self._server)
        self.port = self._server.add_insecure_port(f"127.0.0.1:{port}")
        self.url = f"grpc://127.0.0.1:{self.port}"

    def __enter__(self) -> FakeGrpcServer:
        self._server.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._server.stop(grace=None).wait()


# --- ZeroMQ ------------------------------------------------------------------------------------

_ZMQ_RPCS = {
    b"CreateSession": (pb.CreateSessionRequest, "create_session"),
    b"Frame": (pb.FrameUpdate, "frame"),
    b"UpdateStyle": (pb.UpdateStyleRequest, "update_style"),
    b"CloseSession": (pb.CloseSessionRequest, "close_session"),
}


class FakeZmqServer:
    """The fake on a ZeroMQ ROUTER at ``tcp://127.0.0.1:<port>``, served by one thread.

    Requests are ``[identity, (b"" if REQ), rpc, payload]``; slow replies are queued and sent when
    due, without holding up other requests.
    """

    def __init__(self, core: FakeDirector | None = None, port: int = 0) -> None:
        self.core = core or FakeDirector()
        self._context = zmq.Context()
        self._socket = self._context.socket(zmq.ROUTER)
        self._socket.setsockopt(zmq.LINGER, 0)
        if port:
            self._socket.bind(f"tcp://127.0.0.1:{port}")
            self.port = port
        else:
            self.port = self._socket.bind_to_random_port("tcp://127.0.0.1")
        self.url = f"tcp://127.0.0.1:{self.port}"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="fake-zmq-director", daemon=True)
        self.requests = 0

    def __enter__(self) -> FakeZmqServer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._socket.close(linger=0)
        self._context.term()

    def _answer(self, frames: list[bytes]) -> list[bytes]:
        if len(frames) != 2:
            return [b"3", f"expected 2 frames, got {len(frames)}".encode()]
        rpc, payload = frames
        if rpc not in _ZMQ_RPCS:
            return [b"12", f"unknown rpc {rpc!r}".encode()]
        message_type, method = _ZMQ_RPCS[rpc]
        try:
            reply = getattr(self.core, method)(message_type.FromString(payload))
        except FakeError as error:
            return [str(error.code.value[0]).encode(), error.message.encode()]
        return [b"0", reply.SerializeToString()]

    def _serve(self) -> None:
        sock = self._socket
        delayed: list[tuple[float, list[bytes]]] = []
        while not self._stop.is_set():
            now = time.monotonic()
            for due, message in [d for d in delayed if d[0] <= now]:
                delayed.remove((due, message))
                sock.send_multipart(message)
            wait_ms = 20 if not delayed else max(0, min(20, int((min(d[0] for d in delayed) - now) * 1000)))
            if not sock.poll(wait_ms, zmq.POLLIN):
                continue
            frames = sock.recv_multipart()
            self.requests += 1
            envelope, body = (
                ([frames[0], b""], frames[2:])
                if len(frames) > 1 and frames[1] == b""
                else (
                    frames[:1],
                    frames[1:],
                )
            )
            reply = envelope + self._answer(body)
            slow = body[0:1] == [b"Frame"] and len(body) == 2 and pb.FrameUpdate.FromString(body[1]).time_s == SLOW_TIME_S
            if slow:
                delayed.append((time.monotonic() + self.core.slow_reply_s, reply))
            else:
                sock.send_multipart(reply)


if __name__ == "__main__":
    import sys

    grpc_port = int(sys.argv[1]) if len(sys.argv) > 1 else 50151
    zmq_port = int(sys.argv[2]) if len(sys.argv) > 2 else 50152
    with FakeGrpcServer(port=grpc_port) as g, FakeZmqServer(g.core, port=zmq_port) as z:
        print(f"serving {g.url} and {z.url}", flush=True)
        try:
            threading.Event().wait()
        except KeyboardInterrupt:
            pass
