"""The front process's view of the sessions: which worker holds each, which are streaming, and
when an abandoned one is reclaimed. Both transports call this one object.

With checkpoints (the default; worker/checkpointing.py) no session is lost with its worker: the
sessions of a worker that died are given at once to the least loaded of the others (the same one
when there is no other, which is then awaited while it restarts), and their next request restores
them there. A client's request for a session this node does not know (this node restarted, or the
balancer sent the session here from a node that died) is given to a worker the same way, which
restores it from the checkpoint store or answers NOT_FOUND.

Every session belongs to a tenant (access/roles.py): the tenant of the key that created it. A
request naming another tenant's session is answered NOT_FOUND with the words an unknown id gets.
With authentication on, each session's tenant is also written to the records database, so a node
that adopts the session after its first node died knows whose it is. Those records are read and
written off the event loop (Guard.off_loop): a hung database delays the requests that need it, never
the frames of the sessions held here.
"""

from __future__ import annotations

import asyncio
import logging
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Protocol

import orjson

from camdirector.access.guard import Guard
from camdirector.access.keys import AccessUnavailable
from camdirector.errors import DirectorError, exhausted, invalid, not_found, unavailable
from camdirector.front.metrics import Metrics
from camdirector.front.worker_pool import WorkerPool
from camdirector.infra.channels import encode_create
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb

log = logging.getLogger("camdirector.sessions")

LOST_IDS_KEPT = 10_000  # ids of sessions lost with their worker, remembered to say so (oldest forgotten first)
RESEND_BURST_S = 20.0  # a session may send again this many seconds of frames (at tenant_max_fps) beyond its rate, s


class FrameRoutes(Protocol):
    """Where a session's frames may be answered without the router (_native.Edge)."""

    def route(self, session_id: str, slot: int, tenant: str, tokens: float, resend: float, age_s: float | None) -> None: ...

    def unroute(self, session_id: str) -> tuple[float, float] | None: ...


@dataclass
class SessionEntry:
    slot: int
    created_s: float
    last_seen_s: float
    streams: int = 0
    frames: int = 0
    transport: set[str] = field(default_factory=set)
    restoring: bool = False  # given to a worker that has to restore it from its checkpoint first
    tenant: str = "default"  # the tenant of the key that created it
    frame_tokens: float = 0.0  # frames it may still send at once (the tenant's rate limit, _admit_frame)
    resend_tokens: float = 0.0  # frames it may send beyond those after a DATA_LOSS (_admit_frame)
    tokens_at_s: float = 0.0
    routed: bool = False  # its gRPC frames go from the compiled edge straight to its worker (attach_edge)


