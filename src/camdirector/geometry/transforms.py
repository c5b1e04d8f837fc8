"""Rigid transforms and unit quaternions, (x, y, z, w) order as on the wire.

All functions take and return numpy arrays; batched forms accept leading dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

IDENTITY_QUAT = np.array([0.0, 0.0, 0.0, 1.0])
UP_WORLD = np.array([0.0, 1.0, 0.0])  # +Y up: the wire contract's world (docs/protocol.md)
UP_WORLD.setflags(write=False)


def quat_normalize(q_xyzw: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Unit quaternion with w >= 0 (one of the two that name each rotation), shape kept."""
    q: npt.NDArray[np.float64] = np.asarray(q_xyzw, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def quat_to_matrix(q_xyzw: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Rotation matrix of a unit quaternion: (..., 4) -> (..., 3, 3) float64."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    if q.ndim == 1:  # the per-frame case: scalar arithmetic is several times cheaper than ufuncs
        x, y, z, w = q.tolist()
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
    x, y, z, w = np.moveaxis(q, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.stack(
        [
            1 - 2 * (yy + zz),
            2 * (xy - wz),
            2 * (xz + wy),
            2 * (xy + wz),
            1 - 2 * (xx + zz),
            2 * (yz - wx),
            2 * (xz - wy),
            2 * (yz + wx),
            1 - 2 * (xx + yy),
        ],
        axis=-1,
    )
    return m.reshape(m.shape[:-1] + (3, 3))


def matrix_to_quat(m: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Unit quaternion (x, y, z, w), w >= 0, of a rotation matrix (3, 3).

    Shepperd's method: branch on the largest diagonal term so no square root of a small number
    is taken (continuous and accurate for every rotation).
    """
    m = np.asarray(m, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    return quat_normalize(np.array(q))


def quat_rotate(q_xyzw: npt.ArrayLike, v: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Rotate vectors v (..., 3) by the unit quaternion q (4,)."""
    return np.asarray(v, dtype=np.float64) @ quat_to_matrix(q_xyzw).T


@dataclass
class RigidTransform:
    """Local-to-world transform: world = position + R(rotation) @ (scale * local).

    position_world: (3,) float64 metres; rotation_xyzw: (4,) unit quaternion; scale: (3,).
    """

    position_world: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    rotation_xyzw: npt.NDArray[np.float64] = field(default_factory=lambda: IDENTITY_QUAT.copy())
    scale: npt.NDArray[np.float64] = field(default_factory=lambda: np.ones(3))

    def matrix(self) -> npt.NDArray[np.float64]:
        """(4, 4) float64 local-to-world matrix."""
        m = np.eye(4)
        m[:3, :3] = quat_to_matrix(self.rotation_xyzw) * self.scale[None, :]
        m[:3, 3] = self.position_world
        return m

    def inverse_matrix(self) -> npt.NDArray[np.float64]:
        """(4, 4) float64 world-to-local matrix, without a general inverse: (R S)^-1 = S^-1 R^T."""
        m = np.eye(4)
        m[:3, :3] = quat_to_matrix(self.rotation_xyzw).T / self.scale[:, None]
        m[:3, 3] = -m[:3, :3] @ self.position_world
        return m

    def apply(self, points_local: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(n, 3) local points -> (n, 3) world points."""
        r = quat_to_matrix(self.rotation_xyzw)
        return (np.asarray(points_local) * self.scale) @ r.T + self.position_world
