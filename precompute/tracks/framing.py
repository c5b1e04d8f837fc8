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


class ShotSize(Enum):
    MEDIUM = "medium"
    LONG = "long"
    EXTREME_LONG = "extreme_long"


# (low, high) fractions of the actor's height, from its feet, that the shot size keeps in frame
FRAMED_EXTENT = {ShotSize.MEDIUM: (0.5, 1.0), ShotSize.LONG: (0.0, 1.0), ShotSize.EXTREME_LONG: (0.0, 1.0)}
