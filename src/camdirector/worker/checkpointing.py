"""The checkpoint protocol of a session table: what rebuilds a session exactly after the loss of
its worker or its node. The checkpoints' format and their stores are checkpoint_stores.py's.

An input (a frame that is not stale, a style change, a take) is written before it is computed:
an input answered is never missing from the checkpoint, and one whose worker died before
answering is answered `stale` with the same pose on the client's retry. Writing first is also the
fence between nodes: a write names this process as the owner, a restore claims the checkpoint for
its process, and the store refuses a write by a process that is no longer the owner, so a node
that was bypassed (the balancer sent the session elsewhere, then back) restores the newer state
instead of answering from its old copy.

Every `checkpoint_every_frames` inputs a snapshot replaces the log: at once, or with
`defer_snapshots` (a worker's table) in the worker's idle moments (`SessionTable.idle_work`),
unless the log has grown to twice that (a worker never idle still cuts it). A snapshot holds
computed maps, not the means to compute them: the session's deferred work is done first. The
dashboard's timeline of recent frames is left out (diagnostics, up to a megabyte), so a restored
session's starts anew.

Restoring builds the session again from its creation request (with its tenant, whose levels it
finds again: the create op's payload is kept whole, infra/channels.py), puts the snapshot's state in place,
and runs the inputs since through the session table's own request handling (`handle_bytes`, the
code that replays recordings, recording.py), writing, sending and recording nothing again.
Sessions are deterministic (recordings replay bit for bit), so the restored session answers its
next frame as the lost one would have.

A write that fails (Redis down, a full disk) fails no frame: the session goes on, each answer's
metrics say so (`FrameMetrics.checkpoint_failed`), and once the store answers again (tried every
CHECKPOINT_RETRY_S) the checkpoint is written again whole: begun anew, then a snapshot.
"""
from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from camdirector.errors import DirectorError, not_found, unavailable
from camdirector.infra.channels import decode_create, encode_create
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.checkpoint_stores import (
    CheckpointError,
    CheckpointStore,
    dumps_state,
    encode_entry,
    loads_state,
    open_store,
)

if TYPE_CHECKING:  # the table holds this protocol, which restores sessions through the table
    from camdirector.worker.table import HeldSession, SessionTable

log = logging.getLogger("camdirector.sessions")

CHECKPOINT_RETRY_S = 1.0  # a session whose checkpoint write failed tries again this often (a full snapshot), s


@dataclass
class SessionCheckpoint:
    """What the protocol keeps beside one held session."""

    create_payload: bytes = b""      # the create op's payload (tenant, request): a checkpoint lost with its store begins again
    seq: int = 0                     # inputs taken (frames not stale, styles, takes): the checkpoint's numbering
    snapshot_seq: int = 0            # the input the last snapshot includes
    retry_s: float | None = None     # a failed write: when to try again (clock), else None

    @property
    def failed(self) -> bool:
        return self.retry_s is not None


