"""Worker processes that hold sessions, so capacity grows with cores.

The front process talks to each worker over one socket pair (`multiprocessing.Pipe`), in the
binary framing of infra/channels.py: a struct header, then the raw bytes (the session id
and the client's serialized request; the serialized reply and a frame's metrics as packed
numbers). The front end of the pair is an asyncio stream, so a large scene never blocks the event
loop; the worker reads it blocking. A plain socket pair costs one wake-up per direction, where a
ZeroMQ pair costs three (its I/O threads on both sides): about 150 us against 370 us per round
trip after 16 ms idle on this kind of VM.

Workers are started with the "spawn" method: forking a process that already runs gRPC is unsafe.
A worker that dies is noticed at once (its end of the socket pair closes): its requests in flight
fail with UNAVAILABLE, `on_worker_lost` is told (the router gives its sessions to other workers,
which restore them from their checkpoints), and it is restarted; requests for it meanwhile wait
for the new one. A worker whose front goes away sees end-of-file and exits. With `workers=0` the same SessionTable runs inline in
the front process.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import multiprocessing
import os
import socket
from collections.abc import Callable

import grpc

from camdirector.errors import DirectorError
from camdirector.infra.channels import REPLY, REQUEST_ID_MODULUS, FrameMetrics, decode_reply_tail, encode_request, tail_length
from camdirector.server_settings import ServerSettings
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.main import worker_main
from camdirector.worker.table import SessionTable

log = logging.getLogger("camdirector.workers")

_CODES = {code.value[0]: code for code in grpc.StatusCode}
WORKER_START_WAIT_S = 30.0  # a request for a restarting worker waits this long for it, s


class _Worker:
    def __init__(self, index: int):
        self.index = index
        # its process and socket, set by WorkerPool._spawn before any use (and again for each successor)
        self.process: multiprocessing.process.BaseProcess
        self.writer: asyncio.StreamWriter
        self.reader_task: asyncio.Task[None]
        self.ready = asyncio.Event()  # started and answering; cleared from its death to its successor's start
        self.replacing: asyncio.Task[None] | None = None


class WorkerPool:
    """Front-side handle on the workers: `call` sends one request to one worker and awaits it."""

    def __init__(self, settings: ServerSettings, on_worker_lost: Callable[[int], None] | None = None):
        self.settings = settings
        self.size = settings.workers
        self.on_worker_lost = on_worker_lost
        self._inline = Dispatcher(SessionTable(settings)) if self.size == 0 else None
        self._workers = [_Worker(i) for i in range(self.size)]
        # request id -> (its reply's future, the index of the worker it was sent to)
        self._pending: dict[int, tuple[asyncio.Future[tuple[bytes, FrameMetrics | None]], int]] = {}
        self._ids = itertools.count()
        self._monitor: asyncio.Task[None] | None = None
        self._stopping = False
        self._mp = multiprocessing.get_context("spawn")

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
        worker.ready.set()

    async def _spawn(self, worker: _Worker) -> None:
        front_end, worker_end = self._mp.Pipe(duplex=True)
        worker.process = self._mp.Process(
            target=worker_main, args=(worker_end, self.settings), name=f"camdirector-worker-{worker.index}", daemon=True
        )
        worker.process.start()
        worker_end.close()
        sock = socket.socket(fileno=os.dup(front_end.fileno()))
        front_end.close()
        reader, worker.writer = await asyncio.open_unix_connection(sock=sock, limit=2**20)
        worker.reader_task = asyncio.create_task(self._read(worker, reader))

    async def _read(self, worker: _Worker, reader: asyncio.StreamReader) -> None:
        try:
            while True:
                header = REPLY.unpack(await reader.readexactly(REPLY.size))
                body, metrics = decode_reply_tail(header, await reader.readexactly(tail_length(header)))
                request_id, code = header[0], header[1]
                pending = self._pending.pop(request_id, None)
                if pending is None or pending[0].done():
                    continue
                future = pending[0]
                if code == 0:
                    future.set_result((body, metrics))
                else:
                    future.set_exception(DirectorError(_CODES.get(code, grpc.StatusCode.UNKNOWN), body.decode()))
        except (asyncio.IncompleteReadError, ConnectionError):
            if not self._stopping:  # the worker went away: at once, not at _watch's next look
                self._lost(worker)

    def _lost(self, worker: _Worker) -> None:
        """A worker died: fail what it had in flight, tell the router, start its successor."""
        if worker.replacing is not None and not worker.replacing.done():
            return
        log.error("worker %d died (exit code %s); restarting it", worker.index, worker.process.exitcode)
        worker.ready.clear()
        worker.writer.close()
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
        if worker.writer.is_closing():  # died just now; _lost is starting its successor
            raise DirectorError(grpc.StatusCode.UNAVAILABLE, f"worker {worker.index} died and is restarting")
        request_id = next(self._ids) % REQUEST_ID_MODULUS
        future: asyncio.Future[tuple[bytes, FrameMetrics | None]] = asyncio.get_running_loop().create_future()
        self._pending[request_id] = (future, worker.index)
        try:
            worker.writer.writelines(encode_request(request_id, op, session_id, payload))
            try:
                await worker.writer.drain()  # backpressure on large payloads, immediate otherwise
            except ConnectionError:  # it died before _watch noticed
                raise DirectorError(grpc.StatusCode.UNAVAILABLE, "the worker holding this session died") from None
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
                future.set_exception(DirectorError(_CODES.get(status, grpc.StatusCode.UNKNOWN), body.decode()))

        def reply(status: int, body: bytes) -> None:  # from the render thread
            loop.call_soon_threadsafe(settle, status, body)

        inline.view(session_id, payload, reply)
        return await future

    async def stop(self) -> None:
        self._stopping = True
        if self._inline is not None:
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
            worker.reader_task.cancel()
            worker.writer.close()
            worker.process.join(timeout=2.0)
            if worker.process.is_alive():
                worker.process.kill()
