"""The frame of a camera (geometry/camera.py): which points lie inside it, and where a few points
project (the scalar path) against many (the array path) and from many cameras at once."""

from __future__ import annotations

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from camdirector.geometry.camera import (
    NEAR_PLANE_M,
    CameraPose,
    Lens,
    in_frame,
    level_look_matrices,
    level_look_rotation,
    project_from_cameras,
    project_to_screen,
)
from camdirector.geometry.transforms import quat_to_matrix


def test_the_frustum_test_on_hand_placed_points():
    pose = CameraPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), 90.0)  # looks down -Z, tan(half fov) = 1
    lens = Lens(aspect=2.0)  # half-width 2 at depth 1
    points = np.array(
        [
            [0.0, 0.0, -1.0],  # centre of the frame
            [1.9, 0.9, -1.0],  # near the top right corner, inside
            [2.1, 0.0, -1.0],  # just right of the frame
            [0.0, 1.1, -1.0],  # just above it
            [0.0, 0.0, 1.0],  # behind the camera
            [0.0, 0.0, -0.5 * NEAR_PLANE_M],  # in front, but nearer than the near plane
        ]
    )
    assert in_frame(pose, lens, points).tolist() == [True, True, False, False, False, False]


def test_the_pose_carries_the_field_of_view():
    """A point 40 deg above the view axis is out of a 50 deg frame and in a 90 deg one, whatever
    field of view the lens was made with."""
    point = np.array([[0.0, np.tan(np.radians(40.0)), -1.0]])
    narrow = CameraPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), 50.0)
    wide = CameraPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), 90.0)
    assert not in_frame(narrow, Lens(vertical_fov_deg=90.0), point)[0]
    assert in_frame(wide, Lens(vertical_fov_deg=50.0), point)[0]


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1),
    st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3),
    st.lists(st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3), min_size=1, max_size=4),
)
def test_a_few_points_project_in_scalars_as_many_do_in_arrays(q, camera, points):
    pose = CameraPose(np.array(camera), np.array(q) / np.linalg.norm(q), 50.0)
    few = np.array(points, dtype=np.float64)
    depth_m = (few - pose.position_world) @ quat_to_matrix(pose.rotation_xyzw)[:, 2]
    assume(np.all(np.abs(depth_m) > 1e-6))  # on the camera's plane the two summation orders round apart
    many = np.vstack([few] * 5)  # past the few-point path: the array one
    np.testing.assert_allclose(
        project_to_screen(pose, Lens(), few), project_to_screen(pose, Lens(), many)[: len(few)], rtol=1e-9, atol=1e-9
    )


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1),
            st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3),
        ),
        min_size=1,
        max_size=4,
    ),
    st.lists(st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3), min_size=5, max_size=8),
)
def test_many_cameras_project_as_each_one_does(cameras, points):
    poses = [CameraPose(np.array(c), np.array(q) / np.linalg.norm(q), 50.0) for q, c in cameras]
    world = np.array(points, dtype=np.float64)
    for pose in poses:
        depth_m = (world - pose.position_world) @ quat_to_matrix(pose.rotation_xyzw)[:, 2]
        assume(np.all(np.abs(depth_m) > 1e-6))  # on the camera's plane the two summation orders round apart
    at_once = project_from_cameras(
        np.stack([p.position_world for p in poses]), quat_to_matrix(np.stack([p.rotation_xyzw for p in poses])), Lens(), world
    )
    for pose, screen in zip(poses, at_once):
        np.testing.assert_allclose(screen, project_to_screen(pose, Lens(), world), rtol=1e-9, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3), min_size=1, max_size=6),
    st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3),
    st.tuples(st.floats(-0.9, 0.9), st.floats(-0.9, 0.9)),
)
def test_many_level_look_rotations_at_once_are_each_ones(cameras, point, screen_xy):
    """level_look_matrices (a place search's batch) is level_look_rotation camera by camera."""
    cameras_world, point_world = np.array(cameras, dtype=np.float64), np.array(point, dtype=np.float64)
    assume(np.all(np.linalg.norm(cameras_world - point_world, axis=1) > 1e-3))
    at_once = level_look_matrices(cameras_world, point_world, screen_xy, Lens())
    for camera, rotation in zip(cameras_world, at_once):
        np.testing.assert_allclose(
            rotation, quat_to_matrix(level_look_rotation(camera, point_world, screen_xy, Lens())), atol=1e-9
        )
