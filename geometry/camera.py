"""Camera types: lens, pose, and the projection of world points to normalised screen space.

Camera convention (glTF, as on the wire): the camera looks down its local -Z with +Y up; screen
x is right, y is up, both in [-1, 1] at the frame's edges.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.transforms import quat_to_matrix


@dataclass(frozen=True)
class Lens:
    """vertical_fov_deg: full vertical field of view, degrees, in (1, 170); aspect: width/height."""

    vertical_fov_deg: float = 50.0
    aspect: float = 16.0 / 9.0

    @property
    def tan_half_fov_y(self) -> float:
        return math.tan(math.radians(self.vertical_fov_deg) / 2.0)

    @property
    def tan_half_fov_x(self) -> float:
        return self.tan_half_fov_y * self.aspect


@dataclass(frozen=True)
class CameraPose:
    """position_world: (3,) metres; rotation_xyzw: (4,) unit quaternion camera-to-world."""

    position_world: np.ndarray
    rotation_xyzw: np.ndarray
    vertical_fov_deg: float


def project_to_screen(pose: CameraPose, lens: Lens, points_world: np.ndarray) -> np.ndarray:
    """Normalised screen positions (n, 2) of world points (n, 3); NaN for points behind the camera."""
    r = quat_to_matrix(pose.rotation_xyzw)
    p_cam = (np.atleast_2d(points_world) - pose.position_world) @ r  # world -> camera: R^T p
    depth = -p_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = p_cam[:, 0] / (depth * lens.tan_half_fov_x)
        y = p_cam[:, 1] / (depth * lens.tan_half_fov_y)
    out = np.stack([x, y], axis=1)
    out[depth <= 0.0] = np.nan
    return out
