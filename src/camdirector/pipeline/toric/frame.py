"""The TORIC rig's part of a frame's state (`FrameState.toric`, pipeline/state.py): the framed
points, the torus of cameras that frames them, and the camera's place on it.

FRAMING (framing.py) fills the points and the torus; MOTION (camera_motion.py, occlusion_search.py)
the place. The wire carries the place and the torus's composition angle in the reply's
diagnostics (worker/codec.py); the A-map picture marks the place (rig.py: `anticipation_map`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from camdirector.geometry.toric import Torus


@dataclass
class ToricFrame:
    a_world: npt.NDArray[np.float64] | None = None  # (3,) framed point A, m
    b_world: npt.NDArray[np.float64] | None = None  # (3,) framed point B, m
    b_is_gaze_point: bool = False  # B is the one target's gaze-room point, not a target
    torus: Torus | None = None  # None: the framing is degenerate (the pose is held)
    theta: float = 0.0  # the camera's place on the torus, rad
    phi: float = 0.0  # rad
