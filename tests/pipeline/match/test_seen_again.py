"""A program pose that a degrade left showing none of its subjects is not kept on air
(program_camera.py `_seen_again`, issue 41: frames of nobody outside overviews): a hold before a
wall that hides the subject gives way to the move it held (the rig cuts through the wall), and a
camera moved inside the level so close that its subject leaves the frame is re-placed by a cut, at
most once every `seen_again_gap_s`, and the new place, moved inside the level in its turn, is
stepped back from a player too near for the widest lens as any pose is."""

from __future__ import annotations

import math

import numpy as np

from camdirector.geometry.camera import Lens
from camdirector.geometry.inside import LevelInterior
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.transforms import quat_to_matrix
from camdirector.pipeline.match import program_camera
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.grammar import view_turn_deg
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.look_along import look_along
from camdirector.pipeline.match.program_camera import (
    CUT_TO_SEEN_PLACE,
    HOLD_LEFT_FOR_CUT,
    STEPPED_BACK,
    SUBJECTS_LOST,
    ProgramCamera,
)
from camdirector.pipeline.match.program_shot import Shot
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import Place, framed_seen
from tests.pipeline.match.test_framing_band import rig_of
from tests.pipeline.match.test_step_back import _height_at_widest, _room

PLACE = Place(0.1, math.radians(45.0), 1.0)  # a's FOLLOW place 2.4 m off, 1.2 m over its chest, on -x
DT_S = 1.0 / 30.0


def _follow_of_a(rig):
    """test_framing_band's a framed alone from PLACE at the rig's newest moment: the moment, camera and shot."""
    moment = rig.rig.buffer.moments[-1]
    camera = rig.rig.builder.cameras(ShotKind.FOLLOW, (0,), moment, default=True)[0][0]
    camera.place = camera.goal = PLACE
    return moment, camera, Shot(ShotChoice(("a",), ShotKind.FOLLOW, "test"), (0,), camera, 0.0)


def _shows_a(rig, moment, pose) -> float:
    """The share of a's sample points the pose sees in its frame (of the pose's width)."""
    lens = Lens(pose.vertical_fov_deg, rig.rig.lens.aspect)
    return float(
        framed_seen(rig.rig.visibility, moment, (0,), pose.position_world[None], quat_to_matrix(pose.rotation_xyzw[None]), lens)[
            0, 0
        ]
    )


def _room_with_wall_at(z_m: float) -> TriMesh:
    """A 30 x 8 x 70 m room round both players (faces inward) with a wall 0.5 m thick across z = z_m (solid)."""
    room, wall = box((30.0, 8.0, 70.0)), box((30.0, 8.0, 0.5))
    return TriMesh(
        np.concatenate([room.vertices + [0.0, 4.0, 15.0], wall.vertices + [0.0, 4.0, z_m]]),
        np.concatenate([room.faces[:, ::-1], wall.faces + len(room.vertices)]).astype(np.int32),
    )


def test_a_hold_behind_a_wall_that_hides_the_subject_gives_way_to_the_move_it_held():
    bare = rig_of()
    place = _follow_of_a(bare)[1].pose(bare.rig.buffer.moments[-1]).position_world
    level = _room_with_wall_at(place[2] + 1.5)  # a wall beside the camera's place, away from a
    rig = rig_of([level])
    moment, camera, shot = _follow_of_a(rig)
    in_level = InLevel(LevelInterior(level), np.zeros((0, 3)), MatchSettings().pull_margin_m)
    r = rig.rig
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    behind = place + [0.0, 0.0, 3.0]  # last frame's camera, beyond the wall: a 3 m move through it, 33 degrees round a
    last = look_along(behind, moment.aims_world[0] - behind, r.lens.vertical_fov_deg)
    assert _shows_a(rig, moment, last) == 0.0  # held there, the camera would show a wall
    pose, flags = program.step(moment, DT_S, camera, shot, 0.5, last)
    assert "held_before_wall" in flags and HOLD_LEFT_FOR_CUT in flags
    assert np.allclose(pose.position_world, place)  # the move, which the rig cuts to (a move through a wall)
    assert in_level.crossed(behind, pose.position_world)
    assert _shows_a(rig, moment, pose) >= MatchSettings().candidate_seen

    nearer = place + [0.0, 0.0, 2.0]  # 2 m: a cut there would turn a's view under 30 degrees (a jump cut)
    last = look_along(nearer, moment.aims_world[0] - nearer, r.lens.vertical_fov_deg)
    pose, flags = program.step(moment, DT_S, camera, shot, 0.5, last)
    assert "held_before_wall" in flags and HOLD_LEFT_FOR_CUT not in flags and CUT_TO_SEEN_PLACE in flags
    assert view_turn_deg(nearer, pose.position_world, moment.aims_world[0])[0] >= MatchSettings().jump_cut_deg
    assert _shows_a(rig, moment, pose) >= MatchSettings().candidate_seen


def _room_behind_a(x_m: float) -> TriMesh:
    """A 30 x 8 x 70 m room (faces inward) whose -x wall stands at x = x_m, a little behind a's back."""
    room = box((30.0, 8.0, 70.0))
    return TriMesh(room.vertices + [x_m + 15.0, 4.0, 15.0], room.faces[:, ::-1].astype(np.int32))


