"""The level camera looking along a direction: the view of the baselines' cameras, HLTV's chase,
fixed and in-eye views (hltv.py) and the autotrack's first-person view (autotrack.py).
"""

from __future__ import annotations

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.transforms import matrix_to_quat


def look_along(position: np.ndarray, direction: np.ndarray, fov_deg: float) -> CameraPose:
    """The level camera (no roll) at position (3,) m looking along direction (3,)."""
    forward = direction / np.linalg.norm(direction)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= max(np.linalg.norm(right), 1e-9)
    up = np.cross(right, forward)
    return CameraPose(position, matrix_to_quat(np.stack([right, up, -forward], axis=1)), fov_deg)
