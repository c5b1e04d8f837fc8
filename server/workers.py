"""Worker processes that hold sessions, so capacity grows with cores.

The front process (transports, routing) talks to each worker over a ZeroMQ DEALER pair on an
ipc:// socket: request [request id, op, session id, payload], reply [request id, status code
(ASCII decimal, 0 = OK), body (reply bytes or error message), pickled FrameMetrics or empty].
Workers are started with the "spawn" method: forking a process that already runs gRPC is unsafe.
A worker that dies is restarted; its sessions are lost and their requests answer NOT_FOUND.
With `workers=0` the same SessionTable runs inline in the front process.
"""
from __future__ import annotations

import asyncio
import itertools
import logging
import multiprocessing
import os
import pickle
import tempfile
from typing import Callable

import grpc
import zmq
import zmq.asyncio

from camdirector.server.errors import DirectorError
from camdirector.server.sessions import FrameMetrics, SessionTable
from camdirector.server.settings import ServerSettings

log = logging.getLogger("camdirector.workers")


def _worker_main(endpoint: str, settings: ServerSettings) -> None:
    """Entry point of a worker process: answer requests until told to stop or the front goes."""
    table = SessionTable(settings)
    ctx = zmq.Context()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.bind(endpoint)
    parent = os.getppid()
    poller = zmq.Poller()
    poller.register(sock, zmq.POLLIN)
    while True:
        if not poller.poll(1000):
            if os.getppid() != parent:  # the front died: do not linger as an orphan
                return
            continue
        request_id, op, session_id, payload = sock.recv_multipart(copy=True)
        if op in (b"stop", b"ping"):
            sock.send_multipart([request_id, b"0", b"", b""])
            if op == b"stop":
                return
            continue
        try:
            body, metrics = table.handle_bytes(op.decode(), session_id.decode(), payload)
            sock.send_multipart([request_id, b"0", body, pickle.dumps(metrics) if metrics else b""])
        except DirectorError as exc:
            sock.send_multipart([request_id, str(exc.code.value[0]).encode(), exc.message.encode(), b""])


_CODES = {code.value[0]: code for code in grpc.StatusCode}


class _Worker:
    def __init__(self, index: int, endpoint: str):
        self.index = index
        self.endpoint = endpoint
        self.process: multiprocessing.process.BaseProcess | None = None
        self.socket: zmq.asyncio.Socket | None = None
        self.reader: asyncio.Task | None = None


class WorkerPool:
    """Front-side handle on the workers: `call` sends one request to one worker and awaits it."""

    def __init__(self, settings: ServerSettings, on_worker_lost: Callable[[int], None] | None = None):
        self.settings = settings
        self.size = settings.workers
        self.on_worker_lost = on_worker_lost
        self._inline = SessionTable(settings) if self.size == 0 else None
        self._ctx = zmq.asyncio.Context.instance()
        self._dir = tempfile.mkdtemp(prefix="camdirector-")
        self._workers = [_Worker(i, f"ipc://{self._dir}/worker-{i}.sock") for i in range(self.size)]
        self._pending: dict[bytes, asyncio.Future] = {}
        self._ids = itertools.count()
        self._monitor: asyncio.Task | None = None
        self._mp = multiprocessing.get_context("spawn")

    @property
    def slots(self) -> int:
        """How many places sessions can be put: workers, or 1 when inline."""
        return max(1, self.size)

    async def start(self) -> None:
        for worker in self._workers:
            self._spawn(worker)
        if self._workers:
            # a request sent before the worker has bound waits in ZeroMQ's queue; ping to be sure
            await asyncio.gather(*(self._call_worker(w, "ping", "", b"", timeout_s=120.0) for w in self._workers))
            self._monitor = asyncio.create_task(self._watch())

    def _spawn(self, worker: _Worker) -> None:
        worker.process = self._mp.Process(target=_worker_main, args=(worker.endpoint, self.settings),
                                          name=f"camdirector-worker-{worker.index}", daemon=True)
        worker.process.start()
        worker.socket = self._ctx.socket(zmq.DEALER)
        worker.socket.setsockopt(zmq.LINGER, 0)
        worker.socket.connect(worker.endpoint)
        worker.reader = asyncio.create_task(self._read(worker))

    async def _read(self, worker: _Worker) -> None:
        sock = worker.socket
        while True:
            request_id, code, body, metrics = await sock.recv_multipart()
            future = self._pending.pop(request_id, None)
            if future is None or future.done():
                continue
            if code == b"0":
                future.set_result((body, pickle.loads(metrics) if metrics else None))
            else:
                future.set_exception(DirectorError(_CODES.get(int(code), grpc.StatusCode.UNKNOWN), body.decode()))

    async def _watch(self) -> None:
        """Restarts a worker that died; its sessions are gone and callers are told so."""
        while True:
            await asyncio.sleep(0.5)
            for worker in self._workers:
                if worker.process.is_alive():
                    continue
                log.error("worker %d died (exit code %s); restarting it", worker.index, worker.process.exitcode)
                worker.reader.cancel()
                worker.socket.close()
                for request_id, future in list(self._pending.items()):
                    if getattr(future, "worker_index", None) == worker.index and not future.done():
                        future.set_exception(DirectorError(grpc.StatusCode.UNAVAILABLE,
                                                           "the worker holding this session died"))
                        self._pending.pop(request_id, None)
                if self.on_worker_lost is not None:
                    self.on_worker_lost(worker.index)
                self._spawn(worker)

    async def _call_worker(self, worker: _Worker, op: str, session_id: str, payload: bytes,
                           timeout_s: float | None = None):
        request_id = next(self._ids).to_bytes(8, "little")
        future = asyncio.get_running_loop().create_future()
        future.worker_index = worker.index
        self._pending[request_id] = future
        await worker.socket.send_multipart([request_id, op.encode(), session_id.encode(), payload])
        if timeout_s is None:
            return await future
        try:
            return await asyncio.wait_for(future, timeout_s)
        finally:
            self._pending.pop(request_id, None)

    async def call(self, slot: int, op: str, session_id: str, payload: bytes) -> tuple[bytes, FrameMetrics | None]:
        """Runs one request on the session table of `slot`. Raises DirectorError."""
        if self._inline is not None:
            return self._inline.handle_bytes(op, session_id, payload)
        return await self._call_worker(self._workers[slot], op, session_id, payload)

    async def stop(self) -> None:
        if self._monitor is not None:
            self._monitor.cancel()
        for worker in self._workers:
            try:
                await self._call_worker(worker, "stop", "", b"", timeout_s=2.0)
            except (asyncio.TimeoutError, DirectorError):
                pass
            worker.reader.cancel()
            worker.socket.close()
            worker.process.join(timeout=2.0)
            if worker.process.is_alive():
                worker.process.kill()
        try:
            for name in os.listdir(self._dir):
                os.unlink(os.path.join(self._dir, name))
            os.rmdir(self._dir)
        except OSError:
            pass
