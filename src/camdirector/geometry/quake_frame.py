"""Quake's units and axes turned into the wire contract's world (metres, +Y up), in one place.

Quake (QuakeWorld demos and BSP maps alike) measures in units with +Z up, +X forward at yaw 0 and
yaw turning +X toward +Y. Its player stands 56 units tall (hull -24..+32 about its origin) and 32
wide; taking that player as 1.75 m, a grown person, gives 1/32 m per unit. The alternative
convention, one unit = one inch (Source's), would make the same player 1.42 m and its 10 m/s
running speed 8 m/s; we size cameras for people, so the player's height sets the scale.

Axes: (x, y, z)_quake -> (x, z, -y)_world, a proper rotation (determinant +1), scaled.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

M_PER_UNIT = 1.0 / 32.0  # 56 units = 1.75 m (module docstring)
PLAYER_HEIGHT_UNITS = 56.0  # hull mins z -24 to maxs z +32
PLAYER_RADIUS_UNITS = 16.0  # hull half width
ORIGIN_ABOVE_FEET_UNITS = 24.0  # a player's origin is 24 units above its feet
PLAYER_HEIGHT_M = PLAYER_HEIGHT_UNITS * M_PER_UNIT
PLAYER_RADIUS_M = PLAYER_RADIUS_UNITS * M_PER_UNIT


def points_to_world(points_units: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Quake points (..., 3) in units, Z up -> world points (..., 3) float64 in metres, Y up."""
    p = np.asarray(points_units, dtype=np.float64)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1) * M_PER_UNIT


def feet_world(origins_units: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """A player's feet in the world (..., 3) metres from its Quake origins (..., 3) units."""
    o = np.asarray(origins_units, dtype=np.float64).copy()
    o[..., 2] -= ORIGIN_ABOVE_FEET_UNITS
    return points_to_world(o)


def view_rotation(pitch_deg: npt.ArrayLike, yaw_deg: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Unit quaternions (..., 4) xyzw turning local +Z onto Quake's view direction, local +Y up.

    Quake's forward is (cos p cos y, cos p sin y, -sin p) for pitch p (positive looks down) and
    yaw y (AngleVectors), which is (cos p cos y, -sin p, -cos p sin y) in the world: a turn of
    y + 90 deg about +Y after a turn of p about +X. Roll is not used (players do not roll).
    """
    half_yaw = np.radians(np.asarray(yaw_deg, dtype=np.float64) + 90.0) / 2.0
    half_pitch = np.radians(np.asarray(pitch_deg, dtype=np.float64)) / 2.0
    cy, sy = np.cos(half_yaw), np.sin(half_yaw)
    cp, sp = np.cos(half_pitch), np.sin(half_pitch)
    # q_yaw (0, sy, 0, cy) times q_pitch (sp, 0, 0, cp), Hamilton product.
    q = np.stack([cy * sp, sy * cp, -sy * sp, cy * cp], axis=-1)
    return np.where(q[..., 3:4] < 0.0, -q, q)
