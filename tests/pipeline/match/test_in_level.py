"""Every camera inside the level (issue 41, item 1): in_level.py moves a pose the places test
rejects toward its anchor, and a match session on a level shows no program or candidate pose
outside the level or inside solid, and no move through a wall without a cut."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from camdirector.evaluation.match.measure import JUMP_SPEED_M_S
from camdirector.geometry.camera import CameraPose, level_look_rotation, project_to_screen
from camdirector.geometry.inside import LevelInterior
from camdirector.geometry.meshes import TriMesh, box
from camdirector.pipeline.inputs import LoadedLevel
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.session import Session
from camdirector.precompute.tracks.pipeline import precompute_level
from camdirector.precompute.tracks.track_settings import TrackSettings
from tests.geometry.test_inside import room_with_slab
from tests.pipeline.match.scenes import LENS, melee

TURNED = np.array([0.1, 0.2, 0.3, 0.927])  # some rotation, kept by every move
CENTRE = np.array([0.0, 2.0, 0.0])


def pose_at(position) -> CameraPose:
    return CameraPose(np.array(position, dtype=np.float64), TURNED / np.linalg.norm(TURNED), 60.0)


@pytest.fixture(scope="module")
def in_level() -> InLevel:
    return InLevel(LevelInterior(room_with_slab()), np.array([[-3.0, 1.0, -3.0], [-3.0, 1.0, 3.0]]), margin_m=0.3)


def test_a_pose_inside_is_left_alone(in_level):
    pose = pose_at([-1.0, 1.0, 2.0])
    assert in_level.contained(pose, CENTRE) == (pose, False)


@pytest.mark.parametrize(
    "position, expected",
    [
        ([2.0, 2.0, 0.0], [1.2, 2.0, 0.0]),  # in the slab: 0.3 m short of its face at x = 1.5
        ([0.0, 7.0, 0.0], [0.0, 3.7, 0.0]),  # above the room: 0.3 m under its ceiling
        ([-9.0, 2.0, 0.0], [-4.7, 2.0, 0.0]),  # beside it: 0.3 m inside its wall
    ],
)
def test_a_pose_outside_or_in_solid_comes_inside_on_the_line_to_its_anchor(in_level, position, expected):
    moved, was_moved = in_level.contained(pose_at(position), CENTRE)
    assert was_moved and np.allclose(moved.position_world, expected, atol=1e-4)
    assert in_level.inside(moved.position_world)
    assert np.array_equal(moved.rotation_xyzw, pose_at(position).rotation_xyzw)


def test_a_pose_of_nobody_comes_inside_toward_the_nearest_camera_node(in_level):
    # the node (-3, 1, 3) is nearer than (-3, 1, -3); the line from it up to the pose meets the ceiling at y = 4
    moved, was_moved = in_level.contained(pose_at([-3.0, 9.0, 3.5]), None)
    direction = np.array([0.0, 8.0, 0.5]) / np.linalg.norm([0.0, 8.0, 0.5])
    along_m = 3.0 / direction[1] - 0.3
    assert was_moved and np.allclose(moved.position_world, np.array([-3.0, 1.0, 3.0]) + along_m * direction, atol=1e-4)


def test_a_move_across_the_slab_crosses_the_level_and_one_within_the_room_does_not(in_level):
    assert in_level.crossed(np.array([1.0, 2.0, 0.0]), np.array([3.0, 2.0, 0.0]))
    assert not in_level.crossed(np.array([1.0, 2.0, 0.0]), np.array([-3.0, 1.0, 2.0]))


def test_many_places_and_moves_tested_in_one_call_answer_as_each_one_alone(in_level):
    # a step back's places at one distance (step_back.py): inside the room, in the slab, above the
    # room, beyond the slab, one asked twice; and the moves to them from one centre, across the slab or not
    places = np.array([[-1.0, 1.0, 2.0], [2.0, 2.0, 0.0], [0.0, 7.0, 0.0], [3.0, 2.0, 0.0], [-1.0, 1.0, 2.0], [-3.0, 1.0, 2.0]])
    alone = InLevel(in_level.interior, in_level.nodes_world, in_level.margin_m)
    expected_inside = [alone.inside(p) for p in places]
    assert expected_inside == [True, False, False, True, True, True]
    fresh = InLevel(in_level.interior, in_level.nodes_world, in_level.margin_m)
    fresh.inside(places[2])  # one remembered before the call
    assert fresh.inside_many(places).tolist() == expected_inside
    start = np.array([1.0, 2.0, 0.0])
    expected_crossed = [alone.crossed(start, p) for p in places]
    assert expected_crossed == [False, True, True, True, False, False]  # the slab, the ceiling, the slab
    assert fresh.crossed_many(start, places).tolist() == expected_crossed
    assert fresh.crossed_many(start, np.zeros((0, 3))).tolist() == fresh.inside_many(np.zeros((0, 3))).tolist() == []


def test_a_move_through_the_slab_stays_on_the_anchors_side_or_is_left_to_a_cut(in_level):
    start = np.array([1.0, 2.0, 1.0])
    kept, was_kept = in_level.kept_this_side(start, pose_at([3.0, 2.0, 1.0]), CENTRE)  # the anchor this side of the slab
    assert was_kept and kept.position_world[0] < 1.5 and not in_level.crossed(start, kept.position_world)
    assert np.allclose(np.cross(kept.position_world - CENTRE, [3.0, 0.0, 1.0]), 0.0, atol=1e-6)  # on the anchor's line
    beyond = np.array([4.0, 2.0, 0.0])  # the anchor beyond the slab: nothing this side to stay on
    pose = pose_at([3.0, 2.0, 1.0])
    assert in_level.kept_this_side(start, pose, beyond) == (pose, False)
    assert in_level.kept_this_side(start, pose_at([-2.0, 2.0, 1.0]), CENTRE)[1] is False  # no wall crossed


def test_a_short_move_through_the_slab_holds_the_camera_turned_to_its_anchor_and_a_long_one_is_left_to_a_cut(in_level):
    start = np.array([1.2, 2.0, -3.0])
    beyond = np.array([4.0, 2.0, 0.0])  # the anchor beyond the slab: nothing this side to stay on
    position = np.array([3.0, 2.0, -3.0])
    pose = CameraPose(position, level_look_rotation(position, beyond, (0.2, 0.1), LENS), LENS.vertical_fov_deg)
    held, was_held = in_level.held(start, pose, beyond, LENS, hold_max_m=4.0)
    assert was_held and np.array_equal(held.position_world, start)
    assert np.allclose(project_to_screen(held, LENS, beyond)[0], [0.2, 0.1], atol=1e-6)  # the anchor where it was
    assert in_level.held(start, pose, beyond, LENS, hold_max_m=1.0) == (pose, False)  # 1.8 m: a new place
    assert in_level.held(start, pose_at([-1.0, 2.0, -3.0]), beyond, LENS, hold_max_m=4.0)[1] is False  # no wall


def test_a_fast_move_within_the_room_is_paced_turned_to_its_anchor_and_one_through_the_slab_is_left_to_a_cut(in_level):
    start = np.array([-4.0, 2.0, -3.0])
    position = np.array([-4.0, 2.0, 3.0])  # 6 m along the wall, nothing between
    pose = CameraPose(position, level_look_rotation(position, CENTRE, (0.2, 0.1), LENS), LENS.vertical_fov_deg)
    paced, was_paced = in_level.paced(start, pose, CENTRE, LENS, step_max_m=1.5)
    assert was_paced and np.allclose(paced.position_world, [-4.0, 2.0, -1.5], atol=1e-9)  # 1.5 m along the move
    assert np.allclose(project_to_screen(paced, LENS, CENTRE)[0], [0.2, 0.1], atol=1e-6)  # the anchor where the pose has it
    assert paced.vertical_fov_deg == pose.vertical_fov_deg and in_level.inside(paced.position_world)
    assert in_level.paced(start, pose, CENTRE, LENS, step_max_m=6.5) == (pose, False)  # slow enough: as it is
    across = pose_at([3.0, 2.0, -3.0])  # 4.2 m through the slab at x = 1.5
    assert in_level.paced(np.array([-1.2, 2.0, -3.0]), across, CENTRE, LENS, step_max_m=1.5) == (across, False)


@pytest.mark.parametrize(
    "speed_m_s, cut_s", [(0.0, 0.25), (-1.0, 0.25), (1001.0, 0.25), (math.inf, 0.25), (40.0, -0.1), (40.0, 11.0)]
)
def test_pace_settings_out_of_their_limits_are_refused(speed_m_s, cut_s):
    with pytest.raises(ValueError, match="move_speed_max_m_s|move_cut_s"):
        MatchSettings(move_speed_max_m_s=speed_m_s, move_cut_s=cut_s)


def low_hall() -> TriMesh:
    """The melee's 40 m square under a 4.5 m ceiling (faces inward) with its four pillars (solid):
    a place the style would take 6-12 m from a pair lies beyond the walls or above the ceiling."""
    hall, pillar = box((44.0, 4.5, 44.0)), box((2.0, 4.5, 2.0))
    vertices = [hall.vertices + [0.0, 2.25, 0.0]]
    faces = [hall.faces[:, ::-1]]
    for k, (x, z) in enumerate(((-6.0, -6.0), (6.0, -6.0), (-6.0, 6.0), (6.0, 6.0))):
        vertices.append(pillar.vertices + [x, 2.25, z])
        faces.append(pillar.faces + len(hall.vertices) + k * len(pillar.vertices))
    return TriMesh(np.concatenate(vertices), np.concatenate(faces).astype(np.int32))


def test_a_match_in_a_low_hall_keeps_every_program_and_candidate_camera_inside_and_cuts_through_walls():
    mesh = low_hall()
    level = LoadedLevel("hall", precompute_level(mesh, TrackSettings(), np.random.default_rng(0)), mesh)
    match = melee(seed=3, duration_s=14.0, delay_s=2.0)
    match.walls = []  # the pillars are the level's
    session = Session("s", dataclasses.replace(match.scene(), level=level))
    states = [session.frame(update) for update in match.frames(14.0)]
    shown = [s for s in states if s.pose is not None]
    program = np.array([s.pose.position_world for s in shown])
    candidates = np.array([c.pose.position_world for s in shown for c in s.match.candidates])
    interior = LevelInterior(mesh)
    assert len(shown) > 300 and len(candidates) > 300
    assert not interior.bad(program).any(), int(interior.bad(program).sum())
    assert not interior.bad(candidates).any(), int(interior.bad(candidates).sum())
    moves = [k for k in range(1, len(shown)) if not shown[k].cut]
    assert (interior.reach(program[[k - 1 for k in moves]], program[moves]) == 1.0).all()
    # and no jump a viewer sees as a cut (eval-match's): a move with no cut, but through a player's eyes (they go
    # where the player goes), at most the speed eval-match counts a jump over
    step_max_m = JUMP_SPEED_M_S * (shown[1].time_s - shown[0].time_s)
    moved_m = [np.linalg.norm(program[k] - program[k - 1]) for k in moves if not shown[k].match.shot.eyes_id]
    assert len(moved_m) > 300 and max(moved_m) <= step_max_m + 1e-6, max(moved_m)
