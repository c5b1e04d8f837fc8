"""Shot sizes on screen (Section 6.1): what each shot size must show of the actor.

How we read Section 6.1: a shot size is the actor's expected on-screen height, its height over
the frame's (`DirectorSettings.*_screen_fraction`): medium 1.6 (the whole body would be 1.6 frames
tall, so from the waist up, half the body, fills 0.8 of the frame), long 0.8 ("the whole body
fills most of the frame"), extreme long 0.25 (the actor small in the set). What a shot size must
keep inside the frame is its framed extent, a span up the actor from its feet, in fractions of its
height: the whole body (0 to 1) for long and extreme long, the waist up (0.5 to 1) for medium.
"""
from __future__ import annotations

from enum import Enum

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.transforms import UP_WORLD


class ShotSize(Enum):
    MEDIUM = "medium"
    LONG = "long"
    EXTREME_LONG = "extreme_long"


# (low, high) fractions of the actor's height, from its feet, that the shot size keeps in frame
FRAMED_EXTENT = {ShotSize.MEDIUM: (0.5, 1.0), ShotSize.LONG: (0.0, 1.0), ShotSize.EXTREME_LONG: (0.0, 1.0)}


def framed_ends_world(feet_world: np.ndarray, height_m: float, shot_size: ShotSize) -> np.ndarray:
    """(2, 3) the bottom and top of the shot size's framed extent on the actor's vertical axis, m.
    feet_world (3,): the actor's feet."""
    low, high = FRAMED_EXTENT[shot_size]
    return np.asarray(feet_world, dtype=np.float64) + np.outer([low * height_m, high * height_m], UP_WORLD)


def framing_error(pose: CameraPose, lens: Lens, feet_world: np.ndarray, height_m: float, shot_size: ShotSize,
                  screen_fraction: float) -> float:
    """How far the framed extent's ends land from where the shot size puts them, in normalised
    screen units (the frame is [-1, 1]; the Toric rig's framing error is in the same units): the
    ends belong centred at (0, -h) and (0, h), h = screen_fraction * (high - low), the half of the
    extent's share of the frame height; the larger of the two ends' largest axis error. NaN when
    an end is behind the camera."""
    low, high = FRAMED_EXTENT[shot_size]
    half = screen_fraction * (high - low)
    screen = project_to_screen(pose, lens, framed_ends_world(feet_world, height_m, shot_size))  # (2, 2)
    error = np.abs(screen - np.array([[0.0, -half], [0.0, half]])).max()
    return float(error)
