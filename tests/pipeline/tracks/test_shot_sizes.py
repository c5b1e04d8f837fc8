"""Shot sizes on screen (pipeline/tracks/shot_sizes.py): the aim centres the framed extent, the
fit ratio says whether it can be framed, and the framing error is 0 where the shot size puts it.
Property tests over cameras around an actor standing at the origin."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector.geometry.camera import CameraPose, Lens, level_look_rotation, project_to_screen
from camdirector.pipeline.style import ShotSize
from camdirector.pipeline.tracks.shot_sizes import (
    FRAMED_EXTENT,
    aim_point,
    fit_ratio,
    framed_ends_world,
    framing_error,
)

HEIGHT_M = 1.8
LENS = Lens(vertical_fov_deg=45.0)
FEET = np.zeros(3)

cameras = st.tuples(st.floats(0.0, 2.0 * math.pi), st.floats(0.8, 12.0), st.floats(0.1, 4.0))  # azimuth, distance, height


def camera_at(azimuth: float, distance_m: float, height_m: float) -> np.ndarray:
    return np.array([distance_m * math.sin(azimuth), height_m, distance_m * math.cos(azimuth)])


def aimed(camera: np.ndarray, ends: np.ndarray, radius_m: float) -> CameraPose:
    rotation = level_look_rotation(camera, aim_point(camera, ends, radius_m), (0.0, 0.0), LENS)
    return CameraPose(camera, rotation, LENS.vertical_fov_deg)


def girth_points(ends: np.ndarray, radius_m: float) -> np.ndarray:
    """(n, 3) points on a cylinder of radius_m about the actor's axis between the ends."""
    angles = np.linspace(0.0, 2.0 * math.pi, 16, endpoint=False)
    ring = radius_m * np.stack([np.cos(angles), np.zeros_like(angles), np.sin(angles)], axis=1)
    heights = np.linspace(ends[0, 1], ends[1, 1], 9)
    return np.concatenate([ring + [ends[0, 0], h, ends[0, 2]] for h in heights])


@settings(max_examples=200, deadline=None)
@given(cameras, st.sampled_from(list(ShotSize)))
def test_the_aim_centres_the_axis_of_the_framed_extent(camera, size):
    ends = framed_ends_world(FEET, HEIGHT_M, size)
    screen = project_to_screen(aimed(camera_at(*camera), ends, 0.0), LENS, ends)
    np.testing.assert_allclose(screen[:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(screen[0, 1], -screen[1, 1], atol=1e-9)
    assert screen[0, 1] < 0.0


@settings(max_examples=300, deadline=None)
@given(cameras, st.sampled_from(list(ShotSize)), st.floats(0.0, 0.4))
def test_what_fits_is_inside_the_frame_once_aimed_and_what_does_not_fit_leaves_it(camera, size, radius_m):
    position = camera_at(*camera)
    ends = framed_ends_world(FEET, HEIGHT_M, size)
    points = girth_points(ends, radius_m)
    screen = project_to_screen(aimed(position, ends, radius_m), LENS, points)
    ratio = fit_ratio(position[None], ends, radius_m, LENS.vertical_fov_deg, 0.0)[0]
    if np.hypot(position[0], position[2]) <= radius_m + 0.05:
        return  # inside the actor's girth: nothing to frame
    if ratio <= 1.0:
        assert np.all(np.abs(screen[:, 1]) <= 1.0 + 1e-9)
    if ratio > 1.0 + 1e-6 and radius_m == 0.0:
        assert np.nanmax(np.abs(screen[:, 1])) > 1.0


def test_a_frame_margin_asks_for_room():
    position = camera_at(0.3, 3.0, 1.6)
    ends = framed_ends_world(FEET, HEIGHT_M, ShotSize.LONG)
    tight, roomy = (fit_ratio(position[None], ends, 0.25, LENS.vertical_fov_deg, m)[0] for m in (0.0, 0.1))
    assert roomy == tight / 0.9


def test_the_issues_camera_crops_the_feet_and_the_aim_keeps_them():
    # the issue's report: about 2 m from the actor at eye height, 45 degrees, looking at
    # a fixed point 0.6 up the actor: the feet fall under the frame
    ends = framed_ends_world(FEET, HEIGHT_M, ShotSize.LONG)
    for distance_m in (2.0, 2.1):
        position = camera_at(1.0, distance_m, 1.62)
        fixed = CameraPose(
            position, level_look_rotation(position, [0.0, 0.6 * HEIGHT_M, 0.0], (0.0, 0.0), LENS), LENS.vertical_fov_deg
        )
        assert project_to_screen(fixed, LENS, ends)[0, 1] < -1.0
        assert fit_ratio(position[None], ends, 0.0, LENS.vertical_fov_deg, 0.0)[0] <= 1.0
        assert np.all(np.abs(project_to_screen(aimed(position, ends, 0.0), LENS, ends)[:, 1]) <= 1.0)


def test_the_framing_error_is_zero_where_the_shot_size_puts_the_extent():
    for size, screen_fraction in ((ShotSize.LONG, 0.8), (ShotSize.MEDIUM, 1.6), (ShotSize.EXTREME_LONG, 0.25)):
        low, high = FRAMED_EXTENT[size]
        half = screen_fraction * (high - low)
        # level with the extent's middle, at the distance where half the extent spans `half` of the half-height
        distance_m = 0.5 * (high - low) * HEIGHT_M / (half * LENS.tan_half_fov_y)
        position = np.array([distance_m, 0.5 * (low + high) * HEIGHT_M, 0.0])
        ends = framed_ends_world(FEET, HEIGHT_M, size)
        pose = aimed(position, ends, 0.0)
        assert framing_error(pose, LENS, FEET, HEIGHT_M, size, screen_fraction) < 1e-9
        closer = aimed(position * [0.8, 1.0, 1.0], ends, 0.0)
        # 0.8 times as far: the extent 1 / 0.8 times as tall, each end off by the difference
        assert abs(framing_error(closer, LENS, FEET, HEIGHT_M, size, screen_fraction) - (half / 0.8 - half)) < 1e-9


def test_the_framing_error_is_nan_behind_the_camera():
    position = np.array([3.0, 1.0, 0.0])
    away = CameraPose(position, level_look_rotation(position, [6.0, 1.0, 0.0], (0.0, 0.0), LENS), LENS.vertical_fov_deg)
    assert math.isnan(framing_error(away, LENS, FEET, HEIGHT_M, ShotSize.LONG, 0.8))
