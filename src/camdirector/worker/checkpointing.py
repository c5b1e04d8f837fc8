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

A store that may hang (Redis) has its calls made off the frame path, in order, by a thread of the
table's (checkpoint_writer.py); a write's result is waited for at most `checkpoint_wait_ms`, which a store
that answers meets, so the fence above holds. A write that fails (Redis down, a full disk) or that
the store does not answer within that (Redis paused) fails no frame: the session goes on, its
checkpoint behind, each answer's metrics say so (`FrameMetrics.checkpoint_failed`), no input of
it is queued meanwhile, and once the store answers again (the writer's probe; tried at most every
CHECKPOINT_RETRY_S) the checkpoint is written again whole: begun anew, then a snapshot.

A checkpoint behind can meet the loss of its node: the session restored elsewhere is then older
than what its client was answered. The client says which frame it was last answered
(`FrameUpdate.answered_frame`); a session that has not taken that frame answers DATA_LOSS "state
lost after frame N: resend from N+1" (`check_answered`), and the client's updates from N+1 on,
sent again, bring it to exactly where it was (sessions are deterministic). A frame at or before
the client's `answered_frame` is such a resend and is not checked.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar, cast

from camdirector.errors import data_loss, unavailable
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
from camdirector.worker.checkpoint_writer import CheckpointWriter, InlineWriter

log = logging.getLogger("camdirector.sessions")

T = TypeVar("T")

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


