"""Shot sizes on screen (Section 6.1): what each shot size must show of the actor.

How we read Section 6.1: a shot size is the actor's expected on-screen height, its height over
the frame's (`DirectorSettings.*_screen_fraction`): medium 1.4 (the whole body would be 1.4 frames
tall, so from the waist up, half the body, fills 0.7 of the frame), long 0.8 ("the whole body
fills most of the frame"), extreme long 0.25 (the actor small in the set). What a shot size must
keep inside the frame is its framed extent, a span up the actor from its feet, in fractions of its
height: the whole body (0 to 1) for long and extreme long, the waist up (0.5 to 1) for medium.

The paper orients the camera "in the direction of the actor" (Section 5.4) and sizes the shot by
distance alone (5.2: the optimal distance from the field of view and the expected on-screen
height), which holds for a camera level with the actor's centre. Tracks sit at eye height and
close to the actor in corridors, and a camera that looks down at a fixed point up the actor puts
its feet under the frame. So the camera aims at the extent: with no roll, a point straight ahead
in yaw at pitch p lands at screen y = tan(p - c) / tan(fov / 2) for a camera pitched c, and the
pitch halfway between the pitches to the extent's two ends centres it (`aim_point`). Centred, the
extent fits when half its angular span is within the half field of view less `frame_margin`
(`fit_ratio` <= 1): nearer than that no aim shows it, and the director treats the place as a
framing violation and scores it down (director.py).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.transforms import UP_WORLD
from camdirector.pipeline.style import ShotSize

# (low, high) fractions of the actor's height, from its feet, that the shot size keeps in frame
FRAMED_EXTENT = {ShotSize.MEDIUM: (0.5, 1.0), ShotSize.LONG: (0.0, 1.0), ShotSize.EXTREME_LONG: (0.0, 1.0)}


def framed_ends_world(feet_world: npt.NDArray[np.float64], height_m: float, shot_size: ShotSize) -> npt.NDArray[np.float64]:
    """(2, 3) the bottom and top of the shot size's framed extent on the actor's vertical axis, m.
    feet_world (3,): the actor's feet."""
    low, high = FRAMED_EXTENT[shot_size]
    return np.asarray(feet_world, dtype=np.float64) + np.outer([low * height_m, high * height_m], UP_WORLD)


def framing_error(
    pose: CameraPose,
    lens: Lens,
    feet_world: npt.NDArray[np.float64],
    height_m: float,
    shot_size: ShotSize,
    screen_fraction: float,
) -> float:
    """How far the framed extent's ends land from where the shot size puts them, in normalised
    screen units (the frame is [-1, 1]; the Toric rig's framing error is in the same units): the
    ends belong centred at (0, -h) and (0, h), h = screen_fraction * (high - low), the half of the
    extent's share of the frame height; the larger of the two ends' largest axis error. NaN when
    an end is behind the camera."""
    low, high = FRAMED_EXTENT[shot_size]
    half = screen_fraction * (high - low)
    screen = project_to_screen(pose, lens, framed_ends_world(feet_world, height_m, shot_size))  # (2, 2)
    return float(np.abs(screen - np.array([[0.0, -half], [0.0, half]])).max())


def _pitches(
    cameras_world: npt.NDArray[np.float64], ends_world: npt.NDArray[np.float64], radius_m: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Per camera (m, 3): the lowest pitch to the extent's bottom and the highest to its top,
    rad, over the actor's girth (its axis distance less and plus radius_m: the near side of the
    feet is lower on screen than the axis), and the horizontal distance to its axis, m."""
    cameras = np.atleast_2d(cameras_world)
    offset = ends_world[0] - cameras
    horizontal = np.hypot(offset[:, 0], offset[:, 2])
    near = np.maximum(horizontal - radius_m, 1e-6)[:, None]
    far = (horizontal + radius_m)[:, None]
    rise = ends_world[:, 1][None, :] - cameras[:, 1:2]  # (m, 2): up to the bottom and the top
    from_near, from_far = np.arctan2(rise, near), np.arctan2(rise, far)
    return np.minimum(from_near, from_far)[:, 0], np.maximum(from_near, from_far)[:, 1], horizontal


def aim_point(
    camera_world: npt.NDArray[np.float64], ends_world: npt.NDArray[np.float64], radius_m: float
) -> npt.NDArray[np.float64]:
    """(3,) the point on the actor's axis to put at the screen centre so that the framed extent
    (ends_world (2, 3): bottom, top; an actor radius_m wide) is centred vertically (module docstring)."""
    bottom, top, horizontal = _pitches(camera_world, ends_world, radius_m)
    height = float(camera_world[1] + max(horizontal[0], 1e-6) * np.tan(0.5 * (bottom[0] + top[0])))
    return np.array([ends_world[0, 0], height, ends_world[0, 2]])


def fit_ratio(
    cameras_world: npt.NDArray[np.float64],
    ends_world: npt.NDArray[np.float64],
    radius_m: float,
    vertical_fov_deg: float,
    frame_margin: float,
) -> npt.NDArray[np.float64]:
    """(m,) for cameras (m, 3): tan of half the framed extent's angular span (an actor radius_m
    wide) over the most a centred extent may have, (1 - frame_margin) tan(fov / 2); above 1 it
    cannot be framed."""
    bottom, top, _ = _pitches(cameras_world, ends_world, radius_m)
    half_span = np.minimum(0.5 * (top - bottom), 0.5 * np.pi - 1e-6)
    ratio: npt.NDArray[np.float64] = np.tan(half_span) / ((1.0 - frame_margin) * np.tan(np.radians(vertical_fov_deg) / 2.0))
    return ratio
