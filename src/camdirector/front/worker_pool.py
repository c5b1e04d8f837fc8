"""Worker processes that hold sessions, so capacity grows with cores.

The front process talks to each worker over one socket pair (`multiprocessing.Pipe`), in the
binary framing of infra/channels.py: a struct header, then the raw bytes (the session id
and the client's serialized request; the serialized reply and a frame's metrics as packed
numbers). The front end of the pair is an asyncio protocol (`_Channel`), so a large scene never
blocks the event loop; the worker reads it blocking. A plain socket pair costs one wake-up per
direction, where a ZeroMQ pair costs three (its I/O threads on both sides): about 150 us against
370 us per round trip after 16 ms idle on this kind of VM. The wake-up is most of what a request
costs the front to send, so the requests one turn of the event loop makes for a worker go in one
write at the end of the turn (under load, several sessions' frames a write), and the replies are
read off each arrival in the callback, with no task between the socket and a request's future.

Workers are started with the "spawn" method: forking a process that already runs gRPC is unsafe.
A worker that dies is noticed at once (its end of the socket pair closes): its requests in flight
fail with UNAVAILABLE, `on_worker_lost` is told (the router gives its sessions to other workers,
which restore them from their checkpoints), and it is restarted; requests for it meanwhile wait
for the new one. A worker whose front goes away sees end-of-file and exits. With `workers=0` the same SessionTable runs inline in
the front process; with the compiled edge too, the edge answers the frames of the sessions routed
to it on its own thread (`answer_inline`: no hop, no other process woken), so the table is used
from two threads, one at a time (`_inline_lock`).

With the compiled edge (ServerSettings.edge: gRPC's, ZeroMQ's or both) each worker has a second
socket pair, its frame socket: the edge (native/src/edge.rs) writes the frames of the sessions
routed to it there and reads their replies, in the same framing, with no Python in the front. The
pool makes it with the worker and hands its front end to `frame_sink` (front/edge.py), each
successor's too.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import multiprocessing
import os
import socket
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

import grpc

from camdirector.errors import DirectorError, status_code
from camdirector.infra.channels import (
    REPLY,
    REQUEST_ID_MODULUS,
    FrameMetrics,
    ReplyHeader,
    decode_reply_tail,
    encode_request,
    tail_length,
)
from camdirector.infra.heap import collect_ahead
from camdirector.server_settings import ServerSettings
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.main import worker_main
from camdirector.worker.table import SessionTable

if TYPE_CHECKING:
    from camdirector import _native

log = logging.getLogger("camdirector.workers")

WORKER_START_WAIT_S = 30.0  # a request for a restarting worker waits this long for it, s
# a request this large is written at once and its write waited for, not held to the turn's end, bytes
WRITE_AT_ONCE_BYTES = 1 << 16


class _Channel(asyncio.Protocol):
    """The front's end of one worker's socket pair (module docstring). `on_reply(header, tail)`
    for each whole reply, in order; `on_lost()` once when the pair closes."""

    def __init__(self, on_reply: Callable[[ReplyHeader, bytes], None], on_lost: Callable[[], None]):
        self.on_reply = on_reply
        self.on_lost = on_lost
        self.transport: asyncio.Transport | None = None
        self._held: list[bytes] = []  # requests of this turn of the loop, written at its end
        self._buffer = b""  # a reply's first bytes, until the rest arrives
        self._chunks: list[bytes] = []  # a large reply's arrivals after _buffer's, joined once it is whole
        self._buffer_bytes = 0  # bytes in _buffer and _chunks
        self._reply_bytes = 0  # bytes of the reply begun in _buffer, all told; 0: its header is not all there
        self._writable: asyncio.Future[None] | None = None  # while the transport's buffer is over its mark

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def connection_lost(self, exc: Exception | None) -> None:
        if self._writable is not None and not self._writable.done():
            self._writable.set_result(None)
        self.on_lost()

    def pause_writing(self) -> None:
        self._writable = asyncio.get_running_loop().create_future()

    def resume_writing(self) -> None:
        if self._writable is not None and not self._writable.done():
            self._writable.set_result(None)

    def closed(self) -> bool:
        return self.transport is None or self.transport.is_closing()

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()

    async def write(self, buffers: list[bytes]) -> None:
        """Sends a request's buffers: held to the end of this turn of the loop when small; at
        once, after the held ones, when large, and then waits while the socket's buffer is full."""
        assert self.transport is not None
        if not self._held:
            asyncio.get_running_loop().call_soon(self._flush)
        self._held.extend(buffers)
        if sum(map(len, buffers)) >= WRITE_AT_ONCE_BYTES:
            self._flush()
            if self._writable is not None:
                await self._writable

    def _flush(self) -> None:
        if self._held and self.transport is not None and not self.transport.is_closing():
            self.transport.writelines(self._held)  # one send for them all
        self._held = []

    def data_received(self, data: bytes) -> None:
        if self._buffer:
            self._buffer_bytes += len(data)
            if self._buffer_bytes < self._reply_bytes:  # a large reply still arriving: joined once, when whole
                self._chunks.append(data)
                return
            data = self._buffer + b"".join(self._chunks) + data
            self._buffer, self._chunks = b"", []
        at, size, end = 0, REPLY.size, len(data)
        self._reply_bytes = 0
        while end - at >= size:
            header = REPLY.unpack_from(data, at)
            after = at + size + tail_length(header)
            if after > end:
                self._reply_bytes = after - at
                break
            self.on_reply(header, data[at + size : after])
            at = after
        self._buffer = data[at:]
        self._buffer_bytes = end - at


