"""The session table: the sessions one process holds, and the requests that reach them.

Used the same way inside a worker process and inline in the front process (workers=0): the
worker pool routes a request by session id and calls `handle_bytes`.
"""
from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import orjson
from google.protobuf import json_format

from camdirector.errors import DirectorError, internal, invalid, not_found, precondition, unavailable
from camdirector.infra.channels import FrameMetrics
from camdirector.render.monitor import Monitor, Reply
from camdirector.render.snapshots import ViewQuery, render_job, scene_geometry
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker import codec
from camdirector.worker.checkpoints import (
    CheckpointError,
    CheckpointStore,
    dumps_state,
    encode_entry,
    loads_state,
    open_store,
)
from camdirector.worker.level_cache import LevelCache
from camdirector.worker.map_view import anticipation_png
from camdirector.worker.pose_out import PoseSender
from camdirector.worker.recording import RecordingWriter
from camdirector.worker.session import Session
from camdirector.worker.timeline import Timeline
from camdirector.worker.timeline import dumps as timeline_dumps

log = logging.getLogger("camdirector.sessions")

CHECKPOINT_RETRY_S = 1.0  # a session whose checkpoint write failed tries again this often (a full snapshot), s


@dataclass
class HeldSession:
    """What the table keeps for one session: the pipeline's Session and, at the edge, the style
    as the client last sent it, the recent frames for the dashboard, the recorder if recording,
    the sender of its pose outputs if it asked for any."""

    session: Session
    style_msg: pb.Style
    timeline: Timeline = field(default_factory=Timeline)
    recorder: RecordingWriter | None = None
    pose_sender: PoseSender | None = None
    create_payload: bytes = b""      # the creation request as received: a checkpoint lost with its store is begun again
    seq: int = 0                     # inputs taken (frames not stale, styles, takes): the checkpoint's numbering
    snapshot_seq: int = 0            # the input the last snapshot includes
    checkpoint_retry_s: float | None = None  # a failed checkpoint write: when to try again (clock), else None


