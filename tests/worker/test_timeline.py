"""The session timeline (worker/timeline.py): bounded, oldest first, and its JSON read off the
frame (the framing error null where not measured); a MATCH frame's shot, candidates, players, events
and planned cut; buffering frames."""

from __future__ import annotations

import numpy as np
import orjson
import pytest

from camdirector.geometry.camera import CameraPose
from camdirector.pipeline.inputs import EventKind, GameEvent
from camdirector.pipeline.match.frame import (
    Candidate,
    MatchFrame,
    PlannedCut,
    Replay,
    ReplayedMoment,
    ShotChoice,
    ShotKind,
)
from camdirector.pipeline.state import FrameState
from camdirector.worker.timeline import Timeline, dumps


def state(frame: int, yaw_rad: float = 0.0, cut: bool = False) -> FrameState:
    s = FrameState(
        frame=frame, time_s=frame / 60.0, dt_s=1 / 60.0, cut=cut, shot_id=frame // 10, visibility=0.5, flags=["search_coast"]
    )
    s.pose = CameraPose(
        np.array([float(frame), 1.5, -2.0]), np.array([0.0, np.sin(yaw_rad / 2), 0.0, np.cos(yaw_rad / 2)]), 50.0
    )  # yaw about +Y
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
    s.framing_error = 0.123456
    timeline.add(s, compute_ms=0.125)
    s.flags.append("later")  # the state is not kept by reference
    s.pose.position_world[0] = 99.0
    (frame,) = orjson.loads(dumps(timeline.as_json()))
    assert frame == {
        "frame": 12,
        "time_s": 0.2,
        "camera": [12.0, 1.5, -2.0],
        "forward": pytest.approx([-1.0, 0.0, 0.0], abs=1e-4),  # -Z turned 90 deg about +Y
        "targets": [[0.0, 1.0, 12.0]],
        "cut": True,
        "shot_id": 1,
        "visibility": 0.5,
        "framing_error": 0.1235,
        "flags": ["search_coast"],
        "scores": {},
        "compute_ms": 0.125,
    }


def test_a_frame_with_no_framing_error_shows_null():
    """A rig that does not measure it (MATCH) or a framed point behind the camera leave it NaN."""
    timeline = Timeline()
    for frame, error_screen in ((1, 0.0), (2, float("nan")), (3, 2.5)):
        s = state(frame)
        s.framing_error = error_screen
        timeline.add(s, compute_ms=0.1)
    rows = timeline.as_json()
    assert [r["framing_error"] for r in rows] == [0.0, None, 2.5]
    assert [r["framing_error"] for r in orjson.loads(dumps(rows))] == [0.0, None, 2.5]


ROSTER = (("a0", 0), ("b0", 1))


def match_state(frame: int, buffering: bool = False) -> FrameState:
    """A MATCH frame of two players; while buffering, no pose (the rig's answer)."""
    s = state(frame)
    s.match = MatchFrame(ROSTER, buffering)
    s.aim_points_world = [np.array([0.0, 1.5, 0.0]), np.array([4.0, 1.5, 0.0])]
    if buffering:
        s.pose = None
    return s


def test_a_match_frame_as_json():
    timeline = Timeline()
    s = match_state(30)
    s.match.shot = ShotChoice(("a0", "b0"), ShotKind.DUEL, "fight: a0 vs b0; through a0's eyes", eyes_id="a0")
    preview = CameraPose(np.array([2.0, 3.0, -5.0]), np.array([0.0, 0.0, 0.0, 1.0]), 50.0)  # looking down -Z
    s.match.candidates = [Candidate(preview, ShotChoice(("b0",), ShotKind.FOLLOW, "fighter: b0"), 0.41234)]
    s.match.events = [GameEvent(EventKind.KILL, "a0", "b0", 0, 0.5, "headshot")]
    s.match.planned_cut = PlannedCut(2.75, ShotChoice(("a0",), ShotKind.FOLLOW, "planned objective in 2.2 s: a0"))
    timeline.add(s, compute_ms=1.0)
    (frame,) = orjson.loads(dumps(timeline.as_json()))
    assert frame["targets"] == [[0.0, 1.5, 0.0], [4.0, 1.5, 0.0]]
    assert frame["players"] == ["a0", "b0"] and frame["teams"] == [0, 1] and frame["buffering"] is False
    assert frame["framing_error"] is None  # the MATCH rig does not measure it
    assert frame["shot"] == {
        "subject_ids": ["a0", "b0"],
        "kind": "SHOT_DUEL",
        "reason": "fight: a0 vs b0; through a0's eyes",
        "held": False,
        "replay": None,
        "eyes_id": "a0",
    }
    assert frame["candidates"] == [
        {
            "shot": {
                "subject_ids": ["b0"],
                "kind": "SHOT_FOLLOW",
                "reason": "fighter: b0",
                "held": False,
                "replay": None,
                "eyes_id": "",
            },
            "score": 0.4123,
            "camera": [2.0, 3.0, -5.0],
            "forward": [-0.0, -0.0, -1.0],
        }
    ]
    assert frame["events"] == [
        {"time_s": 0.5, "kind": "EVENT_KILL", "actor_id": "a0", "other_actor_id": "b0", "priority": 0, "label": "headshot"}
    ]
    assert frame["planned_cut"] == {
        "time_s": 2.75,
        "shot": {
            "subject_ids": ["a0"],
            "kind": "SHOT_FOLLOW",
            "reason": "planned objective in 2.2 s: a0",
            "held": False,
            "replay": None,
            "eyes_id": "",
        },
    }


