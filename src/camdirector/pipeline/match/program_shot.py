"""The program's shot, which every director's decision returns, and what the rig asks of its camera.

A shot names whom it shows and how (`ShotChoice`, frame.py), the players' indices, when it went on
air and until when an event it shows holds it. Its camera is any `ShotCamera`: ours and the
takes' Toric cameras and overviews (shots.py), HLTV's chase and fixed cameras (hltv.py), the
autotrack's first-person view (autotrack.py), or a plugin director's own. The rig steps it every
frame (CAMERA, rig.py) and copies it to step it ahead of the frame (camera_ahead.py): a camera
changes only by assigning its attributes, so the rig tells a changed camera by their identity.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.pipeline.match.first_person import FirstPersonCamera
from camdirector.pipeline.match.frame import ShotChoice
from camdirector.pipeline.match.moments import TIME_EPSILON_S, Moment, MomentBuffer
from camdirector.pipeline.match.shots import ToricCamera


class ShotCamera(Protocol):
    """What the rig asks of a shot's camera (module docstring). A plain object whose state is its
    attributes (the rig copies it with copy.copy and compares `vars()` by identity)."""

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        """Moves on dt_s, s, to the moment (a cut's first frame: dt_s 0), with the style's response time."""
        ...

    def pose(self, moment: Moment) -> CameraPose | None:
        """The pose at the moment, as advanced; None when it has none (a degenerate framing)."""
        ...


def unchanged(camera: ShotCamera, attributes: dict[str, object]) -> bool:
    """Whether the camera's attributes are still those objects (`vars()` taken before, by name):
    a camera changes only by assigning them (module docstring)."""
    now = vars(camera)
    return now.keys() == attributes.keys() and all(now[k] is v for k, v in attributes.items())


@dataclass
class Shot:
    """The program's shot: whom and how (choice), the player indices, its camera, when it started
    (program time, s), until when it must hold for an event it shows, and its sub-scores."""

    choice: ShotChoice
    subjects: tuple[int, ...]
    camera: ShotCamera
    start_s: float
    hold_until_s: float = -math.inf
    cover_times_s: list[float] = field(default_factory=list)  # the events it is planned to show (its camera is placed for them)
    scores: dict[str, float] = field(default_factory=dict)
    held: bool = False  # a human's take

    def framed(self, time_s: float) -> tuple[int, ...]:
        """The players its picture frames at time_s, s: its subjects, or the one its pair window keeps (shots.py)."""
        framed = self.camera.framed(time_s) if isinstance(self.camera, (ToricCamera, FirstPersonCamera)) else None
        return self.subjects if framed is None else framed


# A candidate for the preview monitors: whom and how, its Toric camera at the style's place (None:
# an OVERVIEW candidate, shown from the program's pose until taken), and its interest.
CandidateShot = tuple[ShotChoice, ToricCamera | None, float]


def camera_movers(camera: object) -> tuple[int, ...]:
    """The players whose jump (a teleport, a respawn) moves a shot's camera through walls: a
    first-person camera's player, a Toric camera's anchor; none for a fixed or overview camera."""
    if isinstance(camera, FirstPersonCamera):
        return (camera.player,)
    if isinstance(camera, ToricCamera):
        return (camera.anchor_index,)
    return ()


def camera_jumps_at(
    camera: object, buffer: MomentBuffer, time_s: float, crosses: Callable[[np.ndarray, np.ndarray], np.ndarray]
) -> bool:
    """Whether a player whose jump moves the camera (camera_movers) jumps through the level at the
    buffered moment time_s, s, from the moment before (MomentBuffer.jumps_s with `crosses`)."""
    movers = camera_movers(camera)
    return bool(movers) and bool(buffer.jumps_s(movers, time_s - TIME_EPSILON_S, time_s, crosses))
