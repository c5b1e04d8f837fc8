"""Camera types: lens, pose, the projection of world points to normalised screen space, and
whether they lie in the frame.

Camera convention (glTF, as on the wire): the camera looks down its local -Z with +Y up; screen
x is right, y is up, both in [-1, 1] at the frame's edges.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from camdirector.geometry.transforms import matrix_to_quat, quat_to_matrix

# Points nearer the camera than this (along its view axis) are clipped, as a renderer clips at its
# near plane: Cinemachine's default lens (LensSettings.Default, NearClipPlane = 0.1), m.
NEAR_PLANE_M = 0.1


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

    position_world: npt.NDArray[np.float64]
    rotation_xyzw: npt.NDArray[np.float64]
    vertical_fov_deg: float


_FEW_POINTS = 4  # up to this many points (a frame's targets) scalar arithmetic beats numpy's per-call overhead


def project_to_screen(pose: CameraPose, lens: Lens, points_world: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Normalised screen positions (n, 2) of world points (n, 3); NaN for points behind the camera."""
    points = np.atleast_2d(points_world)
    if len(points) <= _FEW_POINTS:  # the per-frame case (a rig's framing error): 2 us instead of 13
        return _project_few(pose, lens, points)
    r = quat_to_matrix(pose.rotation_xyzw)
    p_cam = (points - pose.position_world) @ r  # world -> camera: R^T p
    depth = -p_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = p_cam[:, 0] / (depth * lens.tan_half_fov_x)
        y = p_cam[:, 1] / (depth * lens.tan_half_fov_y)
    out = np.stack([x, y], axis=1)
    out[depth <= 0.0] = np.nan
    return out


def _project_few(pose: CameraPose, lens: Lens, points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """project_to_screen for a few points (n, 3), in scalars: the camera's axes are the columns of
    the rotation (quat_to_matrix), a point's camera coordinates its offset dotted with them."""
    x, y, z, w = pose.rotation_xyzw.tolist()
    right = (1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y))
    up = (2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x))
    back = (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))
    cx, cy, cz = pose.position_world.tolist()
    tan_x, tan_y = lens.tan_half_fov_x, lens.tan_half_fov_y
    out = []
    for px, py, pz in points.tolist():
        dx, dy, dz = px - cx, py - cy, pz - cz
        depth = -(dx * back[0] + dy * back[1] + dz * back[2])
        if depth <= 0.0:
            out.append((math.nan, math.nan))
        else:
            out.append(
                (
                    (dx * right[0] + dy * right[1] + dz * right[2]) / (depth * tan_x),
                    (dx * up[0] + dy * up[1] + dz * up[2]) / (depth * tan_y),
                )
            )
    return np.array(out, dtype=np.float64).reshape(len(points), 2)