def test_a_replay_and_a_replay_candidate_name_the_moment_they_show():
    timeline = Timeline()
    s = match_state(30)
    replay = Replay(kill_time_s=0.4, from_s=-1.6, until_s=0.9)
    s.match.shot = ShotChoice(("a0", "b0"), ShotKind.REPLAY, "replay of the kill: a0 -> b0", replay=replay)
    s.match.replay_of = ReplayedMoment(12, -1.4)
    pose = CameraPose(np.array([2.0, 3.0, -5.0]), np.array([0.0, 0.0, 0.0, 1.0]), 50.0)
    s.match.candidates = [Candidate(pose, s.match.shot, 0.5, ReplayedMoment(36, 0.4))]
    timeline.add(s, compute_ms=1.0)
    (frame,) = orjson.loads(dumps(timeline.as_json()))
    assert frame["shot"]["kind"] == "SHOT_REPLAY"
    assert frame["shot"]["replay"] == {"frame": 12, "time_s": -1.4, "kill_time_s": 0.4}
    assert frame["candidates"][0]["shot"]["replay"] == {"frame": 36, "time_s": 0.4, "kill_time_s": 0.4}


def test_candidates_keep_to_their_frames():
    timeline = Timeline()
    for frame, count in ((1, 2), (2, 0), (3, 1)):
        s = match_state(frame)
        s.match.shot = ShotChoice((), ShotKind.OVERVIEW, "overview")
        s.match.candidates = [
            Candidate(
                CameraPose(np.array([float(frame), float(k), 0.0]), np.array([0.0, 0.0, 0.0, 1.0]), 50.0),
                ShotChoice(("a0",), ShotKind.FOLLOW, "f"),
                1.0,
            )
            for k in range(count)
        ]
        timeline.add(s, compute_ms=1.0)
    rows = orjson.loads(dumps(timeline.as_json()))
    assert [[c["camera"][:2] for c in row["candidates"]] for row in rows] == [[[1.0, 0.0], [1.0, 1.0]], [], [[3.0, 0.0]]]
    assert [row["shot"]["kind"] for row in rows] == ["SHOT_OVERVIEW"] * 3 and rows[0]["planned_cut"] is None


def test_buffering_frames_have_no_camera_and_give_way_to_the_program():
    timeline = Timeline()
    for frame in (1, 2, 3):  # input frames while the delay fills
        timeline.add(match_state(frame, buffering=True), compute_ms=0.5)
    rows = timeline.as_json()
    assert [(r["frame"], r["buffering"], r["camera"], r["forward"], r["shot"]) for r in rows] == [
        (f, True, None, None, None) for f in (1, 2, 3)
    ]
    assert timeline.as_json(after_frame=2)[0]["frame"] == 3
    program = match_state(1)  # the program's first moment: the game's frame 1
    program.match.shot = ShotChoice((), ShotKind.OVERVIEW, "overview")
    timeline.add(program, compute_ms=0.5)
    timeline.add(match_state(2), compute_ms=0.5)
    rows = timeline.as_json()
    assert [(r["frame"], r["buffering"]) for r in rows] == [(1, False), (2, False)]  # frame numbers still grow
    assert rows[0]["camera"].tolist() == [1.0, 1.5, -2.0] and [r["frame"] for r in timeline.as_json(after_frame=1)] == [2]
