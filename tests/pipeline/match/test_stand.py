"""A planned shot's camera that stands where it sees its players through (stand.py), and a move
through a wall held however far rather than cut into a shot under min_shot_s while the hold shows
one of the framed subjects (program_camera.py, rig.py `_cut_short`; issue 41: a rhythm casters use)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from camdirector.geometry.inside import LevelInterior
from camdirector.geometry.meshes import TriMesh, box
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.look_along import look_along
from camdirector.pipeline.match.program_camera import ProgramCamera
from camdirector.pipeline.match.program_shot import Shot
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.stand import best_stand
from tests.pipeline.match.scenes import BareRig, Match, facing
from tests.pipeline.match.test_framing_band import rig_of
from tests.pipeline.match.test_match_places import block
from tests.pipeline.match.test_seen_again import DT_S, _follow_of_a, _shows_a

KILL_S = 2.5
OPEN_NODE = np.array([6.0, 2.5, 4.0])  # beside the pair's fight, in the open
WALLED_NODE = np.array([-6.0, 2.5, 4.0])  # as near on the other side, behind WALL
WALL = block((-4.0, 2.0, 4.0), (0.4, 4.0, 16.0))  # a wall along z between the pair and WALLED_NODE


def approach(t: float):
    """a walks toward b along +z (from z = 0 to z = 3 over 3 s), b waits at z = 8."""
    z = min(t, 3.0)
    return {"a": ((0.0, z), facing((0, z), (0, 8))), "b": ((0.0, 8.0), facing((0, 8), (0, z)))}


def _kill_rig(walls=()) -> BareRig:
    """4 s of `approach` in a bare rig whose buffer holds all of it (a 4 s delay)."""
    # a Toric camera's stand (our director would otherwise look through a's eyes: first_person.py)
    rig = BareRig(Match({"a": 1, "b": 2}, approach, delay_s=4.0, walls=list(walls)), MatchSettings(first_person=False))
    rig.run(4.0)
    return rig


def _stand(rig: BareRig, nodes: np.ndarray, settings: MatchSettings | None = None):
    r = rig.rig
    cut = r.buffer.at(0.5)
    camera = r.builder.cameras(ShotKind.DUEL, (0, 1), cut, default=True)[0][0]
    return best_stand(
        camera, (0, 1), r.buffer, cut, (KILL_S,), nodes, r.visibility, r.builder.body_heights_m, settings or r.settings, None
    )


def test_a_node_that_sees_the_fight_through_is_where_the_shot_stands():
    rig = _kill_rig([WALL])
    stand = _stand(rig, np.array([WALLED_NODE, OPEN_NODE]))
    assert stand is not None and np.array_equal(stand, OPEN_NODE)


def test_no_stand_where_walls_hide_the_fight_from_every_node_in_reach():
    rig = _kill_rig([WALL])
    assert _stand(rig, np.array([WALLED_NODE])) is None
    far = OPEN_NODE + [40.0, 0.0, 0.0]  # sees them, beyond stand_reach_m
    assert _stand(rig, np.array([far])) is None


def test_a_stand_must_see_at_least_as_well_as_the_torus():
    rig = _kill_rig()
    assert _stand(rig, np.array([OPEN_NODE])) is not None
    assert _stand(rig, np.array([OPEN_NODE]), MatchSettings(stand_margin=1.0)) is None


def test_a_stand_that_shows_its_kept_player_too_small_or_too_large_is_not_taken():
    rig = _kill_rig()
    settings = dataclasses.replace(rig.rig.settings, stand_shown_height_min=0.4)  # at most 2.4 m from a
    assert _stand(rig, np.array([OPEN_NODE]), settings) is None
    assert _stand(rig, np.array([[0.5, 1.6, 1.0]])) is None  # a metre from a's chest: taller than shown_height_max


def test_a_planned_shot_stands_still_and_frames_its_pair_as_its_torus_would():
    rig = _kill_rig([WALL])
    r = rig.rig
    r.builder.extra_overview_cameras = np.array([WALLED_NODE, OPEN_NODE])  # the level's camera nodes
    cut = r.buffer.at(0.5)
    choice = ShotChoice(("a", "b"), ShotKind.DUEL, "planned kill")
    shot, _ = r.builder.build(choice, (0, 1), cut, [r.buffer.at(KILL_S)], None, None, 0.5, None, (KILL_S,), r.buffer)
    assert shot is not None and np.array_equal(shot.camera.stand_world, OPEN_NODE)
    assert shot.choice.reason.endswith("standing where it sees them through")
    for time_s in (0.5, 1.5, KILL_S):
        moment = r.buffer.at(time_s)
        shot.camera.advance(moment, 0.1, 0.5)
        pose = shot.camera.pose(moment)
        assert np.array_equal(pose.position_world, OPEN_NODE)
        place = shot.camera.place_at(time_s)
        expected = shot.camera.pose_from(moment, OPEN_NODE, place.width)
        assert np.allclose(pose.rotation_xyzw, expected.rotation_xyzw)


def _room_and_panel(panel: TriMesh) -> TriMesh:
    """A 30 x 8 x 70 m room round the players (faces inward) with a solid panel in it."""
    room = box((30.0, 8.0, 70.0))
    return TriMesh(
        np.concatenate([room.vertices + [0.0, 4.0, 15.0], panel.vertices]),
        np.concatenate([room.faces[:, ::-1], panel.faces + len(room.vertices)]).astype(np.int32),
    )


@pytest.mark.parametrize("pair", [False, True], ids=["follow", "pair"])
@pytest.mark.parametrize("panel_width_m, held", [(0.4, True), (12.0, False)])
def test_a_long_move_through_a_wall_is_held_only_while_a_cut_would_be_short_and_the_hold_shows_a_subject(
    panel_width_m, held, pair
):
    """A pair's hold shows a alone (b, 30 m off, is behind it): held all the same, a pan on one
    of the two rather than a shot under min_shot_s (on the real 4on4's first 3 minutes, holding
    only where both were shown left 48 shots under 2 s; held where either is, 30)."""
    bare = rig_of()
    place = _follow_of_a(bare)[1].pose(bare.rig.buffer.moments[-1]).position_world
    behind = place + [0.0, 0.0, 6.0]  # last frame's camera: a 6 m move (over wall_hold_max_m) through the panel
    # a narrow panel between the two leaves a in view from behind; a wide one hides it
    level = _room_and_panel(block(place + [0.0, 0.0, 3.0], (panel_width_m, 8.0, 0.3)))
    rig = rig_of([level])
    moment, camera, shot = _follow_of_a(rig)
    if pair:
        shot = Shot(ShotChoice(("a", "b"), ShotKind.DUEL, "test"), (0, 1), camera, 0.0)
        assert shot.framed(moment.time_s) == (0, 1)
    in_level = InLevel(LevelInterior(level), np.zeros((0, 3)), MatchSettings().pull_margin_m)
    r = rig.rig
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    last = look_along(behind, moment.aims_world[0] - behind, r.lens.vertical_fov_deg)
    assert in_level.crossed(behind, place)

    pose, flags = program.step(moment, DT_S, camera, shot, 0.5, last, cut_short=False)
    assert "held_before_wall" not in flags and np.allclose(pose.position_world, place)  # the rig cuts through it

    pose, flags = program.step(moment, DT_S, camera, shot, 0.5, last, cut_short=True)
    assert ("held_before_wall" in flags) == held
    if held:
        assert np.array_equal(pose.position_world, behind) and not in_level.crossed(behind, pose.position_world)
        assert _shows_a(rig, moment, pose) >= MatchSettings().candidate_seen
    else:
        assert np.allclose(pose.position_world, place)
