"""A REPLAY over the wire: the program's and a candidate's shot carry the moment their picture
shows and the kill, read back by the SDK's messages; a TakeShot of SHOT_REPLAY keeps its kind."""

from __future__ import annotations

import numpy as np

import camdirector_client as cd
from camdirector.geometry.camera import CameraPose
from camdirector.pipeline.match.frame import Candidate, MatchFrame, Replay, ReplayedMoment, ShotChoice, ShotKind
from camdirector.pipeline.state import FrameState
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.codec import camera_update_msg, take_from_msg
from camdirector_client import wire

POSE = CameraPose(np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, 0.0, 1.0]), 50.0)


def test_a_replay_and_its_candidate_round_trip_with_the_replayed_moment():
    state = FrameState(frame=300, time_s=10.0, dt_s=1 / 30)
    state.pose = POSE
    state.match = MatchFrame((("a", 1), ("b", 2)))
    replay = Replay(kill_time_s=8.5, from_s=6.5, until_s=9.0)
    state.match.shot = ShotChoice(("a", "b"), ShotKind.REPLAY, "replay of the kill: a -> b", replay=replay)
    state.match.replay_of = ReplayedMoment(196, 6.5333)
    live = ShotChoice(("b",), ShotKind.FOLLOW, "fighter: b")
    state.match.candidates = [Candidate(POSE, live, 0.3), Candidate(POSE, state.match.shot, 0.9, ReplayedMoment(255, 8.5))]
    sent = camera_update_msg(state, compute_ms=1.0).SerializeToString()
    got = cd.pb.CameraUpdate.FromString(sent)  # as the SDK reads it
    assert got.frame == 300 and got.time_s == 10.0  # the program's own moment goes on
    assert got.shot.kind == cd.pb.SHOT_REPLAY and list(got.shot.subject_ids) == ["a", "b"]
    assert (got.shot.replay_frame, got.shot.replay_time_s, got.shot.replay_kill_time_s) == (196, 6.5333, 8.5)
    assert got.candidates[0].shot.replay_frame == 0 and got.candidates[0].shot.kind == cd.pb.SHOT_FOLLOW
    assert (got.candidates[1].shot.replay_frame, got.candidates[1].shot.replay_kill_time_s) == (255, 8.5)


def test_a_take_of_a_replay_keeps_its_kind_from_the_sdk_to_the_rig():
    request = pb.TakeShotRequest.FromString(wire.take_shot_request("s", ["a", "b"], cd.pb.SHOT_REPLAY, False).SerializeToString())
    assert take_from_msg(request, frozenset({"a", "b"})) == (["a", "b"], ShotKind.REPLAY, False)
