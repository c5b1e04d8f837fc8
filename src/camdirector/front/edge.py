"""The compiled edge's Python side (issue 43, step 5; native/src/edge.rs, native/src/zmq_edge.rs;
docs/frame_path.md).

The edge runs Rust on its own thread in this process. With `grpc_front compiled` it serves the
node's gRPC port (HTTP/2) and answers StreamFrames and Frame itself: a frame of a session routed to
it (SessionRouter.route_to_edge) goes straight to the session's worker over the worker's frame
socket (front/worker_pool.py) and back, with no Python here; with `--workers 0`, where this
process holds the sessions, the edge computes it on its own thread (WorkerPool.answer_inline), with
no hop. Every other call it passes through to the usual grpc.aio server (grpc_service.py), which
listens on a Unix socket in a private folder. With the node's certificate (`--tls-cert`,
`--tls-key`) the edge serves TLS itself. With `zmq_front compiled` it also reads and writes the
ZeroMQ socket zmq_service.py made: a Frame request of a session routed to it, from a caller let
in, goes to the worker the same way; every other request is handed here whole and answered by
ZmqTransport.answer.

This module answers what the edge asks (its events, announced by a byte on a socket pair the loop
watches): a caller, by its key (access/guard.py), the first time the edge sees its metadata (it
remembers the callers let in until their key is revoked); a stream's first frame (the session
adopted or restored, counted as streaming: SessionRouter.stream_opened), after which the session
is routed to the edge; any frame of a session not routed there; a stream's end; a ZeroMQ request
(after a Frame answered, its caller is let in and its session routed). Errors are answered as
grpc_service.py and zmq_service.py answer them, with the same codes, messages and metrics. What the
edge answered alone is read back every DRAIN_S into the front's metrics and the sessions' counts.
"""

from __future__ import annotations

import asyncio
import logging
import os
import shutil
import socket
import tempfile
import time
from pathlib import Path

import grpc

from camdirector import _native
from camdirector.access.guard import Guard
from camdirector.errors import DirectorError, status_code
from camdirector.front.grpc_service import SERVER_METADATA, TRANSPORT, start_grpc
from camdirector.front.router import RESEND_BURST_S, SessionRouter, named_session
from camdirector.front.session_calls import RPCS
from camdirector.front.zmq_service import TRANSPORT as ZMQ
from camdirector.front.zmq_service import ZmqTransport
from camdirector.infra.channels import frame_metrics

log = logging.getLogger("camdirector.edge")

DRAIN_S = 0.25  # how often what the edge answered alone reaches the metrics and the sessions' counts, s
# (transport, RPC) of a frame the edge answered, by its `via` (native/src/edge.rs's Via; a gRPC
# frame's is whether it was a Frame call's)
_VIA = ((TRANSPORT, "StreamFrames"), (TRANSPORT, "Frame"), (ZMQ, "Frame"))


