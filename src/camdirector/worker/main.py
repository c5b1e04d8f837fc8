"""A worker process's main loop: answer the front's requests over the socket pair (framed by
infra/channels.py) one at a time (dispatch.py, over the process's session table, table.py), and do
the sessions' deferred work while none waits.

"None waits" counts the requests already read into the loop's buffer, not only those still in the
socket: under load one read can take in several (at 8 to 128 FRAMING_ONLY sessions, 1.25 requests
a read on average), and deferred work or a collection run between them would hold them up.

With the compiled gRPC edge the worker has a second socket, its frame socket (front/worker_pool.py):
the edge's frames come there and their replies go back there. The loop takes a request from either,
the one whose requests are already read first, and answers each on the socket it came from.
"""

from __future__ import annotations

import functools
import io
import os
import select
import socket
import threading
from typing import TYPE_CHECKING

from camdirector.errors import DirectorError
from camdirector.infra.channels import READ_BUFFER_BYTES, encode_reply, read_request
from camdirector.infra.heap import collect_ahead, freeze_startup_heap
from camdirector.infra.plugins import import_plugins
from camdirector.server_settings import ServerSettings
from camdirector.worker.dispatch import Dispatcher, refusal
from camdirector.worker.table import SessionTable

if TYPE_CHECKING:
    from _typeshed import WriteableBuffer


class _CountedSocketIO(socket.SocketIO):
    """The socket's reads, counted."""

    def __init__(self, sock: socket.socket):
        super().__init__(sock, "rb")
        self.bytes_read = 0

    def readinto(self, b: WriteableBuffer) -> int | None:
        n = super().readinto(b)
        self.bytes_read += n or 0
        return n


class _CountedReader(io.BufferedReader):
    """A buffered reader whose reads are counted: less what its raw stream read, what it holds."""

    bytes_taken = 0

    def read(self, size: int | None = -1) -> bytes:
        data = super().read(size)
        self.bytes_taken += len(data)
        return data


class _Requests:
    """The front's requests off the socket, through a buffered reader (one read system call takes
    in a whole frame request, or several) that knows whether it holds more."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.raw = _CountedSocketIO(sock)
        self.reader = _CountedReader(self.raw, READ_BUFFER_BYTES)  # sock.makefile("rb", ...), counted

    def read(self) -> tuple[int, str, str, bytes]:
        """The next request (read_request); EOFError when the front has gone."""
        return read_request(self.reader)

    def buffered(self) -> bool:
        """Whether a request's first bytes are already in the reader's buffer."""
        return self.raw.bytes_read > self.reader.bytes_taken


class _Sockets:
    """The front's socket and, with the compiled gRPC edge, the frame socket: which to read next."""

    def __init__(self, front: _Requests, frames: _Requests | None):
        self.front = front
        self.all = [front] if frames is None else [front, frames]

    def next(self) -> _Requests:
        """A socket with a request: one already read into its buffer first, else the first ready."""
        for requests in self.all:
            if requests.buffered():
                return requests
        if len(self.all) == 1:
            return self.front  # its read waits for the request
        ready = select.select([r.sock for r in self.all], [], [])[0]
        return next(r for r in self.all if r.sock in ready)

    def waiting(self) -> bool:
        """Whether a request waits on any socket: in a reader's buffer, or on the socket."""
        if any(r.buffered() for r in self.all):
            return True
        return bool(select.select([r.sock for r in self.all], [], [], 0)[0])

    def drop(self, requests: _Requests) -> None:
        """A frame socket the edge closed (the front stopping it): the front's socket goes on."""
        self.all.remove(requests)


def _socket_of(conn) -> socket.socket:
    sock = socket.socket(fileno=os.dup(conn.fileno()))
    conn.close()
    return sock


def worker_main(conn, settings: ServerSettings, frames_conn=None) -> None:
    """Entry point of a worker process: answer requests until told to stop or the front goes.
    `conn` is the worker's end of a multiprocessing socket pair, read and written as a plain socket;
    `frames_conn`, with the compiled gRPC edge, its frame socket's end (module docstring)."""
    import_plugins(settings.plugins)  # spawned: the front's imports are not inherited
    sock = _socket_of(conn)
    front = _Requests(sock)
    incoming = _Sockets(front, None if frames_conn is None else _Requests(_socket_of(frames_conn)))
    table = SessionTable(settings, defer_snapshots=True)  # snapshots taken below, when no request waits (idle_work)
    requests = Dispatcher(table)
    sending = threading.Lock()  # views are answered from the render process's reader thread
    freeze_startup_heap()  # before the first request: full collections walk only what comes after

    def send(data: bytes, to: socket.socket = sock) -> None:
        with sending:
            to.sendall(data)

    def send_view(request_id: int, status: int, body: bytes) -> None:
        send(encode_reply(request_id, status, body, None))

    while True:
        source = incoming.next()
        try:
            request_id, op, session_id, payload = source.read()
        except EOFError:  # the front died: do not linger as an orphan
            if source is not front:
                incoming.drop(source)
                continue
            table.close_all()
            return
        if op in ("stop", "ping"):
            if op == "stop":  # release the sessions' GL contexts and recording files before saying so
                table.close_all()
            send(encode_reply(request_id, 0, b"", None))
            if op == "stop":
                return
            continue
        if op == "view":  # answered later, off this loop (render/monitor.py)
            try:
                requests.view(session_id, payload, functools.partial(send_view, request_id))
            except DirectorError as exc:
                send(refusal(request_id, exc))
            continue
        send(requests.answer(request_id, op, session_id, payload), source.sock)
        while not incoming.waiting() and table.idle_work():
            pass
        if not incoming.waiting():  # the collector's next run, where it holds no frame up
            collect_ahead()
