"""The kill-coverage ceilings (evaluation/match/ceilings.py): the greedy 2-s schedule on hand-picked
kill times, and the reference cameras on the tiny duel of test_measure.py, open and walled in."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.evaluation.match.ceilings import greedy_schedule, match_ceilings, reference_poses
from camdirector.evaluation.match.measure import BodySampler
from camdirector.geometry.camera import Lens, in_frame
from tests.evaluation.match.test_measure import duel, floor


@pytest.mark.parametrize(
    "times, reachable, expected",
    [
        # the program starts at 0: shots start at 0, 2 (just after kill 1 would be too soon) and 4
        ([1.0, 2.0, 3.0, 4.0], [1, 1, 1, 1], [1, 1, 0, 1]),
        ([2.5, 3.0, 4.6], [1, 1, 1], [1, 1, 1]),  # shots at 0, 2.5+, 4.5+
        ([2.5, 3.0, 4.4], [1, 1, 1], [1, 1, 0]),  # the third would start 2 s after 2.5+
        ([2.5, 3.0, 4.4], [1, 0, 1], [1, 0, 1]),  # an unreachable kill takes no shot
        ([5.0, 5.0], [1, 1], [1, 0]),  # two kills at one instant: one shot
    ],
)
def test_the_greedy_schedule_gives_every_covered_kill_a_shot_of_at_least_2_s(times, reachable, expected):
    covered = greedy_schedule(np.array(times), np.array(reachable, dtype=bool), 2.0, 0.0)
    assert covered.astype(int).tolist() == expected


def test_the_reference_cameras_frame_both_aim_points():
    lens = Lens()
    a, v = np.array([0.0, 1.1, 0.0]), np.array([6.0, 1.1, 0.0])
    poses = reference_poses(a, v, lens)
    assert len(poses) == 3
    for pose in poses:
        assert in_frame(pose, lens, np.stack([a, v])).all()
    assert np.linalg.norm(poses[0].position_world - a) == pytest.approx(np.hypot(2.0, 0.6))  # behind the attacker
    assert poses[0].position_world[0] < a[0]
    assert poses[1].position_world[2] == pytest.approx(-poses[2].position_world[2])  # either side


def test_a_kill_is_reachable_on_open_ground_and_not_inside_a_closed_box():
    match = duel()
    bodies = BodySampler(match, np.random.default_rng(0))
    open_ground = match_ceilings(match, bodies, Lens(), floor())
    assert open_ground.reachable.tolist() == [True] and open_ground.greedy.tolist() == [True]
    # walls all round the duel, 0.5 m from it and 4 m high: no reference camera sees in
    walls = [
        ((-1.0, 0.0, -1.0), (5.0, 4.0, -0.6)),
        ((-1.0, 0.0, 0.6), (5.0, 4.0, 1.0)),
        ((-1.0, 0.0, -1.0), (-0.6, 4.0, 1.0)),
        ((4.6, 0.0, -1.0), (5.0, 4.0, 1.0)),
    ]
    boxed = match_ceilings(match, bodies, Lens(), floor(*walls))
    assert boxed.reachable.tolist() == [False] and boxed.as_json()["greedy_2s_kill_coverage"] == 0.0
