"""A session's recent frames, for the dashboard: where the camera and the targets were, cuts and
shots, visibility, and why the camera moved (the frame's flags: `search_cut`, `pulled_in`,
`tracks_cut_occlusion`, ...).

A bounded ring of plain values kept by the session table beside each session (in the worker that
holds it) and fed by the frame it has just answered; `GET /v1/sessions/{id}` reads it through the
worker's "timeline" operation. Stale frames are not added: they repeat the pose.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.transforms import quat_to_matrix
from camdirector.server.pipeline import FrameState

TIMELINE_FRAMES = 600   # frames kept per session: 10 s at 60 Hz


@dataclass(frozen=True)
class TimelineFrame:
    """One answered frame, kept as computed (the JSON is made only when someone asks).
    camera_world: (3,) metres; rotation_xyzw: (4,) camera-to-world; targets_world: (k, 3) aim
    point per target; compute_ms: the server's time for the frame."""

    frame: int
    time_s: float
    camera_world: np.ndarray
    rotation_xyzw: np.ndarray
    targets_world: np.ndarray
    cut: bool
    shot_id: int
    visibility: float
    flags: tuple[str, ...]
    compute_ms: float

    def as_json(self) -> dict:
        forward = -quat_to_matrix(self.rotation_xyzw)[:, 2]   # the camera looks down its local -Z
        return {"frame": self.frame, "time_s": self.time_s, "camera": _rounded(self.camera_world),
                "forward": _rounded(forward), "targets": [_rounded(t) for t in self.targets_world],
                "cut": self.cut, "shot_id": self.shot_id, "visibility": round(self.visibility, 4),
                "flags": list(self.flags), "compute_ms": round(self.compute_ms, 3)}


def _rounded(v: np.ndarray) -> list[float]:
    return [round(float(c), 4) for c in v]


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
            flags=tuple(state.flags), compute_ms=float(compute_ms)))

    def as_json(self, last: int | None = None) -> list[dict]:
        """The newest `last` frames (all when None), oldest first."""
        frames = list(self._frames)
        return [f.as_json() for f in (frames[-last:] if last else frames)]
