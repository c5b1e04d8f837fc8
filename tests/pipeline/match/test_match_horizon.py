"""The MATCH rig keeps the horizon level: every program pose has no roll, the place search judges
the level picture that is shown, and at the style's composition every place of the grid frames a
level pair."""

from __future__ import annotations

import math
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector.geometry.camera import CameraPose, project_from_cameras, project_to_screen
from camdirector.geometry.transforms import RigidTransform, quat_to_matrix
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.moments import MomentBuffer
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import MIN_CAMERA_HEIGHT_M, PLACE_WIDTHS, Place, ToricCamera, framed_seen, place_grid
from camdirector.pipeline.style import Rig, Style
from tests.pipeline.match.scenes import LENS, melee, run_session, yaw_quat


def moment_of(points_xz: list[tuple[float, float]], heights_m: list[float] | None = None):
    """A buffered moment of players standing at points_xz (their feet at heights_m), aims 1.6 m up."""
    heights_m = heights_m or [0.0] * len(points_xz)
    transforms = [RigidTransform(np.array([x, h, z]), yaw_quat(0.0)) for (x, z), h in zip(points_xz, heights_m)]
    buffer = MomentBuffer([f"p{i}" for i in range(len(points_xz))], MatchSettings())
    buffer.push(0, 0.0, transforms, [t.apply(np.array([[0.0, 1.6, 0.0]]))[0] for t in transforms], [])
    return buffer.newest


@pytest.mark.parametrize("delay_s", [0.0, 10.0])
def test_every_program_pose_of_a_melee_has_a_level_horizon(delay_s):
    match = melee(seed=3, duration_s=40.0 + delay_s, delay_s=delay_s)
    _, states = run_session(match, 40.0 + delay_s)
    shown = [s for s in states if not s.match.buffering]
    kinds = {s.match.shot.kind for s in shown}
    assert ShotKind.DUEL in kinds or ShotKind.GROUP in kinds  # the two-point cameras are on air
    rotations = quat_to_matrix(np.stack([s.pose.rotation_xyzw for s in shown]))
    assert np.abs(rotations[:, 1, 0]).max() < 1e-9  # the camera's right axis is horizontal
    assert rotations[:, 1, 1].min() > 0.0  # and its up axis points up


@pytest.mark.parametrize("kind", [ShotKind.DUEL, ShotKind.GROUP, ShotKind.FOLLOW])
def test_the_place_search_judges_the_picture_that_is_shown(kind):
    moment = moment_of([(0.0, 0.0), (6.0, 3.0)], [0.0, 0.8])
    camera = ToricCamera(
        kind, 0, None if kind == ShotKind.FOLLOW else 1, Style(rig=Rig.MATCH), LENS, Place(0.5, math.radians(70.0))
    )
    places = place_grid(1.0)
    positions = camera.positions(moment, places)
    many = camera.rotations(moment, positions, places)
    assert np.abs(many[:, 1, 0]).max() < 1e-9
    for place, position, matrix in zip(places[::7], positions[::7], many[::7]):
        np.testing.assert_allclose(
            quat_to_matrix(camera.pose_from(moment, position, place.width).rotation_xyzw), matrix, atol=1e-9
        )


@settings(max_examples=30, derandomize=True, deadline=None, database=None)
@given(st.floats(2.0, 15.0), st.floats(-math.pi, math.pi), st.floats(-1.0, 1.0))
def test_at_the_styles_composition_every_place_frames_a_level_pair(distance_m, heading, rise_m):
    # the style's screen points 2/3 of the frame apart, their rays 31 degrees apart, fit the 50
    # degree frame turned any way: the level camera frames the pair from every place of the grid,
    # over a shoulder from above too (the pair one above the other); the wider compositions
    # cannot there, and the search's frame test (framed_seen) drops those places
    moment = moment_of([(0.0, 0.0), (distance_m * math.cos(heading), distance_m * math.sin(heading))], [0.0, rise_m])
    camera = ToricCamera(ShotKind.DUEL, 0, 1, Style(rig=Rig.MATCH), LENS, Place(0.5, math.radians(70.0)))
    places = [p for p in place_grid(1.0) if p.width == PLACE_WIDTHS[0]]
    positions = camera.positions(moment, places)
    aims = moment.aims_world[[0, 1]]
    for place, position in zip(places, positions):
        pose = camera.pose_from(moment, position, place.width)
        screen = project_to_screen(CameraPose(position, pose.rotation_xyzw, LENS.vertical_fov_deg), LENS, aims)
        assert np.all(np.abs(screen) <= 1.0), place
        assert screen[0, 0] < screen[1, 0], place  # A stays screen-left: the line of action holds