class SessionTable:
    def __init__(self, settings: ServerSettings, clock: Callable[[], float] = time.perf_counter,
                 store: CheckpointStore | None = None):
        """store: where sessions are checkpointed; by default the one settings.checkpoint_store names."""
        self.settings = settings
        self.clock = clock
        self.held: dict[str, HeldSession] = {}
        self.levels = LevelCache(settings.data_dir, settings.job_store)  # the TRACKS rig's levels, loaded once per process
        self.monitor: Monitor | None = None          # the render process of the sessions' views, started on the first
        self.store = store if store is not None else open_store(
            settings.checkpoint_store, settings.data_dir, settings.checkpoint_keep_s)
        self.owner = f"{settings.node_name}/{os.getpid()}"  # this process, in checkpoints' ownership
        self._replaying = False   # restoring: the inputs since the snapshot are not written, sent or recorded again
        # Snapshots due are left for idle_work (a worker's idle moments) rather than taken
        # before the frame's answer leaves; the worker loop sets this (inline tables snapshot at once).
        self.defer_snapshots = False
        self._due: dict[str, HeldSession] = {}
        # Sessions whose rig left work for later (Session.has_deferred_work), for idle_work.
        self._deferred: dict[str, HeldSession] = {}

    def _get(self, session_id: str) -> HeldSession:
        held = self.held.get(session_id)
        if held is None:
            held = self._restore(session_id)
        return held

    def create(self, session_id: str, req: pb.CreateSessionRequest, payload: bytes | None = None) -> pb.CreateSessionResponse:
        """payload: the request's bytes as received (the checkpoint keeps them), when at hand."""
        pose_outputs = codec.pose_outputs_from_request(req)  # cheap checks before the scene's meshes
        scene = codec.scene_from_request(req, self.settings, self.levels)
        held = self.held[session_id] = HeldSession(Session(session_id, scene, clock=self.clock), req.style)
        if pose_outputs:  # a failure from here on drops the session (handle_bytes)
            held.pose_sender = PoseSender(session_id, pose_outputs, scene.lens.aspect)
        response = pb.CreateSessionResponse(session_id=session_id)
        if req.record or self.settings.record_all:
            held.recorder = self._recorder(session_id, append=self._replaying)
            if not self._replaying:   # a restored session's recording goes on where the lost process left it
                held.recorder.write(pb.RecordEntry(create=req))
            response.recording_path = str(held.recorder.path)
        if self.store is not None:
            held.create_payload = payload if payload is not None else req.SerializeToString()
            if not self._replaying:
                try:
                    self.store.begin(session_id, self.owner, held.create_payload)
                except CheckpointError as exc:
                    self._checkpoint_failed(held, exc)
        return response

    def _recorder(self, session_id: str, append: bool = False) -> RecordingWriter:
        # With checkpoints every entry is written at once: a worker killed after answering a frame
        # leaves it in the recording, which its restored session goes on appending to.
        return RecordingWriter(self.settings.recordings_dir / f"{session_id}.cdrec",
                               flush_every=1 if self.store is not None else 60, append=append)

    def _restore(self, session_id: str) -> HeldSession:
        """The session rebuilt from its checkpoint (checkpoints.py), now owned by this process.
        NOT_FOUND without one; UNAVAILABLE when the store cannot be read or the checkpoint does
        not restore (the session's other requests will try again; other sessions are untouched)."""
        if self.store is None:
            raise not_found(f"unknown session id {session_id!r} (closed, reclaimed, or never created)")
        try:
            checkpoint = self.store.load(session_id)
        except CheckpointError as exc:
            raise unavailable(f"session {session_id} cannot be restored now: {exc}") from None
        if checkpoint is None:
            raise not_found(f"unknown session id {session_id!r} (closed, reclaimed, or never created)")
        t0 = self.clock()
        self._replaying = True
        try:
            req = pb.CreateSessionRequest.FromString(checkpoint.create)
            self.create(session_id, req, checkpoint.create)
            held = self.held[session_id]
            if checkpoint.snapshot is not None:
                built = held.session
                held.session, held.style_msg = loads_state(checkpoint.snapshot, built.creation_objects())
                built.close()
            held.seq = held.snapshot_seq = checkpoint.seq
            for seq, op, payload in checkpoint.entries:  # as replay does (recording.py)
                try:
                    self.handle_bytes(op, session_id, payload)
                except DirectorError:
                    pass  # refused again, as it was the first time
                held.seq = seq
        except Exception as exc:
            self.drop(session_id, keep_checkpoint=True)
            log.exception("session %s: restoring its checkpoint failed", session_id)
            raise unavailable(f"session {session_id} could not be restored from its checkpoint: "
                              f"{type(exc).__name__}: {exc}") from None
        finally:
            self._replaying = False
        self._snapshot(held, claim=True)
        log.info("session %s restored from its checkpoint (%d inputs after the snapshot) in %.1f ms",
                 session_id, len(checkpoint.entries), (self.clock() - t0) * 1e3)
        return held

    def _checkpoint(self, session_id: str, held: HeldSession, op: str, payload: bytes) -> HeldSession:
        """Writes one input before it is computed (checkpoints.py). Answers the session to compute
        it on: `held`, or the newer state restored when another process has taken the session over."""
        if self._replaying or self.store is None:
            return held
        held.seq += 1
        if held.checkpoint_retry_s is not None:
            return held   # the snapshot after this input repairs the checkpoint (_after_input)
        try:
            owned = self.store.append(session_id, self.owner, encode_entry(held.seq, op, payload))
        except CheckpointError as exc:
            self._checkpoint_failed(held, exc)
            return held
        if owned:
            return held
        log.info("session %s was taken over by another process; restoring its newer state", session_id)
        self.drop(session_id, keep_checkpoint=True)
        return self._restore(session_id)

    def _after_input(self, held: HeldSession) -> None:
        """A snapshot when one is due, or when a failed write is to be repaired: taken at once,
        or with `defer_snapshots` left for idle_work (the worker's idle moments) unless the
        log has grown to twice its period (a worker never idle still cuts it)."""
        if self._replaying or self.store is None:
            return
        if held.checkpoint_retry_s is not None:
            due = self.clock() >= held.checkpoint_retry_s
        else:
            due = held.seq - held.snapshot_seq >= self.settings.checkpoint_every_frames
        if not due:
            return
        if self.defer_snapshots and held.seq - held.snapshot_seq < 2 * self.settings.checkpoint_every_frames:
            self._due[held.session.id] = held
        else:
            self._due.pop(held.session.id, None)
            self._snapshot(held, claim=False)

    def idle_work(self) -> bool:
        """Does one piece of deferred work: a part of a session's deferred map update (its maps or
        their A_s, about 1 ms each; Session.has_deferred_work), else the oldest snapshot due
        (0.5-1 ms); answers whether more is waiting.
        A worker calls this between requests when none is waiting, so that neither delays a
        frame's answer. What a session answers does not depend on whether this ran."""
        if self._deferred:
            held = self._deferred.pop(next(iter(self._deferred)))
            held.session.do_deferred_work(whole=False)
            if held.session.has_deferred_work:   # its other part, after the others' waiting parts
                self._deferred[held.session.id] = held
        elif self._due:
            self._snapshot(self._due.pop(next(iter(self._due))), claim=False)
        return bool(self._deferred or self._due)

    def _snapshot(self, held: HeldSession, claim: bool) -> None:
        """A snapshot; with `claim` (a restore) this process takes the session over; after a failed
        write the checkpoint is begun again first (the store may have lost it: Redis restarted)."""
        session = held.session
        session.do_deferred_work()   # a snapshot holds computed maps, not the means to compute them
        self._deferred.pop(session.id, None)
        try:
            # Not the dashboard's timeline: diagnostics, not state, up to 1 MB; a restored session's starts anew.
            state = dumps_state((session, held.style_msg), session.creation_objects())
            if held.checkpoint_retry_s is not None:
                self.store.begin(session.id, self.owner, held.create_payload)
            self.store.snapshot(session.id, self.owner, held.seq, state, claim=claim)
        except CheckpointError as exc:
            self._checkpoint_failed(held, exc)
            return
        if held.checkpoint_retry_s is not None:
            log.warning("session %s: checkpoint written again after a failure", session.id)
        held.snapshot_seq, held.checkpoint_retry_s = held.seq, None

    def _checkpoint_failed(self, held: HeldSession, exc: CheckpointError) -> None:
        """The session goes on; its checkpoint is written whole again once the store answers."""
        if held.checkpoint_retry_s is None:
            log.error("session %s: %s; frames are still answered, the checkpoint is written again when the "
                      "store answers (tried every %.0f s)", held.session.id, exc, CHECKPOINT_RETRY_S)
        held.checkpoint_retry_s = self.clock() + CHECKPOINT_RETRY_S

    def frame(self, msg: pb.FrameUpdate) -> pb.CameraUpdate:
        return pb.CameraUpdate.FromString(self._frame(msg, msg.SerializeToString())[0])

    def _frame(self, msg: pb.FrameUpdate, payload: bytes) -> tuple[bytes, FrameMetrics]:
        """The serialized reply to `msg` (whose bytes as received are `payload`) and its metrics,
        taken from the frame's state rather than read back out of the reply."""
        t0 = self.clock()
        held = self._get(msg.session_id)
        session = held.session
        if not session.is_stale(msg.frame):
            held = self._checkpoint(msg.session_id, held, "frame", payload)
            session = held.session
        if session.is_stale(msg.frame):
            last = session.last_state
            reply = codec.camera_update_msg(
                last, compute_ms=(self.clock() - t0) * 1e3, stale=True,
                message=f"frame {msg.frame} is not newer than frame {last.frame}: pose repeated, rig not advanced")
            reply.frame, reply.time_s = msg.frame, msg.time_s
            stage_ms = {}
            state = None
        else:
            update = codec.frame_from_msg(msg, session.movable_ids, session.static_ids, session.players, session.delay_s)
            state = session.frame(update)
            if session.has_deferred_work:
                self._deferred[session.id] = held
            reply = codec.camera_update_msg(state, compute_ms=0.0)
            reply.compute_ms = (self.clock() - t0) * 1e3
            held.timeline.add(state, reply.compute_ms)
            stage_ms = state.stage_ms
        body = reply.SerializeToString()
        if self._replaying:
            return body, FrameMetrics(reply.compute_ms, stage_ms, reply.stale)
        if state is not None:
            self._after_input(held)
        if held.recorder is not None:
            held.recorder.write_frame_and_camera(payload, body)
        if held.pose_sender is not None and state is not None and state.pose is not None:
            held.pose_sender.send(state.pose, state.time_s)  # microseconds; drops rather than fails (pose_out.py)
        return body, FrameMetrics(reply.compute_ms, stage_ms, reply.stale,
                                  checkpoint_failed=held.checkpoint_retry_s is not None)

    def update_style(self, msg: pb.UpdateStyleRequest, payload: bytes | None = None) -> pb.UpdateStyleResponse:
        held = self._get(msg.session_id)
        style = codec.style_from_msg(msg.style, held.session.lens, held.session.style)  # refused before it is kept
        held = self._checkpoint(msg.session_id, held, "style", payload if payload is not None else msg.SerializeToString())
        held.session.set_style(style)
        held.style_msg = msg.style
        self._after_input(held)
        if held.recorder is not None and not self._replaying:
            held.recorder.write(pb.RecordEntry(style=msg))
        return pb.UpdateStyleResponse()

    def take_shot(self, msg: pb.TakeShotRequest, payload: bytes | None = None) -> pb.TakeShotResponse:
        """A human director's shot in a MATCH session, held until released (MatchRig.take)."""
        held = self._get(msg.session_id)
        session = held.session
        if session.players is None:
            raise precondition(f"TakeShot is for a RIG_MATCH session; session {msg.session_id} runs the "
                               f"{session.style.rig.name} rig")
        take = codec.take_from_msg(msg, session.players)
        held = self._checkpoint(msg.session_id, held, "take", payload if payload is not None else msg.SerializeToString())
        try:
            shot = held.session.rig.take(*take)
        except ValueError as exc:  # a player named twice, a kind that does not fit the count
            raise invalid(str(exc)) from None
        self._after_input(held)
        if held.recorder is not None and not self._replaying:
            held.recorder.write(pb.RecordEntry(take=msg))
        return pb.TakeShotResponse() if shot is None else pb.TakeShotResponse(shot=codec.shot_msg(shot))

    def timeline(self, session_id: str, last: int | None = None, after_frame: int | None = None) -> dict:
        """The session's style (protobuf JSON of `camdirector.v1.Style`, as the client sent it),
        its newest `last` answered frames after `after_frame` (`timeline.py`), oldest first, and
        with pose outputs their counts (`pose_outputs`: format, address, sent, dropped, last_error)."""
        held = self._get(session_id)
        detail = {"style": json_format.MessageToDict(held.style_msg), "frames": held.timeline.as_json(last, after_frame)}
        if held.pose_sender is not None:  # each output's datagrams sent and dropped (pose_out.py)
            detail["pose_outputs"] = held.pose_sender.status()
        return detail

    def anticipation_png(self, session_id: str) -> bytes:
        """The session's A-map as a PNG (map_view.py); FAILED_PRECONDITION when it has none (not
        a map mode, the tracks rig, or no frame since the maps were asked for)."""
        session = self._get(session_id).session
        found = session.rig.anticipation_map(session.last_state)
        if found is None:
            raise precondition(f"session {session_id} has no anticipation map: its style's visibility is "
                               f"{session.style.visibility.name} on the {session.style.rig.name} rig, and only "
                               "ANTICIPATION and NO_ANTICIPATION build one (after their first frame)")
        return anticipation_png(*found)

    def view(self, session_id: str, payload: bytes, reply: Reply) -> None:
        """A monitor's picture of the session (views.py; payload: a ViewQuery's JSON), rendered
        in the render process (monitor.py) and answered later through `reply(status, body)`, from
        another thread. Only the snapshot is taken here, between two frames. Raises DirectorError
        at once for an unknown session or a query that is not one."""
        session = self._get(session_id).session
        job = render_job(session, ViewQuery.from_json(payload))
        if self.monitor is None:
            self.monitor = Monitor()
        self.monitor.submit(job, lambda: scene_geometry(session), reply)

    def close(self, session_id: str) -> pb.CloseSessionResponse:
        session = self._get(session_id).session
        self.drop(session_id)
        return pb.CloseSessionResponse(frames=session.frames_answered)

    def drop(self, session_id: str, keep_checkpoint: bool = False) -> None:
        """Ends a session if present, releasing what it holds (its occlusion maps' GL objects or
        Embree scenes, its recording file, its pose outputs' socket): on close, on reclaiming an
        abandoned one, on a failed create. Its checkpoint goes too, unless `keep_checkpoint` (the
        process is stopping, or another one has taken the session over)."""
        held = self.held.pop(session_id, None)
        self._due.pop(session_id, None)   # a snapshot or deferred work left for later goes with it
        self._deferred.pop(session_id, None)
        if self.store is not None:
            try:
                if keep_checkpoint:
                    self.store.forget(session_id)
                else:
                    self.store.delete(session_id, self.owner)
            except CheckpointError as exc:
                log.warning("session %s: its checkpoint stays behind: %s", session_id, exc)
        if held is None:
            return
        if held.pose_sender is not None:
            held.pose_sender.close()
        if self.monitor is not None:
            self.monitor.forget(session_id)
        try:
            held.session.close()
        finally:  # the recording is closed even when releasing the rig failed
            if held.recorder is not None:
                held.recorder.close()

    def close_all(self) -> None:
        """Ends every session and the render process (the worker is stopping); their checkpoints
        stay, so the sessions go on when a node started again on this data finds them."""
        for session_id in list(self.held):
            self.drop(session_id, keep_checkpoint=True)
        if self.monitor is not None:
            self.monitor.close()
        if self.store is not None:
            self.store.close()

    def handle_bytes(self, op: str, session_id: str, payload: bytes) -> tuple[bytes, FrameMetrics | None]:
        """One request as the transports carry it: serialized in, serialized out.

        Raises DirectorError for anything the client must hear about; an unexpected exception
        becomes INTERNAL and leaves the other sessions untouched.
        """
        try:
            if op == "frame":
                return self._frame(_parse(pb.FrameUpdate, payload, session_id), payload)
            if op == "create":
                return self.create(session_id, _parse(pb.CreateSessionRequest, payload), payload).SerializeToString(), None
            if op == "style":
                return self.update_style(_parse(pb.UpdateStyleRequest, payload, session_id), payload).SerializeToString(), None
            if op == "close":
                return self.close(session_id).SerializeToString(), None
            if op == "take":
                return self.take_shot(_parse(pb.TakeShotRequest, payload, session_id), payload).SerializeToString(), None
            if op == "timeline":   # payload: JSON {"last": n | null, "after_frame": n | null}
                query = orjson.loads(payload)
                return timeline_dumps(self.timeline(session_id, query["last"], query["after_frame"])), None
            if op == "amap":
                return self.anticipation_png(session_id), None
            if op == "drop":
                self.drop(session_id)
                return b"", None
            raise invalid(f"unknown operation {op!r}")
        except DirectorError:
            raise
        except Exception as exc:  # a bug must not take the worker (and its other sessions) down
            if op == "create":
                self.drop(session_id)
            raise internal(exc, op, session_id, log) from exc


def _parse(message_type, payload: bytes, routed_session_id: str | None = None):
    """The request, parsed once; with `routed_session_id` (what the front routed by, reading only
    field 1) INVALID_ARGUMENT when the parsed session_id differs (the field given twice)."""
    try:
        msg = message_type.FromString(payload)
    except Exception:
        raise invalid(f"payload is not a serialized {message_type.DESCRIPTOR.full_name}") from None
    if routed_session_id is not None and msg.session_id != routed_session_id:
        raise invalid(f"session_id is given more than once ({routed_session_id!r}, then {msg.session_id!r})")
    return msg