class SessionRouter:
    def __init__(
        self, settings: ServerSettings, metrics: Metrics, clock: Callable[[], float] = time.monotonic, guard: Guard | None = None
    ):
        self.settings = settings
        self.guard = guard or Guard(None)
        self.metrics = metrics
        self.clock = clock
        self.pool = WorkerPool(settings, on_worker_lost=self._worker_lost)
        self.checkpoints = settings.checkpoint_store != "off"
        self.sessions: dict[str, SessionEntry] = {}
        # session id -> (the worker slot that died with it, the session's tenant)
        self._lost: OrderedDict[str, tuple[int, str]] = OrderedDict()
        self._reserved = 0  # creations in flight, counted against max_sessions
        self._reserved_by: dict[str, int] = {}  # the same by tenant, against tenant_max_sessions
        self._reaper: asyncio.Task | None = None
        self.edge: FrameRoutes | None = None  # the compiled edge, when it serves gRPC or ZeroMQ
        self._edge_counts: Callable[[], None] = lambda: None  # brings the edge's frame counts here (edge_answered)

    def attach_edge(self, edge: FrameRoutes, counts: Callable[[], None]) -> None:
        """The compiled edge (front/edge.py) answers the frames of the sessions routed to
        it (`route_to_edge`) without this router: a session is routed there after a frame (of a stream,
        or a Frame call) answered here, and taken back whenever its worker, its life or its state changes here.
        `counts()` brings what it answered to `edge_answered`: called before sessions are described,
        so a frame its client has had the answer to is counted."""
        self.edge = edge
        self._edge_counts = counts

    def route_to_edge(self, session_id: str) -> None:
        """Routes the session's frames to the edge, with its rate bucket (_admit_frame), unless it
        is restoring (its next frame must come here) or already routed."""
        entry = self.sessions.get(session_id)
        if self.edge is None or entry is None or entry.routed or entry.restoring:
            return
        entry.routed = True
        age_s = self.clock() - entry.tokens_at_s if entry.tokens_at_s else None
        self.edge.route(session_id, entry.slot, entry.tenant, entry.frame_tokens, entry.resend_tokens, age_s)

    def _unroute(self, session_id: str, entry: SessionEntry) -> None:
        """Takes the session's frames back from the edge, with its rate bucket as the edge left it."""
        if self.edge is None or not entry.routed:
            return
        entry.routed = False
        bucket = self.edge.unroute(session_id)
        if bucket is not None:
            entry.frame_tokens, entry.resend_tokens = bucket
            entry.tokens_at_s = self.clock()

    def edge_answered(self, frames_by_session: list[tuple[str, int, set[str]]]) -> None:
        """Frames the edge answered since it was last asked, (session id, frames, transports):
        counted as answered here would be."""
        now = self.clock()
        for session_id, frames, transports in frames_by_session:
            entry = self.sessions.get(session_id)
            if entry is not None:
                entry.frames += frames
                entry.last_seen_s = now
                entry.transport.update(transports)

    async def start(self) -> None:
        await self.pool.start()
        self._reaper = asyncio.create_task(self._reap_forever())

    async def stop(self) -> None:
        if self._reaper is not None:
            self._reaper.cancel()
        await self.pool.stop()

    def _entry(self, session_id: str, tenant: str) -> SessionEntry:
        """The session's entry, when this node holds it for `tenant` (the dashboard's requests,
        which never move a session here); else `_refused`."""
        entry = self.sessions.get(session_id)
        if entry is not None and entry.tenant == tenant:
            return entry
        raise self._refused(session_id, tenant)

    async def _client_entry(self, session_id: str, tenant: str) -> SessionEntry:
        """The session's entry for a request of its client. With checkpoints, an unknown session
        of the tenant is given to the least loaded worker to restore (module docstring). An id
        that is not the tenant's, unknown or another tenant's (held here, or lost with its
        worker), takes one path: the same owner lookup, the same NOT_FOUND, so neither its answer
        nor its time tells which it was."""
        entry = self.sessions.get(session_id)
        if entry is not None and entry.tenant == tenant:
            return entry
        if self.checkpoints and await self._owner(session_id) == tenant:
            entry = self.sessions.get(session_id)  # another request may have adopted it while the owner was read
            if entry is None:
                now = self.clock()
                entry = self.sessions[session_id] = SessionEntry(
                    slot=self._least_loaded_slot(), created_s=now, last_seen_s=now, restoring=True, tenant=tenant
                )
            if entry.tenant == tenant:
                return entry
        raise self._refused(session_id, tenant)

    def _refused(self, session_id: str, tenant: str) -> DirectorError:
        """The answer to a request naming a session that is not the tenant's here: UNAVAILABLE for
        one of its own lost with its worker, NOT_FOUND for any other."""
        lost = self._lost.get(session_id)
        if lost is not None and lost[1] == tenant:
            return unavailable(
                f"session {session_id!r} was lost: the worker process holding it (worker {lost[0]}) died; create a new session"
            )
        return not_found(f"unknown session id {session_id!r} (closed, reclaimed, or never created)")

    async def _owner(self, session_id: str) -> str | None:
        """The tenant of a session this node does not hold: from the records database with
        authentication on (None: no such session), `default` without."""
        if not self.guard.enabled:
            return "default"
        return await self.guard.off_loop(self.guard.key_store().session_owner, session_id)

    async def _forget(self, session_id: str) -> None:
        if self.guard.enabled:
            await self.guard.off_loop(self.guard.key_store().forget_session, session_id)

    def _least_loaded_slot(self, exclude: int | None = None) -> int:
        load = [0] * self.pool.slots
        for entry in self.sessions.values():
            load[entry.slot] += 1
        slots = [slot for slot in range(len(load)) if slot != exclude] or list(range(len(load)))
        return min(slots, key=load.__getitem__)

    async def _call(self, entry: SessionEntry, op: str, session_id: str, payload: bytes, timeout_s: float | None = None):
        """pool.call for a session's request; a restoring session is known here only once its
        worker has restored it (NOT_FOUND there: it has no checkpoint, and is forgotten)."""
        try:
            result = await self.pool.call(entry.slot, op, session_id, payload, timeout_s)
        except DirectorError as exc:
            if entry.restoring and exc.code.name == "NOT_FOUND" and self.sessions.get(session_id) is entry:
                del self.sessions[session_id]
                self._unroute(session_id, entry)
            raise
        if entry.restoring:
            entry.restoring = False
            self.metrics.sessions_restored.inc()
            self.metrics.sessions.set(len(self.sessions))
        return result

    async def create(self, payload: bytes, transport: str, tenant: str = "default") -> bytes:
        if len(self.sessions) + self._reserved >= self.settings.max_sessions:
            raise exhausted(f"the server holds its maximum of {self.settings.max_sessions} sessions")
        if self.guard.enabled:  # tenants' shares: with keys only (without, everyone is one tenant)
            held = sum(e.tenant == tenant for e in self.sessions.values()) + self._reserved_by.get(tenant, 0)
            if held >= self.settings.tenant_max_sessions:
                raise exhausted(
                    f"tenant {tenant!r} has its maximum of {self.settings.tenant_max_sessions} sessions "
                    "open on this node; close one first"
                )
        session_id = uuid.uuid4().hex
        slot = self._least_loaded_slot()
        self._reserved += 1  # until the session is in `sessions`: both limits count it across every await
        self._reserved_by[tenant] = self._reserved_by.get(tenant, 0) + 1
        try:
            body, _ = await self.pool.call(slot, "create", session_id, encode_create(tenant, payload))
            if self.guard.enabled:
                try:
                    await self.guard.off_loop(self.guard.key_store().set_session_owner, session_id, tenant)
                except BaseException:  # unrecorded (the database down, the caller gone): nobody could find it again
                    await self.pool.call(slot, "drop", session_id, b"")
                    raise
            now = self.clock()
            self.sessions[session_id] = SessionEntry(
                slot=slot, created_s=now, last_seen_s=now, transport={transport}, tenant=tenant
            )
        finally:
            self._reserved -= 1
            self._reserved_by[tenant] -= 1
        self.metrics.sessions.set(len(self.sessions))
        self.metrics.sessions_created.inc()
        return body

    async def frame(self, payload: bytes, session_id: str, transport: str, tenant: str = "default") -> bytes:
        entry = await self._client_entry(session_id, tenant)
        if self.guard.enabled:
            self._admit_frame(entry, session_id)
        entry.last_seen_s = self.clock()
        try:
            body, frame_metrics = await self._call(entry, "frame", session_id, payload)
        except DirectorError as exc:
            if exc.code.name == "DATA_LOSS":  # the updates since are on their way again, at once
                entry.resend_tokens = self.settings.tenant_max_fps * RESEND_BURST_S
            raise
        entry.frames += 1
        entry.transport.add(transport)
        self.metrics.frame_answered(
            transport, frame_metrics.compute_ms, frame_metrics.stage_ms, frame_metrics.stale, frame_metrics.checkpoint_failed
        )
        return body

    def _admit_frame(self, entry: SessionEntry, session_id: str) -> None:
        """The tenant's frame rate per session as a token bucket holding one second's frames:
        RESOURCE_EXHAUSTED (the frame is not answered, the session goes on) when it is empty.
        After its worker answered DATA_LOSS (restored from a checkpoint that fell behind), the
        session may send RESEND_BURST_S of frames more at once: its client sends the updates since
        again, seconds of them. Only the server's own DATA_LOSS grants them."""
        rate = self.settings.tenant_max_fps
        now = self.clock()
        entry.frame_tokens = min(rate, entry.frame_tokens + (now - entry.tokens_at_s) * rate) if entry.tokens_at_s else rate
        entry.tokens_at_s = now
        if entry.frame_tokens >= 1.0:
            entry.frame_tokens -= 1.0
        elif entry.resend_tokens >= 1.0:
            entry.resend_tokens -= 1.0
        else:
            raise exhausted(f"session {session_id} sends more than {rate:g} frames a second, its tenant's limit")

    async def _session_request(self, message_type, op: str, payload: bytes, tenant: str) -> bytes:
        """A serialized request of the session it names (a client's: it keeps the session alive)
        to that session's worker; the serialized answer back."""
        session_id = session_id_of(message_type, payload)
        entry = await self._client_entry(session_id, tenant)
        entry.last_seen_s = self.clock()
        body, _ = await self._call(entry, op, session_id, payload)
        return body

    async def update_style(self, payload: bytes, tenant: str = "default") -> bytes:
        return await self._session_request(pb.UpdateStyleRequest, "style", payload, tenant)

    async def take_shot(self, payload: bytes, tenant: str = "default") -> bytes:
        """A serialized TakeShotRequest in, a serialized TakeShotResponse out (a MATCH session's take)."""
        return await self._session_request(pb.TakeShotRequest, "take", payload, tenant)

    async def close(self, payload: bytes, tenant: str = "default") -> bytes:
        session_id = session_id_of(pb.CloseSessionRequest, payload)
        entry = await self._client_entry(session_id, tenant)
        self._unroute(session_id, entry)  # before the worker closes it: no frame of the edge's follows
        body, _ = await self._call(entry, "close", session_id, payload)
        self.sessions.pop(session_id, None)
        self.metrics.sessions.set(len(self.sessions))
        try:
            await self._forget(session_id)
        except AccessUnavailable as exc:  # closed all the same: its owner record names a session with no checkpoint
            log.warning("forgetting the owner of closed session %s: %s", session_id, exc)
        return body

    async def stream_opened(self, session_id: str, tenant: str = "default") -> None:
        (await self._client_entry(session_id, tenant)).streams += 1

    def stream_closed(self, session_id: str) -> None:
        entry = self.sessions.get(session_id)
        if entry is not None:
            entry.streams -= 1
            entry.last_seen_s = self.clock()

    async def reap_once(self) -> list[str]:
        """Reclaims sessions with no stream and no request for `session_resume_s`."""
        now = self.clock()
        idle = [
            sid for sid, e in self.sessions.items() if e.streams == 0 and now - e.last_seen_s > self.settings.session_resume_s
        ]
        for session_id in idle:
            entry = self.sessions.pop(session_id)
            self._unroute(session_id, entry)
            try:
                await self._forget(session_id)
            except AccessUnavailable as exc:  # the worker drops it all the same: nobody may come back to it
                log.warning("forgetting the owner of session %s: %s", session_id, exc)
            try:
                await self.pool.call(entry.slot, "drop", session_id, b"")
            except DirectorError as exc:
                log.warning("dropping session %s: %s", session_id, exc.message)
            self.metrics.sessions_reclaimed.inc()
            log.info("reclaimed idle session %s after %.1f s", session_id, now - entry.last_seen_s)
        self.metrics.sessions.set(len(self.sessions))
        return idle

    async def _reap_forever(self) -> None:
        while True:
            await asyncio.sleep(self.settings.reap_interval_s)
            try:
                await self.reap_once()
            except Exception:  # the reaper must outlive any one bad session
                log.exception("session reaper")

    def _worker_lost(self, slot: int) -> None:
        lost = [sid for sid, e in self.sessions.items() if e.slot == slot]
        if self.checkpoints:  # each to the least loaded other worker, which restores it on its next request
            for session_id in lost:
                entry = self.sessions[session_id]
                self._unroute(session_id, entry)
                entry.slot, entry.restoring = self._least_loaded_slot(exclude=slot), True
            log.error("worker %d died; its %d sessions are restored from their checkpoints on other workers", slot, len(lost))
            return
        for session_id in lost:
            entry = self.sessions.pop(session_id)
            self._unroute(session_id, entry)
            self._lost[session_id] = (slot, entry.tenant)
            self.metrics.sessions_reclaimed.inc()
        while len(self._lost) > LOST_IDS_KEPT:
            self._lost.popitem(last=False)
        self.metrics.sessions.set(len(self.sessions))
        log.error("worker %d lost %d sessions", slot, len(lost))

    async def timeline(
        self, session_id: str, last: int | None = None, after_frame: int | None = None, tenant: str = "default"
    ) -> dict:
        """The session's summary (as `describe`), style and newest `last` frames after
        `after_frame` (sessions.py); NOT_FOUND for an unknown id. Not a request of the session's
        client: it does not keep the session alive."""
        self._edge_counts()
        entry = self._entry(session_id, tenant)
        body, _ = await self.pool.call(
            entry.slot, "timeline", session_id, orjson.dumps({"last": last, "after_frame": after_frame})
        )
        return {"session": self._describe(session_id, entry, self.clock()), **orjson.loads(body)}

    async def anticipation_png(self, session_id: str, tenant: str = "default") -> bytes:
        """The session's A-map as a PNG (sessions.py); NOT_FOUND, or FAILED_PRECONDITION without one."""
        body, _ = await self.pool.call(self._entry(session_id, tenant).slot, "amap", session_id, b"")
        return body

    async def view(self, session_id: str, query_json: bytes, timeout_s: float, tenant: str = "default") -> bytes:
        """A monitor's picture of the session (render/snapshots.py), its serialized view
        (render/monitor.py); NOT_FOUND for an unknown id, UNAVAILABLE when it takes more than
        timeout_s. Not a request of the session's client: it does not keep the session alive."""
        try:
            body, _ = await self.pool.call(self._entry(session_id, tenant).slot, "view", session_id, query_json, timeout_s)
        except TimeoutError:
            raise unavailable(f"the view of session {session_id} took more than {timeout_s:g} s") from None
        return body

    def describe(self, tenant: str = "default") -> list[dict]:
        self._edge_counts()
        now = self.clock()
        return [self._describe(sid, e, now) for sid, e in self.sessions.items() if e.tenant == tenant]

    @staticmethod
    def _describe(session_id: str, e: SessionEntry, now: float) -> dict:
        return {
            "session_id": session_id,
            "worker": e.slot,
            "frames": e.frames,
            "streams": e.streams,
            "idle_s": round(now - e.last_seen_s, 3),
            "age_s": round(now - e.created_s, 3),
            "transports": sorted(e.transport),
        }


