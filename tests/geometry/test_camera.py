"""The frame of a camera (geometry/camera.py): which points lie inside it."""
from __future__ import annotations

import numpy as np

from camdirector.geometry.camera import NEAR_PLANE_M, CameraPose, Lens, in_frame


def test_the_frustum_test_on_hand_placed_points():
    pose = CameraPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), 90.0)  # looks down -Z, tan(half fov) = 1
    lens = Lens(aspect=2.0)  # half-width 2 at depth 1
    points = np.array([
        [0.0, 0.0, -1.0],                  # centre of the frame
        [1.9, 0.9, -1.0],                  # near the top right corner, inside
        [2.1, 0.0, -1.0],                  # just right of the frame
        [0.0, 1.1, -1.0],                  # just above it
        [0.0, 0.0, 1.0],                   # behind the camera
        [0.0, 0.0, -0.5 * NEAR_PLANE_M],   # in front, but nearer than the near plane
    ])
    assert in_frame(pose, lens, points).tolist() == [True, True, False, False, False, False]


def test_the_pose_carries_the_field_of_view():
    """A point 40 deg above the view axis is out of a 50 deg frame and in a 90 deg one, whatever
    field of view the lens was made with."""
    point = np.array([[0.0, np.tan(np.radians(40.0)), -1.0]])
    narrow = CameraPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), 50.0)
    wide = CameraPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), 90.0)
    assert not in_frame(narrow, Lens(vertical_fov_deg=90.0), point)[0]
    assert in_frame(wide, Lens(vertical_fov_deg=50.0), point)[0]