class Checkpointing:
    """The checkpoint protocol of one session table (module docstring); without a store (the
    setting `checkpoint_store = "off"`) it keeps nothing and restores nothing."""

    def __init__(self, table: SessionTable, settings: ServerSettings, clock: Callable[[], float] = time.perf_counter,
                 store: CheckpointStore | None = None):
        """store: where sessions are checkpointed; by default the one settings.checkpoint_store names."""
        self.table = table
        self.every_frames = settings.checkpoint_every_frames
        self.clock = clock
        self.store = store if store is not None else open_store(
            settings.checkpoint_store, settings.data_dir, settings.checkpoint_keep_s)
        self.owner = f"{settings.node_name}/{os.getpid()}"  # this process, in checkpoints' ownership
        self.replaying = False   # restoring: the inputs since the snapshot are not written, sent or recorded again
        self.defer_snapshots = False  # snapshots due wait for idle time (module docstring)
        self._due: dict[str, HeldSession] = {}

    @property
    def enabled(self) -> bool:
        return self.store is not None

    def begin(self, held: HeldSession, req: pb.CreateSessionRequest, payload: bytes | None, tenant: str) -> None:
        """A session created: its checkpoint begins with the create op's payload, the session's
        tenant and its request (`payload`: those bytes as received, when at hand). A restored
        session's is kept as it is."""
        if self.store is None:
            return
        held.checkpoint.create_payload = payload if payload is not None else encode_create(tenant, req.SerializeToString())
        if not self.replaying:
            try:
                self.store.begin(held.session.id, self.owner, held.checkpoint.create_payload)
            except CheckpointError as exc:
                self._failed(held, exc)

    def write_input(self, session_id: str, held: HeldSession, op: str, payload: bytes) -> HeldSession:
        """Writes one input before it is computed. Answers the session to compute it on: `held`,
        or the newer state restored when another process has taken the session over."""
        if self.replaying or self.store is None:
            return held
        checkpoint = held.checkpoint
        checkpoint.seq += 1
        if checkpoint.failed:
            return held   # the snapshot after this input repairs the checkpoint (after_input)
        try:
            owned = self.store.append(session_id, self.owner, encode_entry(checkpoint.seq, op, payload))
        except CheckpointError as exc:
            self._failed(held, exc)
            return held
        if owned:
            return held
        log.info("session %s was taken over by another process; restoring its newer state", session_id)
        self.table.drop(session_id, keep_checkpoint=True)
        # the restore claims the checkpoint: this input is then written as this process's, or a
        # later restore elsewhere would lack an input this process computed
        return self.write_input(session_id, self.restore(session_id), op, payload)

    def after_input(self, held: HeldSession) -> None:
        """A snapshot when one is due, or when a failed write is to be repaired: taken at once,
        or with `defer_snapshots` left for idle time unless the log has grown to twice its period."""
        if self.replaying or self.store is None:
            return
        checkpoint = held.checkpoint
        if checkpoint.failed:
            due = self.clock() >= checkpoint.retry_s
        else:
            due = checkpoint.seq - checkpoint.snapshot_seq >= self.every_frames
        if not due:
            return
        if self.defer_snapshots and checkpoint.seq - checkpoint.snapshot_seq < 2 * self.every_frames:
            self._due[held.session.id] = held
        else:
            self._due.pop(held.session.id, None)
            self._snapshot(held, claim=False)

    @property
    def snapshots_due(self) -> bool:
        """Whether a snapshot waits for idle time."""
        return bool(self._due)

    def take_due_snapshot(self) -> None:
        """The oldest snapshot left for idle time, if one is (0.5-1 ms)."""
        if self._due:
            self._snapshot(self._due.pop(next(iter(self._due))), claim=False)

    def restore(self, session_id: str) -> HeldSession:
        """The session rebuilt from its checkpoint (module docstring), now held by the table and
        owned by this process. NOT_FOUND without one; UNAVAILABLE when the store cannot be read or
        the checkpoint does not restore (the session's other requests will try again; other
        sessions are untouched)."""
        if self.store is None:
            raise not_found(f"unknown session id {session_id!r} (closed, reclaimed, or never created)")
        try:
            checkpoint = self.store.load(session_id)
        except CheckpointError as exc:
            raise unavailable(f"session {session_id} cannot be restored now: {exc}") from None
        if checkpoint is None:
            raise not_found(f"unknown session id {session_id!r} (closed, reclaimed, or never created)")
        t0 = self.clock()
        self.replaying = True
        try:
            tenant, request = decode_create(checkpoint.create)
            req = pb.CreateSessionRequest.FromString(request)
            self.table.create(session_id, req, checkpoint.create, tenant)
            held = self.table.held[session_id]
            if checkpoint.snapshot is not None:
                built = held.session
                held.session, held.style_msg = loads_state(checkpoint.snapshot, built.creation_objects())
                built.close()
            held.checkpoint.seq = held.checkpoint.snapshot_seq = checkpoint.seq
            for seq, op, payload in checkpoint.entries:  # as replay does (recording.py)
                try:
                    self.table.handle_bytes(op, session_id, payload)
                except DirectorError:
                    pass  # refused again, as it was the first time
                held.checkpoint.seq = seq
        except Exception as exc:
            self.table.drop(session_id, keep_checkpoint=True)
            log.exception("session %s: restoring its checkpoint failed", session_id)
            raise unavailable(f"session {session_id} could not be restored from its checkpoint: "
                              f"{type(exc).__name__}: {exc}") from None
        finally:
            self.replaying = False
        self._snapshot(held, claim=True)
        log.info("session %s restored from its checkpoint (%d inputs after the snapshot) in %.1f ms",
                 session_id, len(checkpoint.entries), (self.clock() - t0) * 1e3)
        return held

    def end(self, session_id: str, keep_checkpoint: bool) -> None:
        """A session the table no longer holds: no snapshot of it waits any more, and its
        checkpoint is deleted, or with `keep_checkpoint` only let go of (the process is stopping,
        or another one has taken the session over)."""
        self._due.pop(session_id, None)
        if self.store is None:
            return
        try:
            if keep_checkpoint:
                self.store.forget(session_id)
            else:
                self.store.delete(session_id, self.owner)
        except CheckpointError as exc:
            log.warning("session %s: its checkpoint stays behind: %s", session_id, exc)

    def close(self) -> None:
        if self.store is not None:
            self.store.close()

    def _snapshot(self, held: HeldSession, claim: bool) -> None:
        """A snapshot; with `claim` (a restore) this process takes the session over; after a failed
        write the checkpoint is begun again first (the store may have lost it: Redis restarted)."""
        session, checkpoint = held.session, held.checkpoint
        self.table.finish_deferred_work(held)   # a snapshot holds computed maps, not the means to compute them
        try:
            # Not the dashboard's timeline: diagnostics, not state, up to 1 MB; a restored session's starts anew.
            state = dumps_state((session, held.style_msg), session.creation_objects())
            if checkpoint.failed:
                self.store.begin(session.id, self.owner, checkpoint.create_payload)
            self.store.snapshot(session.id, self.owner, checkpoint.seq, state, claim=claim)
        except CheckpointError as exc:
            self._failed(held, exc)
            return
        if checkpoint.failed:
            log.warning("session %s: checkpoint written again after a failure", session.id)
        checkpoint.snapshot_seq, checkpoint.retry_s = checkpoint.seq, None

    def _failed(self, held: HeldSession, exc: CheckpointError) -> None:
        """The session goes on; its checkpoint is written whole again once the store answers."""
        if not held.checkpoint.failed:
            log.error("session %s: %s; frames are still answered, the checkpoint is written again when the "
                      "store answers (tried every %.0f s)", held.session.id, exc, CHECKPOINT_RETRY_S)
        held.checkpoint.retry_s = self.clock() + CHECKPOINT_RETRY_S