def varint_at(payload: bytes, at: int) -> tuple[int, int]:
    """The varint at payload[at:] and the index after it; IndexError past the end."""
    value = shift = 0
    while True:
        byte = payload[at]
        at += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, at
        shift += 7
        if shift > 63:
            raise ValueError("varint longer than 10 bytes")


def named_session(rpc: str, payload: bytes) -> str | None:
    """The session a request names, for the log of one that failed: its field 1 when readable;
    None for CreateSession (whose field 1 is the scene) or an unreadable payload."""
    if rpc == "CreateSession":
        return None
    try:
        return session_id_of(pb.FrameUpdate, payload)  # the type only names what was expected in its errors
    except DirectorError:
        return None


def wire_fields(payload: bytes) -> Iterator[tuple[int, int, int, int]]:
    """Each top-level field of a serialized message as (field number, wire type, start, end), in
    order, read from the protobuf wire format without parsing the rest: payload[start:end] is a
    varint's bytes, a length-delimited field's contents or a fixed field's 8 or 4 bytes.
    ValueError at the first bytes that are not a field (truncated, field number 0, a group)."""
    at, end = 0, len(payload)
    while at < end:
        try:
            key, at = varint_at(payload, at)
            field_number, wire_type = key >> 3, key & 7
            if wire_type == 0:
                _, after = varint_at(payload, at)
            elif wire_type == 1:
                after = at + 8
            elif wire_type == 5:
                after = at + 4
            elif wire_type == 2:
                length, at = varint_at(payload, at)
                after = at + length
            else:
                raise ValueError(f"wire type {wire_type}")
        except IndexError:
            raise ValueError("a field cut short") from None
        if field_number == 0 or after > end:
            raise ValueError("not a field")
        yield field_number, wire_type, at, after
        at = after


def session_id_of(message_type, payload: bytes) -> str:
    """The session_id (field 1, a string, in every request that names a session) of a serialized
    request, read from the protobuf wire format without parsing the rest: the front routes by it
    and the worker parses the message once. Fields before it are skipped by their wire type; the
    first occurrence counts (the worker refuses a message whose parsed session_id differs, so
    this never routes one session's frame to another). INVALID_ARGUMENT when it cannot be read."""
    try:
        for field_number, wire_type, start, end in wire_fields(payload):
            if field_number == 1 and wire_type == 2:
                session_id = payload[start:end].decode("utf-8")
                break
        else:
            session_id = ""
    except ValueError:  # not a field, or not UTF-8
        raise invalid(f"payload is not a serialized {message_type.DESCRIPTOR.full_name}") from None
    if not session_id:
        raise invalid("session_id is empty")
    return session_id