def test_the_search_ray_casts_only_the_points_inside_each_frame_and_judges_as_casting_all_would():
    """framed_seen: a sample point is seen when it is inside the frame, not from under the
    subjects' ground, and unoccluded; casting only the points inside the frames gives the same
    shares as casting every one and keeping the inside ones (a melee on its walled field)."""
    session, _ = run_session(melee(seed=3, duration_s=20.0, delay_s=0.0), 15.0)
    rig = session.rig
    moment = rig.buffer.newest
    camera = ToricCamera(ShotKind.DUEL, 0, 5, Style(rig=Rig.MATCH), LENS, Place(0.5, math.radians(70.0)))
    places = place_grid(None)
    positions = camera.positions(moment, places)
    rotations = camera.rotations(moment, positions, places)
    subjects = (0, 5)
    scene = rig.visibility.ray_scene
    with mock.patch.object(scene, "occluded", wraps=scene.occluded) as cast:
        judged = framed_seen(rig.visibility, moment, subjects, positions, rotations, LENS)
    rays = sum(len(c.args[1]) for c in cast.call_args_list)
    every = rig.visibility.seen_points(positions, moment, subjects)  # (m, 2, k)
    screen = project_from_cameras(positions, rotations, LENS, rig.visibility.points_world(moment, subjects))
    with np.errstate(invalid="ignore"):
        inside = (np.abs(screen) <= 1.0).all(axis=2).reshape(every.shape)
    above = positions[:, 1] >= moment.feet_world[list(subjects), 1].min() + MIN_CAMERA_HEIGHT_M
    expected = (every & inside & above[:, None, None]).mean(axis=2)
    assert 0.0 < expected.mean() < 1.0 and (~every).any()  # some points are hidden by walls, some outside
    np.testing.assert_array_equal(judged, expected)
    assert rays == int((inside & above[:, None, None]).sum()) < inside.size


@pytest.mark.parametrize("kind", [ShotKind.DUEL, ShotKind.FOLLOW])
def test_a_place_that_rides_under_its_players_ground_is_raised_to_the_searchs_lowest_camera(kind):
    # the search never chooses a place under the ground; a place chosen beside a pair rides under
    # it once the pair's axis tilts (b 2.5 m up a stair): the pose stands MIN_CAMERA_HEIGHT_M over
    # the lower feet, straight above the torus's point, and still frames what it frames
    camera = ToricCamera(
        kind, 0, None if kind == ShotKind.FOLLOW else 1, Style(rig=Rig.MATCH), LENS, Place(0.5, math.radians(125.0))
    )
    level = moment_of([(0.0, 0.0), (0.0, 8.0)])
    raw = camera.positions(level, [camera.place])[0]
    assert raw[1] < MIN_CAMERA_HEIGHT_M  # so the test can fail: phi past 90 degrees is below the axis
    pose = camera.pose(level)
    np.testing.assert_array_equal(pose.position_world, [raw[0], MIN_CAMERA_HEIGHT_M, raw[2]])
    framed = level.aims_world[[0] if kind == ShotKind.FOLLOW else [0, 1]]
    assert np.all(np.abs(project_to_screen(pose, LENS, framed)) <= 1.0)
    high = ToricCamera(
        kind, 0, None if kind == ShotKind.FOLLOW else 1, Style(rig=Rig.MATCH), LENS, Place(0.5, math.radians(70.0))
    )
    np.testing.assert_array_equal(high.pose(level).position_world, high.positions(level, [high.place])[0])
    if kind == ShotKind.DUEL:  # the lower of the pair's feet is the ground
        tilted = moment_of([(0.0, 0.0), (0.0, 8.0)], [-1.0, 1.5])
        assert camera.pose(tilted).position_world[1] >= -1.0 + MIN_CAMERA_HEIGHT_M - 1e-12
