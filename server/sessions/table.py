"""The session table: the sessions one process holds, and the requests that reach them.

Used the same way inside a worker process and inline in the front process (workers=0): the
worker pool routes a request by session id and calls `handle_bytes`.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import orjson
from google.protobuf import json_format

from camdirector.server.errors import DirectorError, internal, invalid, not_found, precondition
from camdirector.server.sessions import codec
from camdirector.server.sessions.levels import LevelCache
from camdirector.server.sessions.map_view import anticipation_png
from camdirector.server.sessions.monitor import Monitor, Reply
from camdirector.server.sessions.pose_out import PoseSender
from camdirector.server.sessions.recording import RecordingWriter
from camdirector.server.sessions.session import Session
from camdirector.server.sessions.timeline import Timeline
from camdirector.server.sessions.timeline import dumps as timeline_dumps
from camdirector.server.sessions.views import ViewQuery, render_job, scene_geometry
from camdirector.server.settings import ServerSettings
from camdirector.v1 import director_pb2 as pb

log = logging.getLogger("camdirector.sessions")

@dataclass
class FrameMetrics:
    """Timings of one answered frame, for the front's Prometheus histograms."""

    compute_ms: float
    stage_ms: dict[str, float]
    stale: bool


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


class SessionTable:
    def __init__(self, settings: ServerSettings, clock: Callable[[], float] = time.perf_counter):
        self.settings = settings
        self.clock = clock
        self.held: dict[str, HeldSession] = {}
        self.levels = LevelCache(settings.data_dir)  # the TRACKS rig's levels, loaded once per process
        self.monitor: Monitor | None = None          # the render process of the sessions' views, started on the first

    def _get(self, session_id: str) -> HeldSession:
        held = self.held.get(session_id)
        if held is None:
            raise not_found(f"unknown session id {session_id!r} (closed, reclaimed, or never created)")
        return held

    def create(self, session_id: str, req: pb.CreateSessionRequest) -> pb.CreateSessionResponse:
        pose_outputs = codec.pose_outputs_from_request(req)  # cheap checks before the scene's meshes
        scene = codec.scene_from_request(req, self.settings, self.levels)
        held = self.held[session_id] = HeldSession(Session(session_id, scene, clock=self.clock), req.style)
        if pose_outputs:  # a failure from here on drops the session (handle_bytes)
            held.pose_sender = PoseSender(session_id, pose_outputs, scene.lens.aspect)
        response = pb.CreateSessionResponse(session_id=session_id)
        if req.record or self.settings.record_all:
            path = self.settings.recordings_dir / f"{session_id}.cdrec"
            held.recorder = RecordingWriter(path)
            held.recorder.write(pb.RecordEntry(create=req))
            response.recording_path = str(path)
        return response

    def frame(self, msg: pb.FrameUpdate) -> pb.CameraUpdate:
        return pb.CameraUpdate.FromString(self._frame(msg, msg.SerializeToString())[0])

    def _frame(self, msg: pb.FrameUpdate, payload: bytes) -> tuple[bytes, FrameMetrics]:
        """The serialized reply to `msg` (whose bytes as received are `payload`) and its metrics,
        taken from the frame's state rather than read back out of the reply."""
        t0 = self.clock()
        held = self._get(msg.session_id)
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
            reply = codec.camera_update_msg(state, compute_ms=0.0)
            reply.compute_ms = (self.clock() - t0) * 1e3
            held.timeline.add(state, reply.compute_ms)
            stage_ms = state.stage_ms
        body = reply.SerializeToString()
        if held.recorder is not None:
            held.recorder.write_frame_and_camera(payload, body)
        if held.pose_sender is not None and state is not None and state.pose is not None:
            held.pose_sender.send(state.pose, state.time_s)  # microseconds; drops rather than fails (pose_out.py)
        return body, FrameMetrics(reply.compute_ms, stage_ms, reply.stale)

    def update_style(self, msg: pb.UpdateStyleRequest) -> pb.UpdateStyleResponse:
        held = self._get(msg.session_id)
        held.session.set_style(codec.style_from_msg(msg.style, held.session.lens, held.session.style))
        held.style_msg = msg.style
        if held.recorder is not None:
            held.recorder.write(pb.RecordEntry(style=msg))
        return pb.UpdateStyleResponse()

    def take_shot(self, msg: pb.TakeShotRequest) -> pb.TakeShotResponse:
        """A human director's shot in a MATCH session, held until released (MatchRig.take)."""
        held = self._get(msg.session_id)
        session = held.session
        if session.players is None:
            raise precondition(f"TakeShot is for a RIG_MATCH session; session {msg.session_id} runs the "
                               f"{session.style.rig.name} rig")
        try:
            shot = session.rig.take(*codec.take_from_msg(msg, session.players))
        except ValueError as exc:  # a player named twice, a kind that does not fit the count
            raise invalid(str(exc)) from None
        if held.recorder is not None:
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

    def drop(self, session_id: str) -> None:
        """Ends a session if present, releasing what it holds (its occlusion maps' GL objects or
        Embree scenes, its recording file, its pose outputs' socket): on close, on reclaiming an
        abandoned one, on a failed create."""
        held = self.held.pop(session_id, None)
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
        """Ends every session and the render process (the worker is stopping)."""
        for session_id in list(self.held):
            self.drop(session_id)
        if self.monitor is not None:
            self.monitor.close()

    def handle_bytes(self, op: str, session_id: str, payload: bytes) -> tuple[bytes, FrameMetrics | None]:
        """One request as the transports carry it: serialized in, serialized out.

        Raises DirectorError for anything the client must hear about; an unexpected exception
        becomes INTERNAL and leaves the other sessions untouched.
        """
        try:
            if op == "frame":
                return self._frame(_parse(pb.FrameUpdate, payload, session_id), payload)
            if op == "create":
                return self.create(session_id, _parse(pb.CreateSessionRequest, payload)).SerializeToString(), None
            if op == "style":
                return self.update_style(_parse(pb.UpdateStyleRequest, payload, session_id)).SerializeToString(), None
            if op == "close":
                return self.close(session_id).SerializeToString(), None
            if op == "take":
                return self.take_shot(_parse(pb.TakeShotRequest, payload, session_id)).SerializeToString(), None
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
