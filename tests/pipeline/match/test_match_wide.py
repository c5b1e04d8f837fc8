"""A kill no level Toric place can show: the DUEL gives way to a wide, level view of the pair
from a camera that sees them both (shot_builder.py, ShotBuilder.build)."""

from __future__ import annotations

import numpy as np

from camdirector.geometry.transforms import RigidTransform, quat_to_matrix
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.settings import MatchSettings
from tests.pipeline.match.scenes import BareRig, Match, at_time, facing, kill, yaw_quat
from tests.pipeline.match.test_match_places import block, seen_share

KILL_S = 12.0
LENGTH_M = 22.0
NODE = (0.0, 2.7, LENGTH_M + 5.0)  # a node of the level's graph in the tunnel, 5 m past b, under its roof


def tunnel_duel(t: float):
    """a and b face each other 22 m apart along +z."""
    return {"a": ((0.0, 0.0), facing((0, 0), (0, LENGTH_M))), "b": ((0.0, LENGTH_M), facing((0, LENGTH_M), (0, 0)))}


def test_a_duel_no_level_toric_place_sees_is_shown_wide_from_a_camera_that_sees_both():
    # a tunnel 3 m wide and 3 m high, open at both ends: every Toric place is above the roof,
    # behind a wall, or (the wide compositions over a shoulder) shows the pair one above the other
    # further apart than the frame is high; the graph node down the tunnel sees both over b's head
    walls = [block((x, 1.5, LENGTH_M / 2 + 3.0), (0.2, 3.0, LENGTH_M + 8.0)) for x in (-1.5, 1.5)]
    walls.append(block((0.0, 3.1, LENGTH_M / 2 + 3.0), (3.2, 0.2, LENGTH_M + 8.0)))
    match = Match({"a": 1, "b": 2}, tunnel_duel, [kill("a", "b", KILL_S)], delay_s=10.0, walls=walls)
    rig = BareRig(match, MatchSettings())
    rig.rig.builder.extra_overview_cameras = np.array([NODE])
    states = rig.run(KILL_S + 10.0 + 2.0)
    state = at_time(states, KILL_S)
    assert set(state.match.shot.subject_ids) == {"a", "b"}
    rng = np.random.default_rng(5)
    places = tunnel_duel(KILL_S)
    for player in ("a", "b"):
        transform = RigidTransform(np.array([places[player][0][0], 0.0, places[player][0][1]]), yaw_quat(places[player][1]))
        assert seen_share(state.pose, walls, transform, rng) >= 0.5, player
    assert state.match.shot.kind == ShotKind.OVERVIEW and "wide: no level duel place sees both" in state.match.shot.reason
    right = quat_to_matrix(state.pose.rotation_xyzw[None])[0][:, 0]
    assert abs(right[1]) < 1e-9  # level: the camera's x axis is horizontal
