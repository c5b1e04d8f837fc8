"""A session's recent frames, for the dashboard: where the camera and the targets were, cuts and
shots, visibility, and why the camera moved (the frame's flags: `search_cut`, `pulled_in`,
`tracks_cut_occlusion`, ...; the TRACKS rig's scores of the target it chose).

A bounded ring of plain values kept by the session table beside each session (in the worker that
holds it) and fed by the frame it has just answered; `GET /v1/sessions/{id}` reads it through the
worker's "timeline" operation. Stale frames are not added: they repeat the pose.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import orjson

from camdirector.geometry.transforms import quat_to_matrix
from camdirector.server.pipeline.stages import FrameState

TIMELINE_FRAMES = 600   # frames kept per session: 10 s at 60 Hz


@dataclass(frozen=True)
class TimelineFrame:
    """One answered frame, kept as computed (the JSON is made only when someone asks).
    camera_world: (3,) metres; rotation_xyzw: (4,) camera-to-world; targets_world: (k, 3) aim
    point per target; scores: the rig's own scoring of its choice (FrameState.scores, not copied:
    a new dict every frame); compute_ms: the server's time for the frame."""

    frame: int
    time_s: float
    camera_world: np.ndarray
    rotation_xyzw: np.ndarray
    targets_world: np.ndarray
    cut: bool
    shot_id: int
    visibility: float
    flags: tuple[str, ...]
    scores: dict[str, float]
    compute_ms: float


class Timeline:
    """The last `capacity` answered frames of one session, oldest first."""

    def __init__(self, capacity: int = TIMELINE_FRAMES) -> None:
        self._frames: deque[TimelineFrame] = deque(maxlen=capacity)

    def add(self, state: FrameState, compute_ms: float) -> None:
        """Costs a few microseconds a frame: copies, no conversion."""
        pose = state.pose
        self._frames.append(TimelineFrame(
            frame=int(state.frame), time_s=float(state.time_s), camera_world=pose.position_world.copy(),
            rotation_xyzw=pose.rotation_xyzw.copy(), targets_world=np.array(state.aim_points_world),
            cut=bool(state.cut), shot_id=int(state.shot_id), visibility=float(state.visibility),
            flags=tuple(state.flags), scores=state.scores, compute_ms=float(compute_ms)))

    def as_json(self, last: int | None = None, after_frame: int | None = None) -> list[dict]:
        """The newest `last` frames (all when None) of those after frame number `after_frame`
        (a live view asks only for what it has not seen), oldest first, for `dumps`: frame, time_s,
        camera, forward (unit), targets, cut, shot_id, visibility, flags, scores, compute_ms; vectors are
        numpy rows rounded to 0.1 mm. Built in bulk, since the worker that answers this also
        answers its sessions' frames (600 frames: about 2 ms with `dumps`, 18 ms as plain dicts and json)."""
        frames = list(self._frames)
        if after_frame is not None:
            first = len(frames)
            while first > 0 and frames[first - 1].frame > after_frame:   # frame numbers only grow
                first -= 1
            frames = frames[first:]
        frames = frames[-last:] if last else frames
        if not frames:
            return []
        camera = np.stack([f.camera_world for f in frames]).round(4)
        forward = -quat_to_matrix(np.stack([f.rotation_xyzw for f in frames]))[:, :, 2]   # the camera's -Z
        forward = forward.round(4)
        targets = np.stack([f.targets_world for f in frames]).round(4)   # a session's targets are fixed
        return [{"frame": f.frame, "time_s": f.time_s, "camera": c, "forward": d, "targets": t,
                 "cut": f.cut, "shot_id": f.shot_id, "visibility": round(f.visibility, 4),
                 "flags": f.flags, "scores": f.scores, "compute_ms": round(f.compute_ms, 3)}
                for f, c, d, t in zip(frames, camera, forward, targets)]


def dumps(value) -> bytes:
    """JSON bytes of a value holding `Timeline.as_json` frames (numpy rows and all)."""
    return orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY)