# A session's first write (its create) is waited for this long, not checkpoint_wait_ms: creation is
# not on the frame path, and a session whose checkpoint never began can be restored nowhere. A
# first write also connects to the store: in the container cluster over 10 ms, and the node-kill
# test lost the sessions whose begin had missed the budget (docs/scaling.md), s.
BEGIN_WAIT_S = 1.0


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
        self.wait_s = settings.checkpoint_wait_ms * 1e-3
        self.writer: CheckpointWriter | InlineWriter | None = None
        if self.store is not None:
            self.writer = CheckpointWriter(self.store.ping) if self.store.may_hang else InlineWriter()
        self._taken_over: set[str] = set()  # sessions a write was refused for after its frame went on (the writer's thread adds)

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
        self._write(
            session_id, checkpoint, self.store.begin, session_id, self.owner, checkpoint.create_payload, wait_s=BEGIN_WAIT_S
        )

    def write_input(self, session_id: str, checkpoint: SessionCheckpoint, op: str, payload: bytes) -> None:
        """Writes one input before it is computed. Raises TakenOver when another process has
        taken the session over (the store refused this write, or one whose result came after its
        frame went on): the input is then computed on the newer state, restored."""
        if self.store is None:
            return
        if session_id in self._taken_over:
            self._taken_over.discard(session_id)
            raise TakenOver(session_id)
        checkpoint.seq += 1
        if checkpoint.failed:
            return  # the snapshot after this input repairs the checkpoint (snapshot_due)
        entry = encode_entry(checkpoint.seq, op, payload)
        owned = self._write(session_id, checkpoint, self.store.append, session_id, self.owner, entry)
        if owned is False:
            self._taken_over.discard(session_id)
            raise TakenOver(session_id)

    @staticmethod
    def check_answered(session_id: str, update: pb.FrameUpdate, last_frame: int | None) -> None:
        """DATA_LOSS when the client was answered a frame that the session, `last_frame` the
        newest it took (None: none), has not taken: restored from a checkpoint that was behind
        (module docstring). A frame at or before `answered_frame` is a resend, not checked."""
        answered = update.answered_frame
        taken = last_frame or 0
        if taken < answered < update.frame:
            raise data_loss(
                f"session {session_id}: state lost after frame {taken}: resend from {taken + 1} (its node was lost "
                f"while its checkpoint was behind; the client was answered up to frame {answered})"
            )

    def snapshot_due(self, checkpoint: SessionCheckpoint) -> bool:
        """Whether an input just computed calls for a snapshot: every `every_frames` inputs, or
        once a failed write is to be repaired (its retry time has come and the store answers)."""
        if self.writer is None:
            return False
        if checkpoint.retry_s is not None:
            return self.clock() >= checkpoint.retry_s and self.writer.healthy and not self.writer.stuck(self.wait_s)
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
        data = dumps_state(state, creation_objects)
        create_again = checkpoint.create_payload if checkpoint.failed else None
        written = self._write(session_id, checkpoint, self._rewrite, session_id, create_again, checkpoint.seq, data, claim)
        if written is None:
            return
        if checkpoint.failed:
            log.warning("session %s: checkpoint written again after a failure", session_id)
        checkpoint.snapshot_seq, checkpoint.retry_s = checkpoint.seq, None

    def _rewrite(self, session_id: str, create_again: bytes | None, seq: int, data: bytes, claim: bool) -> bool:
        """On the writer's thread: a snapshot, after beginning the checkpoint again with
        `create_again` when its writes had failed."""
        assert self.store is not None
        if create_again is not None:
            self.store.begin(session_id, self.owner, create_again)
        return self.store.snapshot(session_id, self.owner, seq, data, claim=claim)

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
        session over). Not waited for."""
        if self.store is None or self.writer is None:
            return
        self._taken_over.discard(session_id)
        self.writer.call(self._let_go, session_id, keep_checkpoint)

    def _let_go(self, session_id: str, keep_checkpoint: bool) -> None:
        """On the writer's thread: end's store call; a failure only logged (the checkpoint expires)."""
        assert self.store is not None
        try:
            if keep_checkpoint:
                self.store.forget(session_id)
            else:
                self.store.delete(session_id, self.owner)
        except CheckpointError as exc:
            log.warning("session %s: its checkpoint stays behind: %s", session_id, exc)

    def close(self) -> None:
        """The writes given so far made (checkpoint_writer.CLOSE_WAIT_S at most), then the store closed."""
        if self.writer is not None:
            self.writer.close()
        if self.store is not None:
            self.store.close()

    def _write(
        self, session_id: str, checkpoint: SessionCheckpoint, fn: Callable[..., T], *args: object, wait_s: float | None = None
    ) -> T | None:
        """`fn(*args)` (a store call) made by the writer, its result waited for up to the budget
        (checkpoint_wait_ms, or `wait_s` when longer);
        None, the checkpoint marked behind, when the store failed, did not answer in time, or is
        known not to answer (then nothing is given to it). A refusal (False) whose result comes
        after the budget is noted, and the session's next input raises TakenOver."""
        assert self.writer is not None
        if isinstance(self.writer, InlineWriter):
            # A store that cannot hang (a local folder) is called here and now, its refusal noted
            # as ever: no budget to wait on. Handing the call to InlineWriter and reading its
            # result back cost a frame's log append a third of its time in a worker (the write's
            # two system calls are the rest: docs/frame_path.md).
            try:
                return self._noting_refusal(session_id, fn, *args)
            except CheckpointError as exc:
                self._failed(session_id, checkpoint, str(exc))
                return None
        budget_s = self.wait_s if wait_s is None else max(self.wait_s, wait_s)
        if not self.writer.healthy or self.writer.stuck(budget_s):
            self._failed(session_id, checkpoint, "the store does not answer")
            return None
        pending = self.writer.call(self._noting_refusal, session_id, fn, *args)
        try:
            return cast("T", pending.result(budget_s))
        except TimeoutError:
            self._failed(session_id, checkpoint, f"the store did not answer within {budget_s * 1e3:g} ms")
        except CheckpointError as exc:
            self._failed(session_id, checkpoint, str(exc))
        return None

    def _noting_refusal(self, session_id: str, fn: Callable[..., T], *args: object) -> T:
        value = fn(*args)
        if value is False:
            self._taken_over.add(session_id)
        return value

    def _failed(self, session_id: str, checkpoint: SessionCheckpoint, reason: str) -> None:
        """The session goes on; its checkpoint is written whole again once the store answers."""
        if not checkpoint.failed:
            log.error(
                "session %s: its checkpoint is behind (%s); frames are still answered, the checkpoint is "
                "written again when the store answers (tried every %.0f s)",
                session_id,
                reason,
                CHECKPOINT_RETRY_S,
            )
        checkpoint.retry_s = self.clock() + CHECKPOINT_RETRY_S
