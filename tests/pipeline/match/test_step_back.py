"""The program camera stepped back from a player too near for the widest lens (step_back.py): in
the open it dollies back along its own line to the nearest step that fits the band, before a wall
it steps aside instead and never through the wall, with no room to step it pans off the player
where it stands, a far player or a view through a player's eyes
moves nothing, and the program camera's step carries it with its flag."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.inside import LevelInterior
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.transforms import matrix_to_quat, quat_to_matrix
from camdirector.pipeline.match.first_person import EYE_HEIGHT_FRACTION, FirstPersonCamera
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.lens_width import EYES_RADIUS_M, SHOWN_SEEN, silhouette_points
from camdirector.pipeline.match.look_along import look_along
from camdirector.pipeline.match.program_camera import PANNED_OFF, STEPPED_BACK, ProgramCamera
from camdirector.pipeline.match.program_shot import Shot
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import StaticCamera, poses_seen
from camdirector.pipeline.match.step_back import AWAY_SEEN, AWAY_TILTS_DEG, AWAY_TURNS_DEG, BACK_STEPS_M, stepped_back
from tests.pipeline.match.test_framing_band import rig_of

SETTINGS = MatchSettings()
WIDEST = Lens(vertical_fov_deg=SETTINGS.widen_max_fov_deg)


def _room(low, high) -> TriMesh:
    """A room (faces inward) from corner low (3,) to corner high (3,), m."""
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    room = box(tuple(high - low))
    return TriMesh(room.vertices + (low + high) / 2.0, room.faces[:, ::-1].astype(np.int32))


def _setup(distance_m: float, behind_m: float = 20.0, side_m: float = 20.0):
    """a of test_framing_band's rig in a room whose +x wall stands behind_m behind a camera
    distance_m in front of a (along +x, at its chest's height) looking at it, its side walls side_m
    either side of it: the rig, its newest moment, the room's InLevel and the pose."""
    feet = rig_of().rig.buffer.moments[-1].feet_world[0]
    wall_x = feet[0] + distance_m + behind_m
    level = _room([wall_x - 40.0, feet[1], feet[2] - side_m], [wall_x, feet[1] + 8.0, feet[2] + side_m])
    rig = rig_of([level])
    moment = rig.rig.buffer.moments[-1]
    chest = moment.feet_world[0] + [0.0, 1.0, 0.0]
    camera = chest + [distance_m, 0.0, 0.0]
    pose = look_along(camera, chest - camera, SETTINGS.widen_max_fov_deg)
    return rig, moment, InLevel(LevelInterior(level), np.zeros((0, 3)), SETTINGS.pull_margin_m), pose


def _height_at_widest(rig, moment, pose: CameraPose) -> float:
    points = silhouette_points(moment, rig.rig.program_camera.subject_visibility)[0]  # its outline and rims
    y = np.clip(project_to_screen(pose, WIDEST, points)[:, 1], -1.0, 1.0)
    return float((y.max() - y.min()) / 2.0)


def _stepped(rig, moment, in_level, pose, subjects=(0,)):
    visibility = rig.rig.program_camera.subject_visibility
    stepped = stepped_back(pose, moment, visibility, Lens(), SETTINGS, in_level, subjects)
    return None if stepped is None else stepped[0]


def test_in_the_open_the_camera_dollies_back_to_the_nearest_step_that_fits_the_band():
    rig, moment, in_level, pose = _setup(1.0)
    assert _height_at_widest(rig, moment, pose) > SETTINGS.shown_height_max  # too near for any lens
    visibility = rig.rig.program_camera.subject_visibility
    assert stepped_back(pose, moment, visibility, Lens(), SETTINGS, in_level, (0,))[1] is False  # a step, not a pan
    stepped = _stepped(rig, moment, in_level, pose)
    assert stepped is not None and np.allclose(stepped.rotation_xyzw, pose.rotation_xyzw)
    moved = stepped.position_world - pose.position_world
    assert moved[0] > 0.0 and np.allclose(moved[1:], 0.0)  # straight back along its own line
    assert _height_at_widest(rig, moment, stepped) <= SETTINGS.shown_height_max
    one_less = CameraPose(stepped.position_world - [BACK_STEPS_M[0], 0.0, 0.0], pose.rotation_xyzw, pose.vertical_fov_deg)
    assert _height_at_widest(rig, moment, one_less) > SETTINGS.shown_height_max  # the nearest step that fits


def test_before_a_wall_the_camera_steps_aside_panning_to_keep_its_subject_and_never_through_the_wall():
    rig, moment, in_level, pose = _setup(1.0, behind_m=0.5)
    stepped = _stepped(rig, moment, in_level, pose)
    assert stepped is not None
    assert in_level.inside(stepped.position_world) and not in_level.crossed(pose.position_world, stepped.position_world)
    assert stepped.position_world[0] <= pose.position_world[0] + 0.5 - SETTINGS.pull_margin_m  # short of the wall
    assert abs(stepped.position_world[2] - pose.position_world[2]) >= 1.0  # aside
    assert _height_at_widest(rig, moment, stepped) <= SETTINGS.shown_height_max
    chest = moment.feet_world[0] + [0.0, 1.0, 0.0]
    before, after = (project_to_screen(p, WIDEST, chest[None])[0] for p in (pose, stepped))
    assert after == pytest.approx(before, abs=0.05)  # panned: a where it was in the frame
    # a player the shot does not frame is not panned after: aside it would stand as near in depth, so the wall stops
    # the step, and the camera pans off it where it stands
    unframed = _stepped(rig, moment, in_level, pose, subjects=())
    assert unframed is not None and np.array_equal(unframed.position_world, pose.position_world)


def _seen_at_widest(rig, moment, pose: CameraPose) -> float:
    return float(poses_seen(rig.rig.program_camera.subject_visibility, moment, (0,), [pose], WIDEST)[0, 0])


def _panned_by(pose: CameraPose, turn_deg: float) -> CameraPose:
    """The pose turned about the vertical by turn_deg, deg."""
    turned = Rotation.from_euler("y", turn_deg, degrees=True).as_matrix() @ quat_to_matrix(pose.rotation_xyzw)
    return CameraPose(pose.position_world, matrix_to_quat(turned), pose.vertical_fov_deg)


def test_a_camera_with_no_room_to_step_pans_off_the_player_where_it_stands_the_least_it_must():
    rig, moment, in_level, pose = _setup(1.0, behind_m=0.2, side_m=0.3)  # a closet 0.6 m wide open toward a
    assert _height_at_widest(rig, moment, pose) > SETTINGS.shown_height_max
    assert _seen_at_widest(rig, moment, pose) >= SHOWN_SEEN
    stepped = stepped_back(pose, moment, rig.rig.program_camera.subject_visibility, Lens(), SETTINGS, in_level, (0,))
    assert stepped is not None and stepped[1]  # panned, not stepped
    panned = stepped[0]
    assert np.array_equal(panned.position_world, pose.position_world)
    assert panned.vertical_fov_deg == WIDEST.vertical_fov_deg
    assert _seen_at_widest(rig, moment, panned) < AWAY_SEEN
    ahead, after = (quat_to_matrix(p.rotation_xyzw)[:, 2] for p in (pose, panned))
    assert ahead[1] == pytest.approx(after[1])  # a pan: the tilt kept
    turn_deg = float(np.degrees(np.arctan2(np.cross(ahead, after)[1], ahead @ after)))
    assert abs(turn_deg) in AWAY_TURNS_DEG
    less = _panned_by(pose, turn_deg - np.sign(turn_deg) * (AWAY_TURNS_DEG[1] - AWAY_TURNS_DEG[0]))
    assert _seen_at_widest(rig, moment, CameraPose(less.position_world, less.rotation_xyzw, WIDEST.vertical_fov_deg)) >= AWAY_SEEN


def test_a_camera_looking_down_on_a_player_below_it_with_no_room_to_step_tilts_off_it():
    """2.2 m above a's feet in a shaft 0.6 m wide, looking down on a's chest: no step leaves the
    shaft, and a pan about the vertical keeps a in the 90-degree frame, so the camera tilts off
    a where it stands, the least it must, upright, its bearing kept."""
    rig, moment, in_level, _ = _setup(0.3, behind_m=0.2, side_m=0.3)
    above = moment.feet_world[0] + [0.3, 2.2, 0.0]
    pose = look_along(above, moment.feet_world[0] + [0.0, 1.0, 0.0] - above, SETTINGS.widen_max_fov_deg)
    assert _height_at_widest(rig, moment, pose) > SETTINGS.shown_height_max
    assert all(_seen_at_widest(rig, moment, _panned_by(pose, turn)) >= AWAY_SEEN for turn in (-180.0, -90.0, 90.0, 180.0))
    stepped = stepped_back(pose, moment, rig.rig.program_camera.subject_visibility, Lens(), SETTINGS, in_level, (0,))
    assert stepped is not None and stepped[1]  # turned where it stands, not stepped
    tilted = stepped[0]
    assert np.array_equal(tilted.position_world, pose.position_world)
    assert _seen_at_widest(rig, moment, tilted) < AWAY_SEEN
    before, after = quat_to_matrix(pose.rotation_xyzw), quat_to_matrix(tilted.rotation_xyzw)
    assert after[1, 1] > 0.0 and after[:, 0] == pytest.approx(before[:, 0])  # upright, about its own right axis
    tilt_deg = float(np.degrees(np.arcsin(-after[1, 2]) - np.arcsin(-before[1, 2])))
    assert round(abs(tilt_deg)) in AWAY_TILTS_DEG
    step_deg = AWAY_TILTS_DEG[1] - AWAY_TILTS_DEG[0]
    less = Rotation.from_rotvec(np.radians(tilt_deg - np.sign(tilt_deg) * step_deg) * before[:, 0]).as_matrix() @ before
    less_pose = CameraPose(pose.position_world, matrix_to_quat(less), WIDEST.vertical_fov_deg)
    assert _seen_at_widest(rig, moment, less_pose) >= AWAY_SEEN


@pytest.mark.parametrize("distance_m", [3.0, 6.0])
def test_a_player_far_enough_moves_nothing(distance_m):
    rig, moment, in_level, pose = _setup(distance_m)
    assert _stepped(rig, moment, in_level, pose) is None


def test_a_view_through_a_players_eyes_moves_nothing():
    rig, moment, in_level, _ = _setup(1.0)
    eye = moment.feet_world[0] + [0.0, 1.6, 0.0]
    in_eyes = look_along(eye, moment.feet_world[1] + [0.0, 1.6, 0.0] - eye, SETTINGS.widen_max_fov_deg)
    assert _stepped(rig, moment, in_level, in_eyes) is None


def test_a_camera_in_a_players_head_short_of_its_eye_point_steps_back():
    """A Toric camera moved 0.49 m from a's eye point (inside its head, short of the eye radius by
    less than EYES_MARGIN_M: eval-match, reading the feet the program file rounds, can put it
    outside and measure a at the frame's full height), looking down at a's chest, is no view through
    a's eyes: it steps back until a fits the band."""
    rig, moment, in_level, _ = _setup(1.0)
    points = silhouette_points(moment, rig.rig.program_camera.subject_visibility)
    eye = moment.feet_world[0] + [0.0, EYE_HEIGHT_FRACTION * (points[0, :, 1].max() - moment.feet_world[0, 1]), 0.0]
    beside = eye + [0.0, 0.0, EYES_RADIUS_M - 0.01]
    chest = moment.feet_world[0] + [0.0, 1.0, 0.0]
    pose = look_along(beside, chest - beside, SETTINGS.widen_max_fov_deg)
    stepped = _stepped(rig, moment, in_level, pose, subjects=())
    assert stepped is not None and np.linalg.norm(stepped.position_world - eye) > EYES_RADIUS_M
    assert _height_at_widest(rig, moment, stepped) <= SETTINGS.shown_height_max


def test_the_program_cameras_step_carries_the_step_and_its_flag():
    rig, moment, in_level, pose = _setup(1.0)
    r = rig.rig
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    overview = Shot(ShotChoice(("a",), ShotKind.OVERVIEW, "test"), (0,), StaticCamera(pose), 0.0)
    shown, flags = program.step(moment, 0.0, overview.camera, overview, 0.0, None)
    assert STEPPED_BACK in flags and shown.position_world[0] > pose.position_world[0]
    assert SETTINGS.shown_height_max >= _height_at_widest(rig, moment, shown)
    assert shown.vertical_fov_deg <= SETTINGS.widen_max_fov_deg
    _, _, _, far = _setup(6.0)
    away = Shot(ShotChoice(("a",), ShotKind.OVERVIEW, "test"), (0,), StaticCamera(far), 0.0)
    assert STEPPED_BACK not in program.step(moment, 0.0, away.camera, away, 0.0, None)[1]


def test_a_pose_answered_at_another_moment_steps_back_where_it_is_answered():
    """A pose made for another moment (an edit window's hold, a pose held from the frame before) is
    checked where it is answered: past the widest lens it steps back as the program camera's step
    does, with the flag; a player far enough leaves it as it is."""
    rig, moment, in_level, pose = _setup(1.0)
    r = rig.rig
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    held = CameraPose(pose.position_world, pose.rotation_xyzw, r.lens.vertical_fov_deg)
    shot = Shot(ShotChoice(("a",), ShotKind.OVERVIEW, "test"), (0,), StaticCamera(held), 0.0)
    flags: list[str] = []
    answered = program.widened_for_answer(moment, held, None, 0.0, shot, flags)
    assert flags == [STEPPED_BACK] and answered.position_world[0] > pose.position_world[0]
    assert _height_at_widest(rig, moment, answered) <= SETTINGS.shown_height_max
    _, _, _, far = _setup(6.0)
    flags = []
    program.widened_for_answer(moment, far, None, 0.0, shot, flags)
    assert flags == []


def test_a_first_person_pose_held_away_from_the_eye_steps_back_and_a_view_through_the_eyes_does_not():
    """b's eyes camera with its pose held 1 m before a (the eye out of the level a moment before,
    or an edit window's hold) is a camera like any other where it is answered; b's view from its
    eye at the moment is the game's own picture, left as it is."""
    rig, moment, in_level, pose = _setup(1.0)
    r = rig.rig
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    eyes = FirstPersonCamera(1, r.lens)
    shot = Shot(ShotChoice(("b",), ShotKind.FOLLOW, "test", eyes_id="b"), (1,), eyes, 0.0)
    held = CameraPose(pose.position_world, pose.rotation_xyzw, r.lens.vertical_fov_deg)
    flags: list[str] = []
    answered = program.widened_for_answer(moment, held, None, 0.0, shot, flags)
    assert flags == [STEPPED_BACK] and _height_at_widest(rig, moment, answered) <= SETTINGS.shown_height_max
    flags = []
    own = eyes.pose(moment)
    assert program.widened_for_answer(moment, own, None, 0.0, shot, flags) is own and flags == []


def test_the_program_cameras_pan_off_a_player_is_flagged_as_a_pan():
    """In the closet the program camera's step pans off a, its shot's lone subject, where it
    stands, and flags the pan (which program_camera.py's `_seen_again` leaves uncut)."""
    rig, moment, in_level, pose = _setup(1.0, behind_m=0.2, side_m=0.3)
    r = rig.rig
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    fixed = Shot(ShotChoice(("a",), ShotKind.OVERVIEW, "test"), (0,), StaticCamera(pose), 0.0)
    shown, flags = program.step(moment, 0.0, fixed.camera, fixed, 0.0, None)
    assert PANNED_OFF in flags and STEPPED_BACK not in flags
    assert np.array_equal(shown.position_world, pose.position_world)
    assert _seen_at_widest(rig, moment, shown) < AWAY_SEEN
