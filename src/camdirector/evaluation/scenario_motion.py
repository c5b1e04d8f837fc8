"""How a scenario's actors move: keyframed motion and the spawned objects' bounce.

`KeyframedMotion` is a file's `motion` (evaluation/scenario_schema.py): position keys interpolated
linearly or by Catmull-Rom (cubic Hermite through every key with tangents
(p[k+1] - p[k-1]) / (t[k+1] - t[k-1]), one-sided at the ends); before the first key and after the
last the actor holds, unless the motion loops (period t_last - t_first, the tangents wrapping
around). Its orientation follows yaw keys (linear in the written numbers), rotation keys (spherical
linear interpolation), the horizontal direction of travel (local +Z forward, holding the last
heading while it stands still), or else the actor's own rotation. `BounceMotion` is a spawn
generator's object: a straight horizontal line folded back into its region, a bounce off each side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def yaw_quat(yaw_rad: float | np.ndarray) -> np.ndarray:
    """(n,) yaw about +Y -> (n, 4) xyzw quaternions."""
    yaw_rad = np.asarray(yaw_rad, dtype=np.float64)
    q = np.zeros(yaw_rad.shape + (4,))
    q[..., 1], q[..., 3] = np.sin(yaw_rad / 2.0), np.cos(yaw_rad / 2.0)
    return q


@dataclass(eq=False)
class KeyframedMotion:
    """Position keys (times (k,), positions (k, 3)) and an optional orientation track."""

    times: np.ndarray
    positions: np.ndarray
    interpolation: str = "linear"  # linear | catmull_rom
    loop: bool = False
    yaw_keys: np.ndarray | None = None  # (k, 2) t, yaw_rad
    rotation_keys: np.ndarray | None = None  # (k, 5) t, qx, qy, qz, qw
    orient_path: bool = False

    def _wrap(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        t0, t1 = self.times[0], self.times[-1]
        if self.loop and t1 > t0:
            return t0 + np.mod(t - t0, t1 - t0)
        return np.clip(t, t0, t1)

    def _tangents(self) -> np.ndarray:
        p, t = self.positions, self.times
        k = len(t)
        m = np.zeros_like(p)
        if k < 2:
            return m
        m[1:-1] = (p[2:] - p[:-2]) / (t[2:] - t[:-2])[:, None]
        if self.loop and k > 2:
            end = (p[1] - p[-2]) / ((t[1] - t[0]) + (t[-1] - t[-2]))
            m[0] = m[-1] = end
        else:
            m[0] = (p[1] - p[0]) / (t[1] - t[0])
            m[-1] = (p[-1] - p[-2]) / (t[-1] - t[-2])
        return m

    def positions_at(self, times_s: np.ndarray) -> np.ndarray:
        """(n,) times -> (n, 3) positions, m."""
        t = self._wrap(times_s)
        p, keys = self.positions, self.times
        if len(keys) == 1:
            return np.repeat(p[:1], len(t), axis=0)
        j = np.clip(np.searchsorted(keys, t, side="right") - 1, 0, len(keys) - 2)
        h = keys[j + 1] - keys[j]
        u = ((t - keys[j]) / h)[:, None]
        if self.interpolation == "linear":
            return p[j] + u * (p[j + 1] - p[j])
        m = self._tangents()
        u2, u3 = u * u, u * u * u
        return (
            (2 * u3 - 3 * u2 + 1) * p[j]
            + (u3 - 2 * u2 + u) * h[:, None] * m[j]
            + (-2 * u3 + 3 * u2) * p[j + 1]
            + (u3 - u2) * h[:, None] * m[j + 1]
        )

    def rotations_at(self, times_s: np.ndarray, base_xyzw: np.ndarray) -> np.ndarray:
        """(n,) times, sorted -> (n, 4) xyzw quaternions."""
        times_s = np.asarray(times_s, dtype=np.float64)
        if self.yaw_keys is not None:
            t = self._wrap(times_s)
            return yaw_quat(np.interp(t, self.yaw_keys[:, 0], self.yaw_keys[:, 1]))
        if self.rotation_keys is not None:
            if len(self.rotation_keys) == 1:
                return np.repeat(self.rotation_keys[:1, 1:], len(times_s), axis=0)
            keys = self.rotation_keys
            t = np.clip(self._wrap(times_s), keys[0, 0], keys[-1, 0])
            return Slerp(keys[:, 0], Rotation.from_quat(keys[:, 1:]))(t).as_quat()
        if self.orient_path:
            return yaw_quat(self._path_yaw(times_s, base_xyzw))
        return np.repeat(np.asarray(base_xyzw, dtype=np.float64)[None, :], len(times_s), axis=0)

    def _path_yaw(self, times_s: np.ndarray, base_xyzw: np.ndarray) -> np.ndarray:
        h = 1e-3
        d = self.positions_at(times_s + h) - self.positions_at(times_s - h)
        moving = np.hypot(d[:, 0], d[:, 2]) > 1e-6  # 0.5 mm/s
        yaw = np.arctan2(d[:, 0], d[:, 2])
        if not moving.any():
            fwd = Rotation.from_quat(base_xyzw).apply([0.0, 0.0, 1.0])
            return np.full(len(times_s), math.atan2(fwd[0], fwd[2]))
        # hold the last heading while standing; before the first motion, the first heading
        idx = np.where(moving, np.arange(len(yaw)), -1)
        idx = np.maximum.accumulate(idx)
        idx[idx < 0] = int(np.argmax(moving))
        return yaw[idx]


@dataclass(eq=False)
class BounceMotion:
    """Straight line from `origin` at `velocity`, folded back into the region (a bounce off each side)."""

    origin: np.ndarray  # (3,) m, at start_s
    velocity: np.ndarray  # (3,) m/s, horizontal
    start_s: float
    x_range: tuple[float, float]  # allowed range of the centre, m
    z_range: tuple[float, float]

    def positions_at(self, times_s: np.ndarray) -> np.ndarray:
        t = np.maximum(np.asarray(times_s, dtype=np.float64) - self.start_s, 0.0)
        p = self.origin[None, :] + t[:, None] * self.velocity[None, :]
        p[:, 0] = _fold(p[:, 0], *self.x_range)
        p[:, 2] = _fold(p[:, 2], *self.z_range)
        return p

    def rotations_at(self, times_s: np.ndarray, base_xyzw: np.ndarray) -> np.ndarray:
        return np.repeat(np.asarray(base_xyzw, dtype=np.float64)[None, :], len(times_s), axis=0)


def _fold(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Reflect x into [lo, hi] (a triangle wave): the path of a point bouncing between two walls."""
    span = hi - lo
    if span <= 0.0:
        return np.full_like(x, lo)
    u = np.mod(x - lo, 2.0 * span)
    return lo + np.where(u <= span, u, 2.0 * span - u)