class EdgeFront:
    """The edge, its grpc.aio server behind it, and the answers to its events."""

    def __init__(self, router: SessionRouter, guard: Guard):
        self.router = router
        self.guard = guard
        self.metrics = router.metrics
        self.edge: _native.Edge | None = None
        self.zmq: ZmqTransport | None = None  # the ZeroMQ socket's requests the edge hands here
        self._inner: grpc.aio.Server | None = None
        self._folder: str | None = None
        self._wake: socket.socket | None = None
        self._tasks: set[asyncio.Task] = set()
        self._drainer: asyncio.Task | None = None

    async def start(self, grpc_address: str | None, zmq: ZmqTransport | None) -> str | None:
        """Serves gRPC on `grpc_address` (HOST:PORT; port 0 picks one) when given, and `zmq`'s
        socket when given and its libzmq can be shared (ZmqTransport.hand_over; otherwise that
        socket is started as Python's). Returns the bound gRPC HOST:PORT."""
        settings = self.router.settings
        inner_path = ""
        if grpc_address is not None:
            self._folder = tempfile.mkdtemp(prefix="camdirector-grpc-")  # mode 0700: the inner server is this user's
            inner_path = os.path.join(self._folder, "grpc.sock")
            self._inner, _ = await start_grpc(self.router, f"unix:{inner_path}", self.guard)
        self._wake, edge_end = socket.socketpair()
        self._wake.setblocking(False)
        edge = self.edge = _native.Edge(
            grpc_address,
            inner_path,
            edge_end.detach(),
            list(SERVER_METADATA),
            settings.max_message_bytes,
            self.guard.enabled,
            settings.tenant_max_fps,
            settings.tenant_max_fps * RESEND_BURST_S,
            (Path(settings.tls_cert).read_bytes(), Path(settings.tls_key).read_bytes()) if settings.tls else None,
        )
        asyncio.get_running_loop().add_reader(self._wake.fileno(), self._pump)
        self.guard.on_revoked.append(edge.revoke)
        self.router.attach_edge(edge, self.drain)
        pool = self.router.pool
        if pool.inline:  # the front holds the sessions: the edge computes their frames on its thread
            pool.hand_inline_to(edge)
        else:
            pool.attach_frame_sink(lambda slot, sock: edge.set_worker(slot, sock.detach()))
        self._drainer = asyncio.create_task(self._drain_forever())
        if zmq is not None:
            if zmq.hand_over(edge):
                self.zmq = zmq
            else:
                zmq.start()
        if grpc_address is None:
            return None
        host, _, _ = grpc_address.rpartition(":")
        return f"{host}:{edge.port}"

    async def stop(self) -> None:
        if self._drainer is not None:
            self._drainer.cancel()
        if self._wake is not None:
            asyncio.get_running_loop().remove_reader(self._wake.fileno())
        if self.edge is not None:
            self.edge.stop()
            self.drain()
        if self._inner is not None:
            await self._inner.stop(grace=1.0)
        for task in list(self._tasks):
            task.cancel()
        if self._wake is not None:
            self._wake.close()
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)

    def _pump(self) -> None:
        """The edge has events: each answered (in a task, when it has to wait)."""
        assert self._wake is not None and self.edge is not None
        try:
            while self._wake.recv(4096):
                pass
        except BlockingIOError:
            pass
        for event in self.edge.take_events():
            if event[0] == "closed":
                self.router.stream_closed(event[1])
                continue
            task = asyncio.create_task(self._answer_zmq(*event[1:]) if event[0] == "zmq" else self._answer(event))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)

    async def _answer(self, event: tuple) -> None:
        assert self.edge is not None
        kind, token = event[0], event[1]
        session_id = None
        opened = False
        t0 = time.perf_counter()
        try:
            if kind == "auth":  # a stream's or a Frame call's: the same verb, from the cache of keys
                need = RPCS["StreamFrames"]
                identity = await self.guard.authorize_async(event[2], need.verb, fresh=need.fresh)
                self.edge.answer(token, 0, "", b"", identity.key_id, identity.tenant, False)
                return
            session_id, tenant, payload = event[2], event[3], event[4]
            if kind == "open":
                await self.router.stream_opened(session_id, tenant)
                opened = True
            body = await self.router.frame(payload, session_id, TRANSPORT, tenant)
            self.router.route_to_edge(session_id)
            self.metrics.labelled(self.metrics.request, TRANSPORT, _VIA[kind == "unary"][1]).observe(time.perf_counter() - t0)
            self.edge.answer(token, 0, "", body, None, tenant, opened)
        except Exception as exc:  # as grpc_service.py answers it (Guard.refusal)
            self._refuse(token, self.guard.refusal(exc, _VIA[kind == "unary"][1], lambda: session_id, log), opened)

    async def _answer_zmq(self, token: int, parts: list[bytes]) -> None:
        """A ZeroMQ request the edge handed here, answered as the Python front answers it; after a
        Frame answered, its caller is let in and its session routed to the edge."""
        assert self.edge is not None and self.zmq is not None
        reply, framed = await self.zmq.answer(parts)
        caller = None
        session_id = named_session("Frame", framed[1]) if framed is not None else None
        if framed is not None and session_id:
            self.router.route_to_edge(session_id)
            caller = (framed[0].key_id, framed[0].tenant)
        self.edge.answer_zmq(token, reply, caller)

    def _refuse(self, token: int, error: DirectorError, opened: bool) -> None:
        assert self.edge is not None
        self.metrics.labelled(self.metrics.errors, TRANSPORT, error.code.name).inc()
        self.edge.answer(token, error.code.value[0], error.message, b"", None, "", opened)

    async def _drain_forever(self) -> None:
        while True:
            await asyncio.sleep(DRAIN_S)
            self.drain()

    def drain(self) -> None:
        """What the edge answered alone since the last call, into the metrics and the sessions' counts."""
        assert self.edge is not None
        frames, errors, sessions = self.edge.drain()
        request = [self.metrics.labelled(self.metrics.request, transport, rpc) for transport, rpc in _VIA]
        for elapsed_s, compute_ms, flags, names, values, via in frames:
            request[via].observe(elapsed_s)
            if flags & _native.EDGE_HAS_METRICS:
                m = frame_metrics(flags, compute_ms, names, values)
                self.metrics.frame_answered(_VIA[via][0], m.compute_ms, m.stage_ms, m.stale, m.checkpoint_failed)
        if frames:
            self.metrics.edge_frames.inc(len(frames))
        for code, via in errors:
            self.metrics.labelled(self.metrics.errors, _VIA[via][0], status_code(code).name).inc()
        transports = [{t for via, (t, _) in enumerate(_VIA) if bits >> via & 1} for _, _, bits in sessions]  # bit 1 << via
        self.router.edge_answered([(sid, count, ts) for (sid, count, _), ts in zip(sessions, transports)])
