"""Requests as the transports carry them, to the session table that holds their session: an
operation name, the session id the request was routed by, and the request's bytes in; the reply's
bytes out, and a frame's metrics (infra/channels.py).

The worker's main loop (worker/main.py) and the front's inline table (front/worker_pool.py) call
this through `SessionTable.handle_bytes`, and so does a restore, replaying a checkpoint's inputs
(checkpointing.py). Each request is parsed once, here; a frame's bytes as received also go on to
the table, which records and checkpoints them as they are.
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import orjson

from camdirector.errors import DirectorError, internal, invalid
from camdirector.infra.channels import FrameMetrics, decode_create
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.timeline import dumps as timeline_dumps

if TYPE_CHECKING:  # the table answers its requests through this module
    from camdirector.worker.table import SessionTable

log = logging.getLogger("camdirector.sessions")


def handle_bytes(table: SessionTable, op: str, session_id: str, payload: bytes) -> tuple[bytes, FrameMetrics | None]:
    """One request (module docstring), answered by `table`.

    Raises DirectorError for anything the client must hear about; an unexpected exception
    becomes INTERNAL and leaves the other sessions untouched (a failed create drops its session).
    """
    try:
        if op == "frame":
            return table.frame_bytes(parse(pb.FrameUpdate, payload, session_id), payload)
        if op == "create":   # payload: the session's tenant and the request (infra/channels.py)
            tenant, request = decode_create(payload)
            return table.create(session_id, parse(pb.CreateSessionRequest, request), payload,
                                tenant).SerializeToString(), None
        if op == "style":
            return table.update_style(parse(pb.UpdateStyleRequest, payload, session_id), payload).SerializeToString(), None
        if op == "close":
            return table.close(session_id).SerializeToString(), None
        if op == "take":
            return table.take_shot(parse(pb.TakeShotRequest, payload, session_id), payload).SerializeToString(), None
        if op == "timeline":   # payload: JSON {"last": n | null, "after_frame": n | null}
            query = orjson.loads(payload)
            return timeline_dumps(table.timeline(session_id, query["last"], query["after_frame"])), None
        if op == "amap":
            return table.anticipation_png(session_id), None
        if op == "drop":
            table.drop(session_id)
            return b"", None
        raise invalid(f"unknown operation {op!r}")
    except DirectorError:
        raise
    except Exception as exc:  # a bug must not take the worker (and its other sessions) down
        if op == "create":
            table.drop(session_id)
        raise internal(exc, op, session_id, log) from exc


def parse(message_type, payload: bytes, routed_session_id: str | None = None):
    """The request, parsed once; with `routed_session_id` (what the front routed by, reading only
    field 1) INVALID_ARGUMENT when the parsed session_id differs (the field given twice)."""
    try:
        msg = message_type.FromString(payload)
    except Exception:
        raise invalid(f"payload is not a serialized {message_type.DESCRIPTOR.full_name}") from None
    if routed_session_id is not None and msg.session_id != routed_session_id:
        raise invalid(f"session_id is given more than once ({routed_session_id!r}, then {msg.session_id!r})")
    return msg
