"""The session timeline (server/sessions/timeline.py): bounded, oldest first, and its JSON read off the frame."""
from __future__ import annotations

import numpy as np
import orjson
import pytest

from camdirector.geometry.camera import CameraPose
from camdirector.server.pipeline.stages import FrameState
from camdirector.server.sessions.timeline import Timeline, dumps


def state(frame: int, yaw_rad: float = 0.0, cut: bool = False) -> FrameState:
    s = FrameState(frame=frame, time_s=frame / 60.0, dt_s=1 / 60.0, cut=cut, shot_id=frame // 10,
                   visibility=0.5, flags=["search_coast"])
    s.pose = CameraPose(np.array([float(frame), 1.5, -2.0]),
                        np.array([0.0, np.sin(yaw_rad / 2), 0.0, np.cos(yaw_rad / 2)]), 50.0)  # yaw about +Y
    s.aim_points_world = [np.array([0.0, 1.0, float(frame)])]
    return s


def test_keeps_the_newest_frames_oldest_first():
    timeline = Timeline(capacity=3)
    for frame in range(1, 6):
        timeline.add(state(frame), compute_ms=0.25)
    assert [f["frame"] for f in timeline.as_json()] == [3, 4, 5]
    assert Timeline().as_json() == []
    assert [f["frame"] for f in timeline.as_json(last=2)] == [4, 5]
    assert [f["frame"] for f in timeline.as_json(after_frame=3)] == [4, 5]
    assert [f["frame"] for f in timeline.as_json(last=1, after_frame=3)] == [5]
    assert timeline.as_json(after_frame=5) == [] and len(timeline.as_json(after_frame=0)) == 3


def test_a_frame_as_json():
    timeline = Timeline()
    s = state(12, yaw_rad=np.pi / 2, cut=True)
    timeline.add(s, compute_ms=0.125)
    s.flags.append("later")                       # the state is not kept by reference
    s.pose.position_world[0] = 99.0
    (frame,) = orjson.loads(dumps(timeline.as_json()))
    assert frame == {"frame": 12, "time_s": 0.2, "camera": [12.0, 1.5, -2.0],
                     "forward": pytest.approx([-1.0, 0.0, 0.0], abs=1e-4),   # -Z turned 90 deg about +Y
                     "targets": [[0.0, 1.0, 12.0]], "cut": True, "shot_id": 1, "visibility": 0.5,
                     "flags": ["search_coast"], "scores": {}, "compute_ms": 0.125}
