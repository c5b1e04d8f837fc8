"""The state one frame computes, passed along the stages (their order: pipeline/stages.py).

A core that every rig fills and every reader may read (the reply, the timeline, the monitors),
and the part of the rig that ran the frame, each defined in its rig's folder and reached by the
rig's name: `state.toric` (pipeline/toric/frame.py: the framed points, the torus, the camera's
place on it) or `state.match` (pipeline/match/frame.py: the program's shot, the candidates, the
delay buffer, the roster, the game events, the planned cut). A part is None under another rig;
the TRACKS rig has none: all it answers is core (its sub-scores are `scores`, as MATCH's are).
The rig sets its part at the start of its stages (`CameraRig.run`, pipeline/camera_rig.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose
from camdirector.pipeline.match.frame import MatchFrame
from camdirector.pipeline.toric.frame import ToricFrame


@dataclass
class FrameState:
    """What one frame computes, filled stage by stage (module docstring)."""

    frame: int
    time_s: float
    dt_s: float  # since the previous answered frame, s (0 on the first)
    aim_points_world: list[npt.NDArray[np.float64]] = field(default_factory=list)  # (3,) per target
    pose: CameraPose | None = None  # None: no camera yet (MATCH while its delay fills)
    cut: bool = False
    shot_id: int = 0
    visibility: float = 1.0  # [0, 1]
    framing_error: float = math.nan  # framed points from where the style puts them, screen units (NaN: none)
    flags: list[str] = field(default_factory=list)  # degraded-mode notes for diagnostics
    scores: dict[str, float] = field(default_factory=dict)  # the rig's sub-scores of its choice, by name (TORIC: none)
    stage_ms: dict[str, float] = field(default_factory=dict)
    toric: ToricFrame | None = None  # the TORIC rig's part
    match: MatchFrame | None = None  # the MATCH rig's part
