"""Worker processes that hold sessions, so capacity grows with cores.

The front process talks to each worker over one socket pair (`multiprocessing.Pipe`), in the
binary framing of server/sessions/worker.py: a struct header, then the raw bytes (the session id
and the client's serialized request; the serialized reply and a frame's metrics as packed
numbers). The front end of the pair is an asyncio stream, so a large scene never blocks the event
loop; the worker reads it blocking. A plain socket pair costs one wake-up per direction, where a
ZeroMQ pair costs three (its I/O threads on both sides): about 150 us against 370 us per round
trip after 16 ms idle on this kind of VM.

Workers are started with the "spawn" method: forking a process that already runs gRPC is unsafe.
A worker that dies is restarted; its sessions are lost and callers are told so. A worker whose
front goes away sees end-of-file and exits. With `workers=0` the same SessionTable runs inline in
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

from camdirector.server.errors import DirectorError
from camdirector.server.sessions.table import FrameMetrics, SessionTable
from camdirector.server.sessions.worker import (
    REPLY,
    REQUEST_ID_MODULUS,
    decode_reply_tail,
    encode_request,
    tail_length,
    worker_main,
)
from camdirector.server.settings import ServerSettings

log = logging.getLogger("camdirector.workers")

_CODES = {code.value[0]: code for code in grpc.StatusCode}


class _Worker:
    def __init__(self, index: int):
        self.index = index
        self.process: multiprocessing.process.BaseProcess | None = None
        self.writer: asyncio.StreamWriter | None = None
        self.reader_task: asyncio.Task | None = None


class WorkerPool:
    """Front-side handle on the workers: `call` sends one request to one worker and awaits it."""

    def __init__(self, settings: ServerSettings, on_worker_lost: Callable[[int], None] | None = None):
        self.settings = settings
        self.size = settings.workers
        self.on_worker_lost = on_worker_lost
        self._inline = SessionTable(settings) if self.size == 0 else None
        self._workers = [_Worker(i) for i in range(self.size)]
        self._pending: dict[int, asyncio.Future] = {}
        self._ids = itertools.count()
        self._monitor: asyncio.Task | None = None
        self._mp = multiprocessing.get_context("spawn")

    @property
    def slots(self) -> int:
        """How many places sessions can be put: workers, or 1 when inline."""
        return max(1, self.size)

    async def start(self) -> None:
        for worker in self._workers:
            await self._spawn(worker)
        if self._workers:
            await asyncio.gather(*(self._call_worker(w, "ping", "", b"", timeout_s=120.0) for w in self._workers))
            self._monitor = asyncio.create_task(self._watch())

    async def _spawn(self, worker: _Worker) -> None:
        front_end, worker_end = self._mp.Pipe(duplex=True)
        worker.process = self._mp.Process(target=worker_main, args=(worker_end, self.settings),
                                          name=f"camdirector-worker-{worker.index}", daemon=True)
        worker.process.start()
        worker_end.close()
        sock = socket.socket(fileno=os.dup(front_end.fileno()))
        front_end.close()
        reader, worker.writer = await asyncio.open_unix_connection(sock=sock, limit=2 ** 20)
        worker.reader_task = asyncio.create_task(self._read(reader))

    async def _read(self, reader: asyncio.StreamReader) -> None:
        try:
            while True:
                header = REPLY.unpack(await reader.readexactly(REPLY.size))
                body, metrics = decode_reply_tail(header, await reader.readexactly(tail_length(header)))
                request_id, code = header[0], header[1]
                future = self._pending.pop(request_id, None)
                if future is None or future.done():
                    continue
                if code == 0:
                    future.set_result((body, metrics))
                else:
                    future.set_exception(DirectorError(_CODES.get(code, grpc.StatusCode.UNKNOWN), body.decode()))
        except (asyncio.IncompleteReadError, ConnectionError):
            return  # the worker went away; _watch restarts it and fails what was pending

    async def _watch(self) -> None:
        """Restarts a worker that died; its sessions are gone and callers are told so."""
        while True:
            await asyncio.sleep(0.5)
            for worker in self._workers:
                if worker.process.is_alive():
                    continue
                log.error("worker %d died (exit code %s); restarting it", worker.index, worker.process.exitcode)
                worker.reader_task.cancel()
                worker.writer.close()
                for request_id, future in list(self._pending.items()):
                    if getattr(future, "worker_index", None) == worker.index and not future.done():
                        future.set_exception(DirectorError(grpc.StatusCode.UNAVAILABLE,
                                                           "the worker holding this session died"))
                        self._pending.pop(request_id, None)
                if self.on_worker_lost is not None:
                    self.on_worker_lost(worker.index)
                await self._spawn(worker)

    async def _call_worker(self, worker: _Worker, op: str, session_id: str, payload: bytes,
                           timeout_s: float | None = None):
        if worker.writer.is_closing():  # died, and _watch is starting its successor
            raise DirectorError(grpc.StatusCode.UNAVAILABLE, f"worker {worker.index} died and is restarting")
        request_id = next(self._ids) % REQUEST_ID_MODULUS
        future = asyncio.get_running_loop().create_future()
        future.worker_index = worker.index
        self._pending[request_id] = future
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

    async def call(self, slot: int, op: str, session_id: str, payload: bytes,
                   timeout_s: float | None = None) -> tuple[bytes, FrameMetrics | None]:
        """Runs one request on the session table of `slot`. Raises DirectorError (TimeoutError
        past timeout_s, when given)."""
        if self._inline is not None:
            if op == "view":
                return await asyncio.wait_for(self._inline_view(session_id, payload), timeout_s)
            return self._inline.handle_bytes(op, session_id, payload)
        return await self._call_worker(self._workers[slot], op, session_id, payload, timeout_s)

    async def _inline_view(self, session_id: str, payload: bytes) -> tuple[bytes, None]:
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

        self._inline.view(session_id, payload, lambda status, body: loop.call_soon_threadsafe(settle, status, body))
        return await future

    async def stop(self) -> None:
        if self._inline is not None:
            self._inline.close_all()
        if self._monitor is not None:
            self._monitor.cancel()
        for worker in self._workers:
            try:
                await self._call_worker(worker, "stop", "", b"", timeout_s=2.0)
            except (TimeoutError, DirectorError, ConnectionError):
                pass
            worker.reader_task.cancel()
            worker.writer.close()
            worker.process.join(timeout=2.0)
            if worker.process.is_alive():
                worker.process.kill()