def project_from_cameras(
    positions_world: npt.NDArray[np.float64], rotations: npt.NDArray[np.float64], lens: Lens, points_world: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """project_to_screen for m cameras at once: (m, n, 2) normalised screen positions of world
    points (n, 3) from cameras at positions_world (m, 3) with camera-to-world rotation matrices
    (m, 3, 3); NaN for points behind a camera (and for a camera whose rotation is NaN)."""
    offsets = np.atleast_2d(points_world)[None, :, :] - positions_world[:, None, :]
    p_cam = offsets @ rotations  # world -> camera: R^T p, per camera
    depth = -p_cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.stack([p_cam[..., 0] / (depth * lens.tan_half_fov_x), p_cam[..., 1] / (depth * lens.tan_half_fov_y)], axis=-1)
    out[~(depth > 0.0)] = np.nan
    return out


def in_frame(pose: CameraPose, lens: Lens, points_world: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """(n,) bool: whether each point (n, 3) m lies in the view frustum of `pose`: at least
    NEAR_PLANE_M in front of the camera along its view axis, and within the frame's edges
    (|x| <= 1 and |y| <= 1 in normalised screen units) at the pose's vertical field of view and the
    lens's aspect. lens.vertical_fov_deg is not used: the pose carries the field of view."""
    frame_lens = Lens(vertical_fov_deg=pose.vertical_fov_deg, aspect=lens.aspect)
    screen = project_to_screen(pose, frame_lens, points_world)  # NaN behind the camera
    z_camera = (np.atleast_2d(points_world) - pose.position_world) @ quat_to_matrix(pose.rotation_xyzw)[:, 2]
    with np.errstate(invalid="ignore"):
        inside: npt.NDArray[np.bool_] = (-z_camera >= NEAR_PLANE_M) & np.all(np.abs(screen) <= 1.0, axis=1)
    return inside


def level_look_rotation(
    camera_world: npt.NDArray[np.float64], point_world: npt.ArrayLike, screen_xy: Sequence[float], lens: Lens
) -> npt.NDArray[np.float64]:
    """Camera-to-world quaternion (4,) xyzw with no roll (camera x axis horizontal, +Y up) that
    shows point_world at normalised screen_xy (2,) (`level_rotation`)."""
    d = np.array([screen_xy[0] * lens.tan_half_fov_x, screen_xy[1] * lens.tan_half_fov_y, -1.0])
    a = np.asarray(point_world, dtype=np.float64) - camera_world
    return matrix_to_quat(level_rotation(a / np.linalg.norm(a), d / np.linalg.norm(d)))


def level_look_matrices(
    cameras_world: npt.ArrayLike, point_world: npt.ArrayLike, screen_xy: Sequence[float], lens: Lens
) -> npt.NDArray[np.float64]:
    """(m, 3, 3) camera-to-world rotation matrices of `level_look_rotation` for m cameras (m, 3) at
    once (a place search tries hundreds); rows of NaN for a camera at the point."""
    d = np.array([screen_xy[0] * lens.tan_half_fov_x, screen_xy[1] * lens.tan_half_fov_y, -1.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.asarray(point_world, dtype=np.float64) - np.atleast_2d(cameras_world)
        a /= np.linalg.norm(a, axis=1, keepdims=True)
    return level_rotations(a, d / np.linalg.norm(d))


def level_rotation(world_dir: Iterable[float], camera_dir: Iterable[float]) -> npt.NDArray[np.float64]:
    """(3, 3) `level_rotations` for one world direction (3,), in scalars: the per-frame case, where
    numpy's per-call cost would triple it."""
    wx, wy, wz = (float(c) for c in world_dir)
    dx, dy, dz = (float(c) for c in camera_dir)
    rho = math.hypot(dy, dz)
    delta = math.atan2(dz, dy)
    base = math.acos(max(-1.0, min(1.0, wy / rho)))
    pitch = min((base - delta, -base - delta), key=lambda p: abs(math.remainder(p, math.tau)))
    return level_matrix(math.atan2(wx, wz) - math.atan2(dx, dy * math.sin(pitch) + dz * math.cos(pitch)), pitch)


def level_matrix(yaw_rad: float, pitch_rad: float) -> npt.NDArray[np.float64]:
    """(3, 3) camera-to-world rotation with no roll, R = Ry(yaw) Rx(pitch) (`level_rotations`)."""
    cw, sw, cp, sp = math.cos(yaw_rad), math.sin(yaw_rad), math.cos(pitch_rad), math.sin(pitch_rad)
    return np.array(((cw, sw * sp, sw * cp), (0.0, cp, -sp), (-sw, cw * sp, cw * cp)))


def level_angles(rotation: npt.NDArray[np.float64]) -> tuple[float, float]:
    """The yaw and pitch, radians, of a (3, 3) rotation with no roll: `level_matrix` inverted."""
    return math.atan2(-rotation[2, 0], rotation[0, 0]), math.atan2(-rotation[1, 2], rotation[1, 1])


def level_rotations(world_dirs: npt.ArrayLike, camera_dir: Iterable[float]) -> npt.NDArray[np.float64]:
    """(m, 3, 3) camera-to-world rotations with no roll that turn the unit camera-space direction
    camera_dir (3,) onto each unit world direction of world_dirs (m, 3); rows of NaN stay NaN.

    Written as yaw about +Y after pitch about x, R = Ry(yaw) Rx(pitch): the pitch brings camera_dir
    to the world direction's elevation (yaw keeps elevations), then the yaw turns it onto the world
    direction. Of the two pitches, the one nearer level is taken. When the direction is too steep
    for camera_dir (near the zenith) the pitch saturates and it lands off camera_dir rather than
    the camera rolling.
    """
    w = np.asarray(world_dirs, dtype=np.float64)
    dx, dy, dz = (float(c) for c in camera_dir)
    rho = math.hypot(dy, dz)
    delta = math.atan2(dz, dy)
    base = np.arccos(np.clip(w[:, 1] / rho, -1.0, 1.0))
    up, down = base - delta, -base - delta
    pitch = np.where(
        np.abs(np.remainder(up + math.pi, math.tau) - math.pi) <= np.abs(np.remainder(down + math.pi, math.tau) - math.pi),
        up,
        down,
    )
    cp, sp = np.cos(pitch), np.sin(pitch)
    yaw = np.arctan2(w[:, 0], w[:, 2]) - np.arctan2(dx, dy * sp + dz * cp)
    cw, sw = np.cos(yaw), np.sin(yaw)
    out = np.stack(
        [
            np.stack([cw, sw * sp, sw * cp], axis=1),
            np.stack([np.zeros_like(cw), cp, -sp], axis=1),
            np.stack([-sw, cw * sp, cw * cp], axis=1),
        ],
        axis=1,
    )
    out[np.isnan(pitch)] = np.nan  # the constant zero of a NaN row too
    return out
