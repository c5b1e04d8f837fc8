"""Requests as the transports carry them, to the session table that holds their session: an
operation name, the session id the request was routed by, and the request's bytes in; the reply's
bytes out, and a frame's metrics (infra/channels.py).

The worker's main loop (worker/main.py) and the front's inline table (front/worker_pool.py) call
`Dispatcher.handle_bytes` (and `view`, whose answer comes later). Each request is parsed once,
here, and handed to the table's typed method (table.py); a frame's bytes as received also go on to
the table, which records and checkpoints them as they are.

A session the table does not hold but whose checkpoint is kept (its worker died, its node
restarted, a balancer sent it here) is rebuilt here before its request is answered: the checkpoint
as checkpointing.py loads it, the session built again to its snapshot (`SessionTable.restore`),
then each input since parsed as a request is and computed again (`SessionTable.replay`), then
claimed for this process. When the store refuses an input because another process has taken the
session over (`TakenOver`), the request is answered on the newer state, rebuilt the same way.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TypeVar

import orjson
from google.protobuf.message import Message

from camdirector.errors import DirectorError, internal, invalid, unavailable
from camdirector.infra.channels import FrameMetrics, ViewQuery, decode_create, encode_reply
from camdirector.render.monitor import Reply
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.checkpoint_stores import Checkpoint
from camdirector.worker.checkpointing import TakenOver
from camdirector.worker.table import SessionTable
from camdirector.worker.timeline import dumps as timeline_dumps

log = logging.getLogger("camdirector.sessions")

M = TypeVar("M", bound=Message)
Routed = TypeVar("Routed", pb.FrameUpdate, pb.UpdateStyleRequest, pb.TakeShotRequest)  # requests naming their session
T = TypeVar("T")

# The inputs a checkpoint keeps (checkpoint_stores.OPS), by the op they came as.
INPUTS: dict[str, type[pb.FrameUpdate] | type[pb.UpdateStyleRequest] | type[pb.TakeShotRequest]] = {
    "frame": pb.FrameUpdate,
    "style": pb.UpdateStyleRequest,
    "take": pb.TakeShotRequest,
}


class Dispatcher:
    """One session table's requests (module docstring)."""

    def __init__(self, table: SessionTable):
        self.table = table

    def handle_bytes(self, op: str, session_id: str, payload: bytes) -> tuple[bytes, FrameMetrics | None]:
        """One request (module docstring), answered by the table.

        Raises DirectorError for anything the client must hear about; an unexpected exception
        becomes INTERNAL and leaves the other sessions untouched (a failed create drops its session).
        """
        table = self.table
        try:
            if op == "frame":
                frame = parse_routed(pb.FrameUpdate, payload, session_id)
                return self._on_session(session_id, lambda: table.frame_bytes(frame, payload))
            if op == "create":  # payload: the session's tenant and the request (infra/channels.py)
                tenant, request = decode_create(payload)
                return table.create(
                    session_id, parse(pb.CreateSessionRequest, request), payload, tenant
                ).SerializeToString(), None
            if op == "style":
                style = parse_routed(pb.UpdateStyleRequest, payload, session_id)
                return self._on_session(session_id, lambda: table.update_style(style, payload)).SerializeToString(), None
            if op == "close":
                return self._on_session(session_id, lambda: table.close(session_id)).SerializeToString(), None
            if op == "take":
                take = parse_routed(pb.TakeShotRequest, payload, session_id)
                return self._on_session(session_id, lambda: table.take_shot(take, payload)).SerializeToString(), None
            if op == "timeline":  # payload: JSON {"last": n | null, "after_frame": n | null}
                query = orjson.loads(payload)
                detail = self._on_session(session_id, lambda: table.timeline(session_id, query["last"], query["after_frame"]))
                return timeline_dumps(detail), None
            if op == "amap":
                return self._on_session(session_id, lambda: table.anticipation_png(session_id)), None
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

    def answer(self, request_id: int, op: str, session_id: str, payload: bytes) -> bytes:
        """One request (handle_bytes) answered in the workers' framing (infra/channels.py): its
        reply, or its DirectorError's code and message."""
        try:
            body, metrics = self.handle_bytes(op, session_id, payload)
            return encode_reply(request_id, 0, body, metrics)
        except DirectorError as exc:
            return refusal(request_id, exc)

    def view(self, session_id: str, payload: bytes, reply: Reply) -> None:
        """A monitor's picture of the session (payload: a ViewQuery's JSON, infra/channels.py),
        answered later through `reply(status, body)`, from another thread (SessionTable.view).
        Raises DirectorError at once for an unknown session or a query that is not one."""
        self._on_session(session_id, lambda: self.table.get(session_id))
        try:
            query = ViewQuery.from_json(payload)
        except ValueError as exc:
            raise invalid(str(exc)) from None
        self.table.view(session_id, query, reply)

    def _on_session(self, session_id: str, call: Callable[[], T]) -> T:
        """`call` on the session, rebuilt from its checkpoint first when the table does not hold
        it; again on the newer state when another process has taken the session over."""
        while True:
            if session_id not in self.table.held:
                checkpoint = self.table.checkpoints.load(session_id)
                if checkpoint is not None:  # else the table answers NOT_FOUND
                    self._restore(session_id, checkpoint)
            try:
                return call()
            except TakenOver:
                log.info("session %s was taken over by another process; restoring its newer state", session_id)
                # the restore claims the checkpoint: the input is then written as this process's, or a
                # later restore elsewhere would lack an input this process computed
                self.table.drop(session_id, keep_checkpoint=True)

    def _restore(self, session_id: str, checkpoint: Checkpoint) -> None:
        """The session rebuilt from its checkpoint (module docstring), now held by the table and
        owned by this process. UNAVAILABLE when it does not restore (the session's other requests
        will try again; other sessions are untouched)."""
        table = self.table
        t0 = table.clock()
        try:
            tenant, request = decode_create(checkpoint.create)
            table.restore(session_id, checkpoint, pb.CreateSessionRequest.FromString(request), tenant)
            for _, op, payload in checkpoint.entries:  # as the first time
                try:
                    self._replay(op, session_id, payload)
                except DirectorError:
                    pass  # refused again, as it was the first time
        except Exception as exc:
            table.drop(session_id, keep_checkpoint=True)
            log.exception("session %s: restoring its checkpoint failed", session_id)
            raise unavailable(
                f"session {session_id} could not be restored from its checkpoint: {type(exc).__name__}: {exc}"
            ) from None
        table.claim(session_id)
        log.info(
            "session %s restored from its checkpoint (%d inputs after the snapshot) in %.1f ms",
            session_id,
            len(checkpoint.entries),
            (table.clock() - t0) * 1e3,
        )

    def _replay(self, op: str, session_id: str, payload: bytes) -> None:
        """One input of a checkpoint computed again; an unexpected exception becomes INTERNAL, as
        it did the first time."""
        try:
            self.table.replay(parse_routed(INPUTS[op], payload, session_id))
        except DirectorError:
            raise
        except Exception as exc:
            raise internal(exc, op, session_id, log) from exc


def refusal(request_id: int, error: DirectorError) -> bytes:
    """The reply refusing a request, in the workers' framing: the error's code and message."""
    return encode_reply(request_id, error.code.value[0], error.message.encode(), None)


def parse(message_type: type[M], payload: bytes | memoryview) -> M:
    """The request, parsed once."""
    try:
        return message_type.FromString(payload)
    except Exception:
        raise invalid(f"payload is not a serialized {message_type.DESCRIPTOR.full_name}") from None


def parse_routed(message_type: type[Routed], payload: bytes, routed_session_id: str) -> Routed:
    """The request of a session, parsed once: INVALID_ARGUMENT when its session_id differs from
    the one the front routed it by, reading only field 1 (the field given twice)."""
    msg = parse(message_type, payload)
    if msg.session_id != routed_session_id:
        raise invalid(f"session_id is given more than once ({routed_session_id!r}, then {msg.session_id!r})")
    return msg
