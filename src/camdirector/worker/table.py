"""The session table: the sessions one process holds (hosting them), and the requests that reach them.

Used the same way inside a worker process and inline in the front process (workers=0): the
worker pool routes a request by session id and calls `handle_bytes`, which parses it and calls the
table's typed method for it (dispatch.py). The table creates, runs, restyles, shows and ends its
sessions, with what it keeps beside each (`HeldSession`); their checkpoints are the checkpoint
protocol's (checkpointing.py), which the table tells of every input and of every session it ends,
and which restores, through the table, a session it does not hold.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from google.protobuf import json_format

from camdirector.errors import invalid, precondition
from camdirector.infra.channels import FrameMetrics
from camdirector.precompute.tracks.registry import DEFAULT_TENANT
from camdirector.render.monitor import Monitor, Reply
from camdirector.render.snapshots import ViewQuery, render_job, scene_geometry
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker import codec, dispatch
from camdirector.worker.checkpoint_stores import CheckpointStore
from camdirector.worker.checkpointing import Checkpointing, SessionCheckpoint
from camdirector.worker.level_cache import LevelCache
from camdirector.worker.map_view import anticipation_png
from camdirector.worker.pose_out import PoseSender
from camdirector.worker.recording import RecordingWriter
from camdirector.worker.session import Session
from camdirector.worker.timeline import Timeline


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


class SessionTable:
    """The sessions one process holds (module docstring)."""

    def __init__(self, settings: ServerSettings, clock: Callable[[], float] = time.perf_counter,
                 store: CheckpointStore | None = None):
        """store: where sessions are checkpointed; by default the one settings.checkpoint_store names."""
        self.settings = settings
        self.clock = clock
        self.held: dict[str, HeldSession] = {}
        self.levels = LevelCache(settings.data_dir, settings.job_store)  # the TRACKS rig's levels, loaded once per process
        self.monitor: Monitor | None = None          # the render process of the sessions' views, started on the first
        self.checkpoints = Checkpointing(self, settings, clock, store)
        # Sessions whose rig left work for later (Session.has_deferred_work), for idle_work.
        self._deferred: dict[str, HeldSession] = {}

    @property
    def defer_snapshots(self) -> bool:
        """Whether snapshots due are left for idle_work (a worker's idle moments) rather than taken
        before the frame's answer leaves; the worker loop sets it (inline tables snapshot at once)."""
        return self.checkpoints.defer_snapshots

    @defer_snapshots.setter
    def defer_snapshots(self, value: bool) -> None:
        self.checkpoints.defer_snapshots = value

    def handle_bytes(self, op: str, session_id: str, payload: bytes) -> tuple[bytes, FrameMetrics | None]:
        """One request as the transports carry it: serialized in, serialized out (dispatch.py).
        Raises DirectorError for anything the client must hear about."""
        return dispatch.handle_bytes(self, op, session_id, payload)

    def _get(self, session_id: str) -> HeldSession:
        held = self.held.get(session_id)
        if held is None:
            held = self.checkpoints.restore(session_id)
        return held

    def create(self, session_id: str, req: pb.CreateSessionRequest, payload: bytes | None = None,
               tenant: str = DEFAULT_TENANT) -> pb.CreateSessionResponse:
        """payload: the create op's bytes as received, the tenant's and the request's (the checkpoint
        keeps them), when at hand; tenant: the session's, whose levels it may use."""
        pose_outputs = codec.pose_outputs_from_request(req)  # cheap checks before the scene's meshes
        scene = codec.scene_from_request(req, self.settings, self.levels, tenant)
        held = self.held[session_id] = HeldSession(Session(session_id, scene, clock=self.clock), req.style)
        if pose_outputs:  # a failure from here on drops the session (dispatch.py)
            held.pose_sender = PoseSender(session_id, pose_outputs, scene.lens.aspect)
        response = pb.CreateSessionResponse(session_id=session_id)
        replaying = self.checkpoints.replaying
        if req.record or self.settings.record_all:
            held.recorder = self._recorder(session_id, append=replaying)
            if not replaying:   # a restored session's recording goes on where the lost process left it
                held.recorder.write(pb.RecordEntry(create=req))
            response.recording_path = str(held.recorder.path)
        self.checkpoints.begin(held, req, payload, tenant)
        return response

    def _recorder(self, session_id: str, append: bool = False) -> RecordingWriter:
        # With checkpoints every entry is written at once: a worker killed after answering a frame
        # leaves it in the recording, which its restored session goes on appending to.
        return RecordingWriter(self.settings.recordings_dir / f"{session_id}.cdrec",
                               flush_every=1 if self.checkpoints.enabled else 60, append=append)

    def frame(self, msg: pb.FrameUpdate) -> pb.CameraUpdate:
        return pb.CameraUpdate.FromString(self.frame_bytes(msg, msg.SerializeToString())[0])

    def frame_bytes(self, msg: pb.FrameUpdate, payload: bytes) -> tuple[bytes, FrameMetrics]:
        """The serialized reply to `msg` (whose bytes as received are `payload`) and its metrics,
        taken from the frame's state rather than read back out of the reply."""
        t0 = self.clock()
        held = self._get(msg.session_id)
        session = held.session
        if not session.is_stale(msg.frame):
            held = self.checkpoints.write_input(msg.session_id, held, "frame", payload)
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
            inputs = session.rig.player_inputs   # whom the frame's game events may name, if the rig takes any
            update = codec.frame_from_msg(msg, session.movable_ids, session.static_ids,
                                          None if inputs is None else inputs.player_ids, session.delay_s)
            state = session.frame(update)
            if session.has_deferred_work:
                self._deferred[session.id] = held
            reply = codec.camera_update_msg(state, compute_ms=0.0)
            reply.compute_ms = (self.clock() - t0) * 1e3
            held.timeline.add(state, reply.compute_ms)
            stage_ms = state.stage_ms
        body = reply.SerializeToString()
        if self.checkpoints.replaying:
            return body, FrameMetrics(reply.compute_ms, stage_ms, reply.stale)
        if state is not None:
            self.checkpoints.after_input(held)
        if held.recorder is not None:
            held.recorder.write_frame_and_camera(payload, body)
        if held.pose_sender is not None and state is not None and state.pose is not None:
            held.pose_sender.send(state.pose, state.time_s)  # microseconds; drops rather than fails (pose_out.py)
        return body, FrameMetrics(reply.compute_ms, stage_ms, reply.stale, checkpoint_failed=held.checkpoint.failed)

    def update_style(self, msg: pb.UpdateStyleRequest, payload: bytes | None = None) -> pb.UpdateStyleResponse:
        held = self._get(msg.session_id)
        style = codec.style_from_msg(msg.style, held.session.lens, held.session.style)  # refused before it is kept
        held = self.checkpoints.write_input(msg.session_id, held, "style",
                                            payload if payload is not None else msg.SerializeToString())
        held.session.set_style(style)
        held.style_msg = msg.style
        self.checkpoints.after_input(held)
        if held.recorder is not None and not self.checkpoints.replaying:
            held.recorder.write(pb.RecordEntry(style=msg))
        return pb.UpdateStyleResponse()

    def take_shot(self, msg: pb.TakeShotRequest, payload: bytes | None = None) -> pb.TakeShotResponse:
        """A human director's shot, held until released, in a session whose rig takes one
        (`PlayerInputs.take`, pipeline/camera_rig.py: MATCH)."""
        held = self._get(msg.session_id)
        session = held.session
        inputs = session.rig.player_inputs
        if inputs is None:
            raise precondition(f"TakeShot is for a RIG_MATCH session; session {msg.session_id} runs the "
                               f"{session.style.rig.name} rig")
        take = codec.take_from_msg(msg, inputs.player_ids)
        held = self.checkpoints.write_input(msg.session_id, held, "take",
                                            payload if payload is not None else msg.SerializeToString())
        try:
            shot = held.session.rig.player_inputs.take(*take)
        except ValueError as exc:  # a player named twice, a kind that does not fit the count
            raise invalid(str(exc)) from None
        self.checkpoints.after_input(held)
        if held.recorder is not None and not self.checkpoints.replaying:
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
        """A monitor's picture of the session (render/snapshots.py; payload: a ViewQuery's JSON),
        rendered in the render process (render/monitor.py) and answered later through `reply(status, body)`, from
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
        self._deferred.pop(session_id, None)   # deferred work or a snapshot left for later goes with it
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

    def idle_work(self) -> bool:
        """Does one piece of deferred work: a part of a session's deferred map update (its maps or
        their A_s, about 1 ms each) or of its drawn match plan (2 ms; Session.has_deferred_work),
        else the oldest snapshot due
        (0.5-1 ms; checkpointing.py); answers whether more is waiting.
        A worker calls this between requests when none is waiting, so that neither delays a
        frame's answer. What a session answers does not depend on whether this ran."""
        if self._deferred:
            held = self._deferred.pop(next(iter(self._deferred)))
            held.session.do_deferred_work(whole=False)
            if held.session.has_deferred_work:   # its other part, after the others' waiting parts
                self._deferred[held.session.id] = held
        else:
            self.checkpoints.take_due_snapshot()
        return bool(self._deferred) or self.checkpoints.snapshots_due

    def finish_deferred_work(self, held: HeldSession) -> None:
        """The session's deferred work, done whole now (before a snapshot)."""
        held.session.do_deferred_work()
        self._deferred.pop(held.session.id, None)