def _follow_before_the_wall_behind_a():
    """a's FOLLOW from PLACE, outside a room whose -x wall stands 0.4 m behind a's back: no pull-in
    comes nearer than a's readable distance (shots.py pulled_in), so the level's containment moves
    the camera in to the wall's margin, 0.16 m from a's chest, inside its body. The rig, moment,
    camera, shot, the room's ProgramCamera and the camera's pose before the step."""
    level = _room_behind_a(-0.4)
    rig = rig_of([level])
    moment, camera, shot = _follow_of_a(rig)
    in_level = InLevel(LevelInterior(level), np.zeros((0, 3)), MatchSettings().pull_margin_m)
    r = rig.rig
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    return rig, moment, camera, shot, program, camera.pose(moment)


def test_a_camera_moved_inside_so_close_that_its_subject_leaves_the_frame_is_re_placed_by_a_cut_once_a_gap():
    rig, moment, camera, shot, program, last = _follow_before_the_wall_behind_a()
    pose, flags = program.step(moment, DT_S, camera, shot, 0.5, last)
    assert flags[0] == "moved_inside_level" and CUT_TO_SEEN_PLACE in flags
    assert _shows_a(rig, moment, pose) >= MatchSettings().candidate_seen
    assert camera.reach_m is None and camera.seen_again_s == moment.time_s and camera.goal == camera.place != PLACE
    assert np.linalg.norm(pose.position_world - moment.aims_world[0]) > 1.5  # within the band, not at a's chest
    assert view_turn_deg(last.position_world, pose.position_world, moment.aims_world[0])[0] >= MatchSettings().jump_cut_deg

    camera.place = camera.goal = PLACE  # the same again within seen_again_gap_s: the degraded pose stays
    pose, flags = program.step(moment, DT_S, camera, shot, 0.5, last)
    assert flags[0] == "moved_inside_level" and CUT_TO_SEEN_PLACE not in flags
    assert _shows_a(rig, moment, pose) < MatchSettings().candidate_seen


def test_a_degraded_pose_that_shows_its_subject_is_kept():
    rig = rig_of()
    moment, camera, shot = _follow_of_a(rig)
    last = camera.pose(moment)
    camera.reach_m = 2.0  # pulled in a little: 2.07 m from a's chest, a in the frame
    pose, flags = rig.rig.program_camera.step(moment, DT_S, camera, shot, 0.5, last)
    assert flags[0] == "pulled_in_front_of_wall" and CUT_TO_SEEN_PLACE not in flags
    assert camera.place == PLACE and camera.seen_again_s is None
    assert _shows_a(rig, moment, pose) >= MatchSettings().candidate_seen


def test_a_copy_of_the_camera_that_may_not_be_re_placed_is_flagged_as_losing_its_subjects_and_left_as_it_was():
    # the edit window's copies (edit_window.py) end where they would be re-placed: no place search for them
    rig, moment, camera, shot, program, last = _follow_before_the_wall_behind_a()
    pose, flags = program.step(moment, DT_S, camera, shot, 0.5, last, re_place=False)
    assert flags[0] == "moved_inside_level" and SUBJECTS_LOST in flags and CUT_TO_SEEN_PLACE not in flags
    assert camera.seen_again_s is None and camera.place == camera.goal == PLACE  # not re-placed
    assert _shows_a(rig, moment, pose) < MatchSettings().candidate_seen


def test_a_re_placed_pose_moved_inside_near_its_player_is_stepped_back(monkeypatch):
    # a cast's re-placement cut stood 0.74 m from p01's chest at 90 degrees (p01 the whole frame's
    # height) for one frame, stepped back the next: the new place, moved inside the level, skipped
    # the step back every other pose takes
    feet = rig_of().rig.buffer.moments[-1].feet_world[0]
    room = _room(feet + [-1.1, 0.0, -20.0], feet + [20.0, 8.0, 20.0])  # its -x wall 1.1 m behind a's back
    block = box((0.3, 0.3, 0.3))  # hides a from where the camera's own place is moved inside
    level = TriMesh(
        np.concatenate([room.vertices, block.vertices + [-0.45, 1.7, 0.4]]),
        np.concatenate([room.faces, block.faces + len(room.vertices)]).astype(np.int32),
    )
    rig = rig_of([level])
    moment, camera, shot = _follow_of_a(rig)
    r = rig.rig
    in_level = InLevel(LevelInterior(room), np.zeros((0, 3)), MatchSettings().pull_margin_m)
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    beyond_the_wall = Place(0.1, math.radians(150.0), 1.0)  # low behind a, outside: moved inside 1.2 m from its chest
    # the place search isolated: it answers that place (its own choice depends on the whole level)
    monkeypatch.setattr(program_camera, "best_place", lambda *args, **kwargs: (beyond_the_wall, 1.0))
    pose, flags = program.step(moment, 0.0, camera, shot, 0.5, None)
    assert flags[:2] == ["moved_inside_level", CUT_TO_SEEN_PLACE] and camera.place == beyond_the_wall
    assert STEPPED_BACK in flags  # before: 1.23 m from a's chest, a 0.66 of the frame's height at the widest lens
    assert _height_at_widest(rig, moment, pose) <= MatchSettings().shown_height_max
    assert in_level.inside(pose.position_world)
