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
and runs the inputs since through the same computations as the first time, writing, sending and
recording nothing again. This module only loads what to rebuild (`Checkpointing.load`: the
creation payload, the snapshot, the inputs since); the rebuild is driven from above it
(worker/dispatch.py, which parses the inputs as it parses requests, and worker/table.py's
`restore` and `replay`). Sessions are deterministic (recordings replay bit for bit), so the
restored session answers its next frame as the lost one would have.

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

from camdirector.errors import unavailable
from camdirector.infra.channels import encode_create
from camdirector.pipeline.session import CreationName
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.checkpoint_stores import (
    Checkpoint,
    CheckpointError,
    CheckpointStore,
    dumps_state,
    encode_entry,
    open_store,
)

log = logging.getLogger("camdirector.sessions")

CHECKPOINT_RETRY_S = 1.0  # a session whose checkpoint write failed tries again this often (a full snapshot), s


@dataclass
class SessionCheckpoint:
    """What the protocol keeps beside one held session."""

    create_payload: bytes = b""  # the create op's payload (tenant, request): a checkpoint lost with its store begins again
    seq: int = 0  # inputs taken (frames not stale, styles, takes): the checkpoint's numbering
    snapshot_seq: int = 0  # the input the last snapshot includes
    retry_s: float | None = None  # a failed write: when to try again (clock), else None

    @property
    def failed(self) -> bool:
        return self.retry_s is not None


class TakenOver(Exception):
    """The store refused an input: another process has taken the session over since (module
    docstring), so this process's copy is behind and is to be restored before the input is computed."""


class Checkpointing:
    """The checkpoint protocol of one session table (module docstring): the stores' reads and
    writes, and when a snapshot is due. Without a store (the setting `checkpoint_store = "off"`)
    it keeps nothing and loads nothing."""

    def __init__(
        self, settings: ServerSettings, clock: Callable[[], float] = time.perf_counter, store: CheckpointStore | None = None
    ):
        """store: where sessions are checkpointed; by default the one settings.checkpoint_store names."""
        self.every_frames = settings.checkpoint_every_frames
        self.clock = clock
        self.store = (
            store if store is not None else open_store(settings.checkpoint_store, settings.data_dir, settings.checkpoint_keep_s)
        )
        self.owner = f"{settings.node_name}/{os.getpid()}"  # this process, in checkpoints' ownership

    @property
    def enabled(self) -> bool:
        return self.store is not None

    def begin(
        self, session_id: str, checkpoint: SessionCheckpoint, req: pb.CreateSessionRequest, payload: bytes | None, tenant: str
    ) -> None:
        """A session created: its checkpoint begins with the create op's payload, the session's
        tenant and its request (`payload`: those bytes as received, when at hand)."""
        if self.store is None:
            return
        checkpoint.create_payload = payload if payload is not None else encode_create(tenant, req.SerializeToString())
        try:
            self.store.begin(session_id, self.owner, checkpoint.create_payload)
        except CheckpointError as exc:
            self._failed(session_id, checkpoint, exc)

    def write_input(self, session_id: str, checkpoint: SessionCheckpoint, op: str, payload: bytes) -> None:
        """Writes one input before it is computed. Raises TakenOver when another process has
        taken the session over: the input is then computed on the newer state, restored."""
        if self.store is None:
            return
        checkpoint.seq += 1
        if checkpoint.failed:
            return  # the snapshot after this input repairs the checkpoint (snapshot_due)
        try:
            owned = self.store.append(session_id, self.owner, encode_entry(checkpoint.seq, op, payload))
        except CheckpointError as exc:
            self._failed(session_id, checkpoint, exc)
            return
        if not owned:
            raise TakenOver(session_id)

    def snapshot_due(self, checkpoint: SessionCheckpoint) -> bool:
        """Whether an input just computed calls for a snapshot: every `every_frames` inputs, or
        once a failed write is to be repaired (its retry time has come)."""
        if self.store is None:
            return False
        if checkpoint.retry_s is not None:
            return self.clock() >= checkpoint.retry_s
        return checkpoint.seq - checkpoint.snapshot_seq >= self.every_frames

    def may_wait(self, checkpoint: SessionCheckpoint) -> bool:
        """Whether a snapshot due may wait for idle time: not once the log has grown to twice its
        period (a worker never idle still cuts it)."""
        return checkpoint.seq - checkpoint.snapshot_seq < 2 * self.every_frames

    def snapshot(
        self,
        session_id: str,
        checkpoint: SessionCheckpoint,
        state: object,
        creation_objects: dict[CreationName, object],
        claim: bool,
    ) -> None:
        """Writes `state` (the session and its style as sent; its deferred work done: a snapshot
        holds computed maps, not the means to compute them) in place of the log; with `claim` (a
        restore) this process takes the session over. After a failed write the checkpoint is
        begun again first (the store may have lost it: Redis restarted)."""
        if self.store is None:
            return
        try:
            data = dumps_state(state, creation_objects)
            if checkpoint.failed:
                self.store.begin(session_id, self.owner, checkpoint.create_payload)
            self.store.snapshot(session_id, self.owner, checkpoint.seq, data, claim=claim)
        except CheckpointError as exc:
            self._failed(session_id, checkpoint, exc)
            return
        if checkpoint.failed:
            log.warning("session %s: checkpoint written again after a failure", session_id)
        checkpoint.snapshot_seq, checkpoint.retry_s = checkpoint.seq, None

    def load(self, session_id: str) -> Checkpoint | None:
        """What rebuilds the session (module docstring), or None when none is kept (or no store).
        UNAVAILABLE when the store cannot be read (the session's other requests will try again)."""
        if self.store is None:
            return None
        try:
            return self.store.load(session_id)
        except CheckpointError as exc:  # its words name the store's URL or folder: the log's, not the client's
            log.warning("session %s cannot be restored now: %s", session_id, exc)
            raise unavailable(f"session {session_id} cannot be restored now: its checkpoint store does not answer") from None

    def end(self, session_id: str, keep_checkpoint: bool) -> None:
        """A session the table no longer holds: its checkpoint is deleted, or with
        `keep_checkpoint` only let go of (the process is stopping, or another one has taken the
        session over)."""
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

    def _failed(self, session_id: str, checkpoint: SessionCheckpoint, exc: CheckpointError) -> None:
        """The session goes on; its checkpoint is written whole again once the store answers."""
        if not checkpoint.failed:
            log.error(
                "session %s: %s; frames are still answered, the checkpoint is written again when the "
                "store answers (tried every %.0f s)",
                session_id,
                exc,
                CHECKPOINT_RETRY_S,
            )
        checkpoint.retry_s = self.clock() + CHECKPOINT_RETRY_S