class _Worker:
    def __init__(self, index: int):
        self.index = index
        # its process and socket, set by WorkerPool._spawn before any use (and again for each successor)
        self.process: multiprocessing.process.BaseProcess
        self.channel: _Channel
        self.ready = asyncio.Event()  # started and answering; cleared from its death to its successor's start
        self.frame_socket: socket.socket | None = None  # its frame socket's front end, until frame_sink takes it
        self.replacing: asyncio.Task[None] | None = None


class WorkerPool:
    """Front-side handle on the workers: `call` sends one request to one worker and awaits it."""

    def __init__(self, settings: ServerSettings, on_worker_lost: Callable[[int], None] | None = None):
        self.settings = settings
        self.size = settings.workers
        self.on_worker_lost = on_worker_lost
        self._inline = Dispatcher(SessionTable(settings)) if self.size == 0 else None
        self._inline_lock = threading.Lock()  # the inline table's callers: the loop's thread and the edge's
        self._workers = [_Worker(i) for i in range(self.size)]
        # request id -> (its reply's future, the index of the worker it was sent to)
        self._pending: dict[int, tuple[asyncio.Future[tuple[bytes, FrameMetrics | None]], int]] = {}
        self._ids = itertools.count()
        self._monitor: asyncio.Task[None] | None = None
        self._stopping = False
        self._mp = multiprocessing.get_context("spawn")
        self._frame_sink: Callable[[int, socket.socket], None] | None = None

    def attach_frame_sink(self, sink: Callable[[int, socket.socket], None]) -> None:
        """Hands each worker's frame socket to `sink(slot, socket)`: those made so far at once,
        each successor's when it starts."""
        self._frame_sink = sink
        for worker in self._workers:
            self._hand_frame_socket(worker)

    def _hand_frame_socket(self, worker: _Worker) -> None:
        if self._frame_sink is not None and worker.frame_socket is not None:
            sock, worker.frame_socket = worker.frame_socket, None
            self._frame_sink(worker.index, sock)

    @property
    def slots(self) -> int:
        """How many places sessions can be put: workers, or 1 when inline."""
        return max(1, self.size)

    async def start(self) -> None:
        for worker in self._workers:
            await self._spawn(worker)
        if self._workers:
            await asyncio.gather(*(self._ping(w) for w in self._workers))
            self._monitor = asyncio.create_task(self._watch())

    async def _ping(self, worker: _Worker) -> None:
        """Waits until a just started worker answers (its imports done), then lets requests in."""
        await self._send(worker, "ping", "", b"", timeout_s=120.0)
        self._hand_frame_socket(worker)
        worker.ready.set()

    async def _spawn(self, worker: _Worker) -> None:
        front_end, worker_end = self._mp.Pipe(duplex=True)
        frames_front, frames_worker = self._mp.Pipe(duplex=True) if self.settings.edge else (None, None)
        worker.process = self._mp.Process(
            target=worker_main,
            args=(worker_end, self.settings, frames_worker),
            name=f"camdirector-worker-{worker.index}",
            daemon=True,
        )
        worker.process.start()
        worker_end.close()
        sock = socket.socket(fileno=os.dup(front_end.fileno()))
        front_end.close()
        if frames_front is not None and frames_worker is not None:
            frames_worker.close()
            if worker.frame_socket is not None:  # its predecessor's, never taken
                worker.frame_socket.close()
            worker.frame_socket = socket.socket(fileno=os.dup(frames_front.fileno()))
            frames_front.close()
        channel = _Channel(self._reply, lambda: self._closed(worker, channel))
        await asyncio.get_running_loop().create_unix_connection(lambda: channel, sock=sock)
        worker.channel = channel

    def _reply(self, header: ReplyHeader, tail: bytes) -> None:
        """A worker's reply: its request's future settled."""
        pending = self._pending.pop(header[0], None)
        if pending is None or pending[0].done():
            return
        body, metrics = decode_reply_tail(header, tail)
        if header[1] == 0:
            pending[0].set_result((body, metrics))
        else:
            pending[0].set_exception(DirectorError(status_code(header[1]), body.decode()))

    def _closed(self, worker: _Worker, channel: _Channel) -> None:
        """A worker's socket pair closed: it went away (at once, not at _watch's next look). A
        channel that is no longer the worker's (its successor's is) says nothing of the worker."""
        if not self._stopping and getattr(worker, "channel", None) is channel:
            self._lost(worker)

    def _lost(self, worker: _Worker) -> None:
        """A worker died: fail what it had in flight, tell the router, start its successor."""
        if worker.replacing is not None and not worker.replacing.done():
            return
        log.error("worker %d died (exit code %s); restarting it", worker.index, worker.process.exitcode)
        worker.ready.clear()
        worker.channel.close()
        for request_id, (future, worker_index) in list(self._pending.items()):
            if worker_index == worker.index and not future.done():
                future.set_exception(
                    DirectorError(
                        grpc.StatusCode.UNAVAILABLE, "the worker holding this session died; retry: it is being restored"
                    )
                )
                self._pending.pop(request_id, None)
        if self.on_worker_lost is not None:
            self.on_worker_lost(worker.index)
        worker.replacing = asyncio.create_task(self._replace(worker))

    async def _replace(self, worker: _Worker) -> None:
        worker.process.kill()  # already dead, or its socket broke: either way it is done
        await asyncio.get_running_loop().run_in_executor(None, worker.process.join)
        await self._spawn(worker)
        await self._ping(worker)

    async def _watch(self) -> None:
        """Notices a worker that died without its socket saying so (a backstop to _read)."""
        while True:
            await asyncio.sleep(0.5)
            for worker in self._workers:
                if not worker.process.is_alive() and worker.ready.is_set():
                    self._lost(worker)

    async def _call_worker(self, worker: _Worker, op: str, session_id: str, payload: bytes, timeout_s: float | None = None):
        if not worker.ready.is_set():  # its successor is starting: wait for it rather than fail
            try:
                await asyncio.wait_for(worker.ready.wait(), WORKER_START_WAIT_S)
            except TimeoutError:
                raise DirectorError(grpc.StatusCode.UNAVAILABLE, f"worker {worker.index} is restarting") from None
        return await self._send(worker, op, session_id, payload, timeout_s)

    async def _send(self, worker: _Worker, op: str, session_id: str, payload: bytes, timeout_s: float | None = None):
        if worker.channel.closed():  # died just now; _lost is starting its successor
            raise DirectorError(grpc.StatusCode.UNAVAILABLE, f"worker {worker.index} died and is restarting")
        request_id = next(self._ids) % REQUEST_ID_MODULUS
        future: asyncio.Future[tuple[bytes, FrameMetrics | None]] = asyncio.get_running_loop().create_future()
        self._pending[request_id] = (future, worker.index)
        try:
            await worker.channel.write(encode_request(request_id, op, session_id, payload))
            if timeout_s is None:
                return await future
            return await asyncio.wait_for(future, timeout_s)
        finally:
            self._pending.pop(request_id, None)

    async def call(
        self, slot: int, op: str, session_id: str, payload: bytes, timeout_s: float | None = None
    ) -> tuple[bytes, FrameMetrics | None]:
        """Runs one request on the session table of `slot`. Raises DirectorError (TimeoutError
        past timeout_s, when given)."""
        if self._inline is not None:
            if op == "view":
                return await asyncio.wait_for(self._inline_view(self._inline, session_id, payload), timeout_s)
            with self._inline_lock:
                return self._inline.handle_bytes(op, session_id, payload)
        return await self._call_worker(self._workers[slot], op, session_id, payload, timeout_s)

    async def _inline_view(self, inline: Dispatcher, session_id: str, payload: bytes) -> tuple[bytes, None]:
        """A view of an inline session: the table answers from the render process's thread."""
        loop = asyncio.get_running_loop()
        future = loop.create_future()

        def settle(status: int, body: bytes) -> None:
            if future.done():
                return
            if status == 0:
                future.set_result((body, None))
            else:
                future.set_exception(DirectorError(status_code(status), body.decode()))

        def reply(status: int, body: bytes) -> None:  # from the render thread
            loop.call_soon_threadsafe(settle, status, body)

        with self._inline_lock:
            inline.view(session_id, payload, reply)
        return await future

    @property
    def inline(self) -> bool:
        """Whether the sessions are held in this process (`workers=0`)."""
        return self._inline is not None

    def hand_inline_to(self, edge: _native.Edge) -> None:
        """The compiled edge answers the inline sessions' frames on its thread (`answer_inline`)
        and, when it would otherwise sleep, does the table's idle work (`idle_inline`); from now on
        the table's snapshots due wait for those moments, as a worker's do."""
        assert self._inline is not None
        self._inline.table.defer_snapshots = True
        edge.set_inline(0, self.answer_inline, self.idle_inline)

    def idle_inline(self) -> bool:
        """One piece of the inline table's idle work (SessionTable.idle_work), else the collector's
        next run (infra/heap.py), as a worker does them when no request waits; called on the edge's
        thread when it has nothing else to do. Whether more waits: False too while the loop's thread
        holds the table (the edge asks again after its next frame) or the pool is stopping."""
        assert self._inline is not None
        if self._stopping or not self._inline_lock.acquire(blocking=False):
            return False
        try:
            if self._inline.table.idle_work(anywhere=True):  # not the thread that made the sessions
                return True
        finally:
            self._inline_lock.release()
        collect_ahead()
        return False

    def answer_inline(self, session_id: str, payload: bytes) -> bytes | None:
        """A frame of an inline session, answered on the calling thread (the compiled edge's):
        its reply in the workers' framing (infra/channels.py), or None for a session this thread
        must not compute (not held: restored on the loop's thread; or bound to the thread that
        made it, CameraRig.thread_bound), which the edge hands to the loop."""
        assert self._inline is not None
        with self._inline_lock:
            if not self._inline.table.answers_anywhere(session_id):
                return None
            return self._inline.answer(0, "frame", session_id, payload)

    async def stop(self) -> None:
        self._stopping = True
        if self._inline is not None:
            with self._inline_lock:
                self._inline.table.close_all()
        if self._monitor is not None:
            self._monitor.cancel()
        for worker in self._workers:
            if worker.replacing is not None:
                worker.replacing.cancel()
            try:
                await self._send(worker, "stop", "", b"", timeout_s=2.0)
            except (TimeoutError, DirectorError, ConnectionError):
                pass
            worker.channel.close()
            if worker.frame_socket is not None:
                worker.frame_socket.close()
            worker.process.join(timeout=2.0)
            if worker.process.is_alive():
                worker.process.kill()
