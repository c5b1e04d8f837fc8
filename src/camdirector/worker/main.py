"""A worker process's main loop: answer the front's requests over the socket pair (framed by
infra/channels.py) one at a time (dispatch.py, over the process's session table, table.py), and do
the sessions' deferred work while none waits.
"""

from __future__ import annotations

import functools
import io
import os
import select
import socket
import threading

from camdirector.errors import DirectorError
from camdirector.infra.channels import READ_BUFFER_BYTES, encode_reply, read_request
from camdirector.infra.heap import collect_ahead, freeze_startup_heap
from camdirector.infra.plugins import import_plugins
from camdirector.server_settings import ServerSettings
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.table import SessionTable


def _idle(sock: socket.socket) -> bool:
    """Whether no request waits on the socket. (One already in the reader's buffer, read with the
    one before it, is not seen: it then waits for at most one snapshot.)"""
    return not select.select([sock], [], [], 0)[0]


def worker_main(conn, settings: ServerSettings) -> None:
    """Entry point of a worker process: answer requests until told to stop or the front goes.
    `conn` is the worker's end of a multiprocessing socket pair, read and written as a plain socket."""
    import_plugins(settings.plugins)  # spawned: the front's imports are not inherited
    sock = socket.socket(fileno=os.dup(conn.fileno()))
    conn.close()
    reader = io.BufferedReader(socket.SocketIO(sock, "rb"), READ_BUFFER_BYTES)  # sock.makefile("rb", ...)
    table = SessionTable(settings, defer_snapshots=True)  # snapshots taken below, when no request waits (idle_work)
    requests = Dispatcher(table)
    sending = threading.Lock()  # views are answered from the render process's reader thread
    freeze_startup_heap()  # before the first request: full collections walk only what comes after

    def send(data: bytes) -> None:
        with sending:
            sock.sendall(data)

    def send_view(request_id: int, status: int, body: bytes) -> None:
        send(encode_reply(request_id, status, body, None))

    while True:
        try:
            request_id, op, session_id, payload = read_request(reader)
        except EOFError:  # the front died: do not linger as an orphan
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
                send(encode_reply(request_id, exc.code.value[0], exc.message.encode(), None))
            continue
        try:
            body, metrics = requests.handle_bytes(op, session_id, payload)
            reply = encode_reply(request_id, 0, body, metrics)
        except DirectorError as exc:
            reply = encode_reply(request_id, exc.code.value[0], exc.message.encode(), None)
        send(reply)
        while _idle(sock) and table.idle_work():
            pass
        if _idle(sock):  # the collector's next run, where it holds no frame up
            collect_ahead()
