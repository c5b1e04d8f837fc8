"""The session table: the sessions one process holds (hosting them), and the typed requests that reach them.

Used the same way inside a worker process and inline in the front process (workers=0), below the
requests' parsing (dispatch.py, which calls this table's typed methods and knows how to rebuild a
session it does not hold). The table creates, runs, restyles, shows and ends its sessions, with
what it keeps beside each (`HeldSession`). Each input is written to the session's checkpoint
(checkpointing.py: within a budget where the store may hang) before it is computed (`TakenOver`
when the store says another process has the session now: dispatch.py restores the newer state and
asks again), and a snapshot taken when one
is due (at once, or with `defer_snapshots` in `idle_work`). A session it does not hold is
NOT_FOUND here: rebuilding one is `restore` and `replay`, driven from dispatch.py.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

from google.protobuf import json_format

from camdirector.errors import invalid, not_found, precondition
from camdirector.geometry.toric_maps.native import hand_updates_apart, share_texels
from camdirector.infra.channels import FrameMetrics, ViewQuery
from camdirector.infra.tenants import DEFAULT_TENANT
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.session import Session
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style
from camdirector.render.monitor import Monitor, Reply
from camdirector.render.snapshots import render_job, scene_geometry
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker import codec
from camdirector.worker.checkpoint_stores import Checkpoint, CheckpointStore, loads_state
from camdirector.worker.checkpointing import Checkpointing, SessionCheckpoint
from camdirector.worker.level_cache import LevelCache
from camdirector.worker.map_view import anticipation_png
from camdirector.worker.pose_out import PoseSender
from camdirector.worker.recording import RecordingWriter
from camdirector.worker.timeline import Timeline

ANSWERS_KEPT = 128  # a session's last answers kept for frames sent again (HeldSession.answers), frames


@dataclass
class HeldSession:
    """What the table keeps for one session: the pipeline's Session and, at the edge, the style
    as the client last sent it, the recent frames for the dashboard, the recorder if recording,
    the sender of its pose outputs if it asked for any, and what the checkpoint protocol keeps."""

    session: Session
    style_msg: pb.Style
    timeline: Timeline = field(default_factory=Timeline)
    recorder: RecordingWriter | None = None
    pose_sender: PoseSender | None = None
    checkpoint: SessionCheckpoint = field(default_factory=SessionCheckpoint)
    # The last ANSWERS_KEPT frames' answers, by frame, serialized: a frame sent again (its answer was
    # lost with a stream or a node) is answered stale with its own pose, not the newest one. Bytes,
    # which the collector does not track (timeline.py's TimelineFrame says why that matters).
    answers: OrderedDict[int, bytes] = field(default_factory=OrderedDict)


class SessionTable:
    """The sessions one process holds (module docstring)."""

    def __init__(
        self,
        settings: ServerSettings,
        clock: Callable[[], float] = time.perf_counter,
        store: CheckpointStore | None = None,
        defer_snapshots: bool = False,
    ):
        """store: where sessions are checkpointed; by default the one settings.checkpoint_store names.
        defer_snapshots: snapshots due are left for idle_work (a worker's idle moments) rather than
        taken before the frame's answer leaves (a worker's table; inline tables snapshot at once)."""
        self.settings = settings
        self.clock = clock
        self.held: dict[str, HeldSession] = {}
        self.levels = LevelCache(settings.data_dir, settings.job_store)  # the TRACKS rig's levels, loaded once per process
        self.monitor: Monitor | None = None  # the render process of the sessions' views, started on the first
        self.checkpoints = Checkpointing(settings, clock, store)
        self.defer_snapshots = defer_snapshots
        share_texels(settings.map_threads_per_update)  # per process: this table holds its sessions
        hand_updates_apart(settings.workers == 0)  # the front's table, its frames on one thread
        # Sessions whose rig left work for later (Session.has_deferred_work), then those whose
        # snapshot waits for idle time: idle_work's two queues, in that order.
        self._deferred: dict[str, HeldSession] = {}
        self._snapshots_due: dict[str, HeldSession] = {}

    def get(self, session_id: str) -> HeldSession:
        """The held session; NOT_FOUND when this table does not hold it (dispatch.py restores a
        checkpointed one first)."""
        held = self.held.get(session_id)
        if held is None:
            raise not_found(f"unknown session id {session_id!r} (closed, reclaimed, or never created)")
        return held

    def answers_anywhere(self, session_id: str) -> bool:
        """Whether a frame of the session may be computed on any thread: it is held here, not
        restored first, and its rig is not bound to the thread that made it (CameraRig.thread_bound)."""
        held = self.held.get(session_id)
        return held is not None and not held.session.rig.thread_bound

    def create(
        self, session_id: str, req: pb.CreateSessionRequest, payload: bytes | None = None, tenant: str = DEFAULT_TENANT
    ) -> pb.CreateSessionResponse:
        """payload: the create op's bytes as received, the tenant's and the request's (the checkpoint
        keeps them), when at hand; tenant: the session's, whose levels it may use."""
        held = self._build(session_id, req, tenant)
        response = pb.CreateSessionResponse(session_id=session_id)
        if req.record or self.settings.record_all:
            held.recorder = self._recorder(session_id)
            held.recorder.write(pb.RecordEntry(create=req))
            # its name in the recordings folder, never the server's path (docs/protocol.md)
            response.recording_path = held.recorder.path.name
        self.checkpoints.begin(session_id, held.checkpoint, req, payload, tenant)
        return response

    def restore(self, session_id: str, checkpoint: Checkpoint, req: pb.CreateSessionRequest, tenant: str) -> None:
        """A session rebuilt from its checkpoint (checkpointing.py), as of its snapshot: built from
        its creation request (`req`, `tenant`: the checkpoint's), the snapshot's state put in
        place, its numbering that of the checkpoint's last input. Its recording goes on where the
        lost process left it; the inputs since the snapshot follow through `replay`."""
        held = self._build(session_id, req, tenant)
        if req.record or self.settings.record_all:
            held.recorder = self._recorder(session_id, append=True)
        held.checkpoint.create_payload = checkpoint.create
        if checkpoint.snapshot is not None:
            built = held.session
            held.session, held.style_msg = loads_state(checkpoint.snapshot, built.creation_objects())
            built.close()
        held.checkpoint.snapshot_seq = checkpoint.seq
        held.checkpoint.seq = checkpoint.entries[-1][0] if checkpoint.entries else checkpoint.seq

    def replay(self, msg: pb.FrameUpdate | pb.UpdateStyleRequest | pb.TakeShotRequest) -> None:
        """An input of a session's checkpoint, computed again on the session being restored as it
        was the first time; written, recorded and sent nowhere (that was done). Raises what the
        input raised then (a refused one is refused again)."""
        held = self.get(msg.session_id)
        if isinstance(msg, pb.FrameUpdate):
            answer, state = self._frame(held, msg, self.clock())
            if state is not None:
                _keep_answer(held, msg.frame, answer.SerializeToString())
        elif isinstance(msg, pb.UpdateStyleRequest):
            self._set_style(held, msg, self._checked_style(held, msg))
        else:
            self._take(held, self._checked_take(held, msg))

    def claim(self, session_id: str) -> None:
        """A restored session made this process's: a snapshot that claims its checkpoint."""
        self._snapshot(self.get(session_id), claim=True)

    def _build(self, session_id: str, req: pb.CreateSessionRequest, tenant: str) -> HeldSession:
        pose_outputs = codec.pose_outputs_from_request(req, self.settings.pose_output_allow)  # cheap checks before the meshes
        scene = codec.scene_from_request(req, self.settings, self.levels, tenant)
        session = Session(session_id, scene, self.clock, compiled=self.settings.compiled_frame_path)
        held = self.held[session_id] = HeldSession(session, req.style)
        if pose_outputs:  # a failure from here on drops the session (dispatch.py)
            held.pose_sender = PoseSender(session_id, pose_outputs, scene.lens.aspect)
        return held

    def _recorder(self, session_id: str, append: bool = False) -> RecordingWriter:
        # With checkpoints every entry is written at once: a worker killed after answering a frame
        # leaves it in the recording, which its restored session goes on appending to.
        return RecordingWriter(
            self.settings.recordings_dir / f"{session_id}.cdrec", flush_every=1 if self.checkpoints.enabled else 60, append=append
        )

    def frame(self, msg: pb.FrameUpdate) -> pb.CameraUpdate:
        return pb.CameraUpdate.FromString(self.frame_bytes(msg, msg.SerializeToString())[0])

    def frame_bytes(self, msg: pb.FrameUpdate, payload: bytes) -> tuple[bytes, FrameMetrics]:
        """The serialized reply to `msg` (whose bytes as received are `payload`) and its metrics,
        taken from the frame's state rather than read back out of the reply."""
        t0 = self.clock()
        held = self.get(msg.session_id)
        if msg.answered_frame:  # restored from a checkpoint that was behind: DATA_LOSS, resend from (checkpointing.py)
            last = held.session.last_input
            self.checkpoints.check_answered(msg.session_id, msg, None if last is None else last[0])
        if not held.session.is_stale(msg.frame):
            self.checkpoints.write_input(msg.session_id, held.checkpoint, "frame", payload)
        reply, state = self._frame(held, msg, t0, payload)
        body = reply.SerializeToString()
        if state is not None:
            _keep_answer(held, msg.frame, body)
            self._after_input(held)
        if held.recorder is not None:
            held.recorder.write_frame_and_camera(payload, body)
        if held.pose_sender is not None and state is not None and state.pose is not None:
            held.pose_sender.send(state.pose, state.time_s)  # microseconds; drops rather than fails (pose_out.py)
        stage_ms = {} if state is None else state.stage_ms
        return body, FrameMetrics(reply.compute_ms, stage_ms, reply.stale, checkpoint_failed=held.checkpoint.failed)

    def _frame(
        self, held: HeldSession, msg: pb.FrameUpdate, t0: float, payload: bytes | None = None
    ) -> tuple[codec.Reply, FrameState | None]:
        """The frame's reply, and its state when it was computed (None: stale, the last pose
        repeated). payload: msg's bytes as received, which the compiled frame path decodes
        (serialized again when not given: a checkpoint's input replayed)."""
        session = held.session
        if session.is_stale(msg.frame):
            last = session.last_state
            assert last is not None  # a frame is stale only after one was answered
            kept = held.answers.get(msg.frame)
            if kept is not None:  # sent again: its own answer, marked stale
                reply = pb.CameraUpdate.FromString(kept)
                reply.stale, reply.compute_ms = True, (self.clock() - t0) * 1e3
                reply.message = f"frame {msg.frame} is not newer than frame {last.frame}: its first answer repeated"
                return reply, None
            reply = codec.camera_update_msg(
                last,
                compute_ms=(self.clock() - t0) * 1e3,
                stale=True,
                message=f"frame {msg.frame} is not newer than frame {last.frame}: pose repeated, rig not advanced",
            )
            reply.frame, reply.time_s = msg.frame, msg.time_s
            return reply, None
        inputs = session.rig.player_inputs  # whom the frame's game events may name, if the rig takes any
        player_ids = None if inputs is None else inputs.player_ids
        compiled = self.settings.compiled_frame_path  # the frame's wire in camdirector._native
        if compiled:
            payload = msg.SerializeToString() if payload is None else payload
            update = codec.frame_from_wire(payload, msg, session.movable_ids, session.static_ids, player_ids, session.delay_s)
        else:
            update = codec.frame_from_msg(msg, session.movable_ids, session.static_ids, player_ids, session.delay_s)
        state = session.frame(update)
        if session.has_deferred_work:
            self._deferred[session.id] = held
        answer: codec.Reply  # on the compiled frame path, written in camdirector._native but for a MATCH state
        if compiled and state.match is None:
            answer = codec.camera_update_wire(state)
        else:
            answer = codec.camera_update_msg(state, compute_ms=0.0)
        answer.compute_ms = (self.clock() - t0) * 1e3
        held.timeline.add(state, answer.compute_ms)
        return answer, state

    def update_style(self, msg: pb.UpdateStyleRequest, payload: bytes | None = None) -> pb.UpdateStyleResponse:
        held = self.get(msg.session_id)
        style = self._checked_style(held, msg)  # refused before it is kept
        self.checkpoints.write_input(
            msg.session_id, held.checkpoint, "style", payload if payload is not None else msg.SerializeToString()
        )
        self._set_style(held, msg, style)
        self._after_input(held)
        if held.recorder is not None:
            held.recorder.write(pb.RecordEntry(style=msg))
        return pb.UpdateStyleResponse()

    @staticmethod
    def _checked_style(held: HeldSession, msg: pb.UpdateStyleRequest) -> Style:
        return codec.style_from_msg(msg.style, held.session.lens, held.session.style)

    @staticmethod
    def _set_style(held: HeldSession, msg: pb.UpdateStyleRequest, style: Style) -> None:
        held.session.set_style(style)
        held.style_msg = msg.style

    def take_shot(self, msg: pb.TakeShotRequest, payload: bytes | None = None) -> pb.TakeShotResponse:
        """A human director's shot, held until released, in a session whose rig takes one
        (`PlayerInputs.take`, pipeline/camera_rig.py: MATCH)."""
        held = self.get(msg.session_id)
        take = self._checked_take(held, msg)
        self.checkpoints.write_input(
            msg.session_id, held.checkpoint, "take", payload if payload is not None else msg.SerializeToString()
        )
        shot = self._take(held, take)
        self._after_input(held)
        if held.recorder is not None:
            held.recorder.write(pb.RecordEntry(take=msg))
        return pb.TakeShotResponse() if shot is None else pb.TakeShotResponse(shot=codec.shot_msg(shot))

    @staticmethod
    def _checked_take(held: HeldSession, msg: pb.TakeShotRequest) -> tuple[list[str], ShotKind | None, bool]:
        session = held.session
        inputs = session.rig.player_inputs
        if inputs is None:
            raise precondition(
                f"TakeShot is for a RIG_MATCH session; session {msg.session_id} runs the {session.style.rig.name} rig"
            )
        return codec.take_from_msg(msg, inputs.player_ids)

    @staticmethod
    def _take(held: HeldSession, take: tuple[list[str], ShotKind | None, bool]) -> ShotChoice | None:
        inputs = held.session.rig.player_inputs
        assert inputs is not None  # _checked_take refused the take otherwise
        try:
            return inputs.take(*take)
        except ValueError as exc:  # a player named twice, a kind that does not fit the count
            raise invalid(str(exc)) from None

    def timeline(self, session_id: str, last: int | None = None, after_frame: int | None = None) -> dict:
        """The session's style (protobuf JSON of `camdirector.v1.Style`, as the client sent it, a
        MATCH style's director by the name it resolved to: codec.shown_style),
        its newest `last` answered frames after `after_frame` (`timeline.py`), oldest first, its
        targets as people see them (`roster`: id, display_name, team, team_name in target order;
        here once per ask, where the frames name targets by id only), and with pose outputs their
        counts (`pose_outputs`: format, address, sent, dropped, last_error)."""
        held = self.get(session_id)
        detail = {
            "style": json_format.MessageToDict(held.style_msg),
            "frames": held.timeline.as_json(last, after_frame),
            "roster": [
                {"id": t.id, "display_name": t.display_name, "team": t.team, "team_name": t.team_name}
                for t in held.session.targets
            ],
        }
        if held.pose_sender is not None:  # each output's datagrams sent and dropped (pose_out.py)
            detail["pose_outputs"] = held.pose_sender.status()
        return detail

    def anticipation_png(self, session_id: str) -> bytes:
        """The session's A-map as a PNG (map_view.py); FAILED_PRECONDITION when it has none (not
        a map mode, the tracks rig, or no frame since the maps were asked for)."""
        session = self.get(session_id).session
        found = session.rig.anticipation_map(session.last_state)
        if found is None:
            raise precondition(
                f"session {session_id} has no anticipation map: its style's visibility is "
                f"{session.style.visibility.name} on the {session.style.rig.name} rig, and only "
                "ANTICIPATION and NO_ANTICIPATION build one (after their first frame)"
            )
        return anticipation_png(*found)

    def view(self, session_id: str, query: ViewQuery, reply: Reply) -> None:
        """A monitor's picture of the session (render/snapshots.py), rendered in the render process
        (render/monitor.py) and answered later through `reply(status, body)`, from another thread.
        Only the snapshot is taken here, between two frames. Raises DirectorError at once for an
        unknown session."""
        session = self.get(session_id).session
        job = render_job(session, query)
        if self.monitor is None:
            self.monitor = Monitor()
        self.monitor.submit(job, lambda: scene_geometry(session), reply)

    def close(self, session_id: str) -> pb.CloseSessionResponse:
        session = self.get(session_id).session
        self.drop(session_id)
        return pb.CloseSessionResponse(frames=session.frames_answered)

    def drop(self, session_id: str, keep_checkpoint: bool = False) -> None:
        """Ends a session if present, releasing what it holds (its occlusion maps' GL objects or
        Embree scenes, its recording file, its pose outputs' socket): on close, on reclaiming an
        abandoned one, on a failed create. Its checkpoint goes too, unless `keep_checkpoint` (the
        process is stopping, or another one has taken the session over)."""
        held = self.held.pop(session_id, None)
        self._deferred.pop(session_id, None)  # deferred work or a snapshot left for later goes with it
        self._snapshots_due.pop(session_id, None)
        self.checkpoints.end(session_id, keep_checkpoint)
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
        self.checkpoints.close()

    def idle_work(self, anywhere: bool = False) -> bool:
        """Does one piece of deferred work: a part of a session's deferred map update (its maps,
        their A_s, about 1 ms each, or their aggregate) or of its drawn match plan (2 ms; Session.has_deferred_work),
        else the oldest snapshot due
        (0.5-1 ms; checkpointing.py); answers whether more is waiting.
        A worker calls this between requests when none is waiting, so that neither delays a
        frame's answer. What a session answers does not depend on whether this ran.
        With `anywhere` (the caller is not the thread that made the sessions: the front's edge)
        sessions bound to that thread (CameraRig.thread_bound) are left out, and not counted as
        waiting: their deferred work is done in the frame that needs it, their snapshot once it
        may no longer wait."""

        def here(held: HeldSession) -> bool:
            return not (anywhere and held.session.rig.thread_bound)

        if (held := next(filter(here, self._deferred.values()), None)) is not None:
            del self._deferred[held.session.id]
            held.session.do_deferred_work(whole=False)
            if held.session.has_deferred_work:  # its other part, after the others' waiting parts
                self._deferred[held.session.id] = held
        elif (held := next(filter(here, self._snapshots_due.values()), None)) is not None:
            del self._snapshots_due[held.session.id]
            self._snapshot(held)
        return any(map(here, self._deferred.values())) or any(map(here, self._snapshots_due.values()))

    def _after_input(self, held: HeldSession) -> None:
        """A snapshot when one is due (checkpointing.py): taken at once, or with `defer_snapshots`
        left for idle_work while it may wait."""
        checkpoint = held.checkpoint
        if not self.checkpoints.snapshot_due(checkpoint):
            return
        if self.defer_snapshots and self.checkpoints.may_wait(checkpoint):
            self._snapshots_due[held.session.id] = held
        else:
            self._snapshots_due.pop(held.session.id, None)
            self._snapshot(held)

    def _snapshot(self, held: HeldSession, claim: bool = False) -> None:
        session = held.session
        session.do_deferred_work()  # a snapshot holds computed maps, not the means to compute them
        self._deferred.pop(session.id, None)
        # Not the dashboard's timeline: diagnostics, not state, up to 1 MB; a restored session's starts anew.
        self.checkpoints.snapshot(session.id, held.checkpoint, (session, held.style_msg), session.creation_objects(), claim)


def _keep_answer(held: HeldSession, frame: int, answer: bytes) -> None:
    """The frame's serialized answer kept for its resending (HeldSession.answers), the oldest
    dropped past ANSWERS_KEPT."""
    held.answers[frame] = answer
    if len(held.answers) > ANSWERS_KEPT:
        held.answers.popitem(last=False)
