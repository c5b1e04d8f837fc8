"""A worker process's main loop: it holds a session table and answers the front's requests over
its end of the socket pair (server/front/worker_pool.py describes the framing)."""
from __future__ import annotations

import pickle

from camdirector.server.errors import DirectorError
from camdirector.server.sessions.table import SessionTable
from camdirector.server.settings import ServerSettings


def worker_main(conn, settings: ServerSettings) -> None:
    """Entry point of a worker process: answer requests until told to stop or the front goes."""
    table = SessionTable(settings)
    while True:
        try:
            request_id, op, session_id, payload = pickle.loads(conn.recv_bytes())
        except EOFError:  # the front died: do not linger as an orphan
            table.close_all()
            return
        if op in ("stop", "ping"):
            if op == "stop":  # release the sessions' GL contexts and recording files before saying so
                table.close_all()
            conn.send_bytes(pickle.dumps((request_id, 0, b"", None)))
            if op == "stop":
                return
            continue
        try:
            body, metrics = table.handle_bytes(op, session_id, payload)
            reply = (request_id, 0, body, metrics)
        except DirectorError as exc:
            reply = (request_id, exc.code.value[0], exc.message.encode(), None)
        conn.send_bytes(pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL))
