"""The compiled gRPC edge's Python side (issue 43, step 5; native/src/edge.rs; docs/frame_path.md).

With `grpc_front compiled` the node's gRPC port is served by the edge, HTTP/2 in Rust on its own
thread in this process. It answers StreamFrames and Frame itself: a frame of a session routed to it
(SessionRouter.route_to_edge) goes straight to the session's worker over the worker's frame socket
(front/worker_pool.py) and back, with no Python here. Every other call it passes through to the
usual grpc.aio server (grpc_service.py), which listens on a Unix socket in a private folder. With
the node's certificate (`--tls-cert`, `--tls-key`) the edge serves TLS itself.

This module answers what the edge asks (its events, announced by a byte on a socket pair the loop
watches): a caller, by its key (access/guard.py), the first time the edge sees its metadata (it
remembers the callers let in until their key is revoked); a stream's first frame (the session
adopted or restored, counted as streaming: SessionRouter.stream_opened), after which the session
is routed to the edge; any frame of a session not routed there; a stream's end. Errors are answered
as grpc_service.py answers them, with the same codes, messages and metrics. What the edge answered
alone is read back every DRAIN_S into the front's metrics and the sessions' counts.
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
from camdirector.access.keys import AccessUnavailable
from camdirector.errors import DirectorError, internal, status_code
from camdirector.front.grpc_service import SERVER_METADATA, TRANSPORT, start_grpc
from camdirector.front.router import RESEND_BURST_S, SessionRouter
from camdirector.front.session_calls import RPCS
from camdirector.infra.channels import frame_metrics

log = logging.getLogger("camdirector.grpc_edge")

DRAIN_S = 0.25  # how often what the edge answered alone reaches the metrics and the sessions' counts, s
_RPC = ("StreamFrames", "Frame")  # by whether the edge's frame was a Frame call's


class GrpcEdgeFront:
    """The edge, its grpc.aio server behind it, and the answers to its events."""

    def __init__(self, router: SessionRouter, guard: Guard):
        self.router = router
        self.guard = guard
        self.metrics = router.metrics
        self.edge: _native.GrpcEdge | None = None
        self._inner: grpc.aio.Server | None = None
        self._folder: str | None = None
        self._wake: socket.socket | None = None
        self._tasks: set[asyncio.Task] = set()
        self._drainer: asyncio.Task | None = None

    async def start(self, address: str) -> str:
        """Serves `address` (HOST:PORT; port 0 picks one); returns the bound HOST:PORT."""
        settings = self.router.settings
        self._folder = tempfile.mkdtemp(prefix="camdirector-grpc-")  # mode 0700: the inner server is this user's
        inner_path = os.path.join(self._folder, "grpc.sock")
        self._inner, _ = await start_grpc(self.router, f"unix:{inner_path}", self.guard)
        self._wake, edge_end = socket.socketpair()
        self._wake.setblocking(False)
        edge = self.edge = _native.GrpcEdge(
            address,
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
        self.router.pool.attach_frame_sink(lambda slot, sock: edge.set_worker(slot, sock.detach()))
        self._drainer = asyncio.create_task(self._drain_forever())
        host, _, _ = address.rpartition(":")
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
            task = asyncio.create_task(self._answer(event))
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
            self.metrics.labelled(self.metrics.request, TRANSPORT, _RPC[kind == "unary"]).observe(time.perf_counter() - t0)
            self.edge.answer(token, 0, "", body, None, tenant, opened)
        except DirectorError as exc:
            self._refuse(token, exc, opened)
        except AccessUnavailable as exc:  # a session of this tenant not held here, its owner unread
            self._refuse(token, self.guard.records_down(exc), opened)
        except Exception as exc:  # a bug: INTERNAL, as grpc_service.py answers it
            self._refuse(token, internal(exc, _RPC[kind == "unary"], session_id, log), opened)

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
        request = [self.metrics.labelled(self.metrics.request, TRANSPORT, rpc) for rpc in _RPC]
        for elapsed_s, compute_ms, flags, names, values, unary in frames:
            request[unary].observe(elapsed_s)
            if flags & _native.EDGE_HAS_METRICS:
                m = frame_metrics(flags, compute_ms, names, values)
                self.metrics.frame_answered(TRANSPORT, m.compute_ms, m.stage_ms, m.stale, m.checkpoint_failed)
        if frames:
            self.metrics.edge_frames.inc(len(frames))
        for code in errors:
            self.metrics.labelled(self.metrics.errors, TRANSPORT, status_code(code).name).inc()
        self.router.edge_answered(sessions)
