"""NumPy interop with the wire contract, and conversions from and to game-engine frames.

Our frame (the wire contract's): right-handed, +Y up, metres. A camera looks down its local -Z
with local +Y up and local +X to its right (glTF). Quaternions are (x, y, z, w), unit length, and
rotate as ``v' = q v q*`` (Hamilton product), as they do in Unity and Unreal too: only the axes
differ between the three frames, never the quaternion algebra.

Unity: left-handed, +Y up, +Z forward, +X right, metres.
    ours = (x_u, y_u, -z_u)                       positions and directions
    q_ours = (-qx_u, -qy_u, qz_u, qw_u)           rotations
    s_ours = s_u                                  scales
    Each map is its own inverse. A Unity camera looks down its local +Z, which these maps send to
    our local -Z, so a Unity camera's rotation converts to our camera rotation unchanged.

Unreal: left-handed, +Z up, +X forward, +Y right, centimetres.
    ours = (y_ue, z_ue, -x_ue) / 100              positions (cm -> m) and, without /100, directions
    q_ours = (-qy_ue, -qz_ue, qx_ue, qw_ue)       rotations (FQuat components, not FRotator angles)
    s_ours = (sy_ue, sz_ue, sx_ue)                scales (ratios: no unit change)
    and back: ue = 100 * (-z, x, y), q_ue = (qz, -qx, -qy, qw), s_ue = (sz, sx, sy).
    Unreal's forward, right and up (+X, +Y, +Z) become our -Z, +X and +Y: the forward, right and up
    of our camera, so an Unreal camera's rotation converts to our camera rotation unchanged.

Why the rotation formulas: both maps are reflections ``ours = A engine`` with det(A) = -1. A rotation
R becomes ``A R A^T``; a rotation by angle t about the axis a becomes one by t about
``det(A) A a = -A a``. So a quaternion's vector part maps by ``-A`` and its w part stays. For the
same reason a scale ``diag(s)`` in the engine's local frame becomes ``A diag(s) A^T``, a
permutation of s, and ``world = p + R (s * local)`` holds in both frames at once.

Meshes: a reflection turns clockwise triangles counter-clockwise. Unity and Unreal treat clockwise
triangles as front-facing, glTF (and we) counter-clockwise: pass ``flip_winding=True`` to
:func:`mesh_from_arrays` for triangles read from either engine after converting their vertices
with ``from_unity_position`` / ``from_unreal_position``.

Every converter takes one vector ``(3,)`` / quaternion ``(4,)`` or a batch ``(n, 3)`` / ``(n, 4)``
and returns a new float64 array of the same shape.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from camdirector.v1 import director_pb2 as pb

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Pose",
    "camera_pose_to_unity",
    "camera_pose_to_unreal",
    "from_unity_position",
    "from_unity_rotation",
    "from_unity_scale",
    "from_unreal_position",
    "from_unreal_rotation",
    "from_unreal_scale",
    "horizontal_fov_deg",
    "mesh_from_arrays",
    "pack_states",
    "pose_from_msg",
    "quat",
    "rotation_matrix",
    "to_unity_position",
    "to_unity_rotation",
    "to_unity_scale",
    "to_unreal_position",
    "to_unreal_rotation",
    "to_unreal_scale",
    "transform_msg",
    "unpack_states",
    "vec3",
]

PACKED_WIDTH = 10
"""Doubles per id in ``FrameUpdate.packed_transforms``: px, py, pz, qx, qy, qz, qw, sx, sy, sz."""

_UNREAL_CM_PER_M = 100.0

# Unity: flip Z.
_UNITY_POSITION_SIGN = np.array([1.0, 1.0, -1.0])
_UNITY_ROTATION_SIGN = np.array([-1.0, -1.0, 1.0, 1.0])

# Unreal: ours = A ue with A = [[0, 1, 0], [0, 0, 1], [-1, 0, 0]]; quaternion vector part by -A.
_FROM_UNREAL_AXES = np.array([1, 2, 0])
_FROM_UNREAL_POSITION_SIGN = np.array([1.0, 1.0, -1.0])
_TO_UNREAL_AXES = np.array([2, 0, 1])
_TO_UNREAL_POSITION_SIGN = np.array([-1.0, 1.0, 1.0])
_FROM_UNREAL_QUAT_AXES = np.array([1, 2, 0, 3])
_FROM_UNREAL_QUAT_SIGN = np.array([-1.0, -1.0, 1.0, 1.0])
_TO_UNREAL_QUAT_AXES = np.array([2, 0, 1, 3])
_TO_UNREAL_QUAT_SIGN = np.array([1.0, -1.0, -1.0, 1.0])


def _as_rows(values: ArrayLike, width: int, name: str) -> NDArray[np.float64]:
    """``values`` as float64 of shape (width,) or (n, width); ValueError otherwise."""
    array = np.asarray(values, dtype=np.float64)
    if array.ndim not in (1, 2) or array.shape[-1] != width:
        raise ValueError(f"{name} must be ({width},) or (n, {width}), got shape {array.shape}")
    return array


# --- Unity -------------------------------------------------------------------------------------


def from_unity_position(position: ArrayLike) -> NDArray[np.float64]:
    """Unity positions or directions ``(3,) | (n, 3)`` (metres) in our frame: ``(x, y, -z)``."""
    return _as_rows(position, 3, "position") * _UNITY_POSITION_SIGN


def to_unity_position(position: ArrayLike) -> NDArray[np.float64]:
    """Our positions or directions ``(3,) | (n, 3)`` in Unity's frame: ``(x, y, -z)``."""
    return _as_rows(position, 3, "position") * _UNITY_POSITION_SIGN


def from_unity_rotation(rotation_xyzw: ArrayLike) -> NDArray[np.float64]:
    """Unity quaternions ``(4,) | (n, 4)`` (x, y, z, w) in our frame: ``(-x, -y, z, w)``."""
    return _as_rows(rotation_xyzw, 4, "rotation_xyzw") * _UNITY_ROTATION_SIGN


def to_unity_rotation(rotation_xyzw: ArrayLike) -> NDArray[np.float64]:
    """Our quaternions ``(4,) | (n, 4)`` (x, y, z, w) in Unity's frame: ``(-x, -y, z, w)``."""
    return _as_rows(rotation_xyzw, 4, "rotation_xyzw") * _UNITY_ROTATION_SIGN


def from_unity_scale(scale: ArrayLike) -> NDArray[np.float64]:
    """Unity local scales ``(3,) | (n, 3)`` in our frame: unchanged (a copy)."""
    return _as_rows(scale, 3, "scale").copy()


def to_unity_scale(scale: ArrayLike) -> NDArray[np.float64]:
    """Our local scales ``(3,) | (n, 3)`` in Unity's frame: unchanged (a copy)."""
    return _as_rows(scale, 3, "scale").copy()


# --- Unreal ------------------------------------------------------------------------------------


def from_unreal_position(position_cm: ArrayLike) -> NDArray[np.float64]:
    """Unreal positions ``(3,) | (n, 3)`` in centimetres as ours in metres: ``(y, z, -x) / 100``.

    For a direction (unitless), multiply the result by 100, or use it as it is and renormalise.
    """
    array = _as_rows(position_cm, 3, "position_cm")
    return array[..., _FROM_UNREAL_AXES] * _FROM_UNREAL_POSITION_SIGN / _UNREAL_CM_PER_M


def to_unreal_position(position: ArrayLike) -> NDArray[np.float64]:
    """Our positions ``(3,) | (n, 3)`` in metres as Unreal's in centimetres: ``100 (-z, x, y)``."""
    array = _as_rows(position, 3, "position")
    return array[..., _TO_UNREAL_AXES] * _TO_UNREAL_POSITION_SIGN * _UNREAL_CM_PER_M


def from_unreal_rotation(rotation_xyzw: ArrayLike) -> NDArray[np.float64]:
    """Unreal FQuat components ``(4,) | (n, 4)`` (x, y, z, w) in our frame: ``(-y, -z, x, w)``."""
    array = _as_rows(rotation_xyzw, 4, "rotation_xyzw")
    return array[..., _FROM_UNREAL_QUAT_AXES] * _FROM_UNREAL_QUAT_SIGN


def to_unreal_rotation(rotation_xyzw: ArrayLike) -> NDArray[np.float64]:
    """Our quaternions ``(4,) | (n, 4)`` (x, y, z, w) as Unreal FQuat components: ``(z, -x, -y, w)``."""
    array = _as_rows(rotation_xyzw, 4, "rotation_xyzw")
    return array[..., _TO_UNREAL_QUAT_AXES] * _TO_UNREAL_QUAT_SIGN


def from_unreal_scale(scale: ArrayLike) -> NDArray[np.float64]:
    """Unreal local scales ``(3,) | (n, 3)`` (X, Y, Z) in our frame: ``(sy, sz, sx)``."""
    return _as_rows(scale, 3, "scale")[..., _FROM_UNREAL_AXES]


def to_unreal_scale(scale: ArrayLike) -> NDArray[np.float64]:
    """Our local scales ``(3,) | (n, 3)`` as Unreal's (X, Y, Z): ``(sz, sx, sy)``."""
    return _as_rows(scale, 3, "scale")[..., _TO_UNREAL_AXES]


# --- rotations and camera poses ----------------------------------------------------------------


def rotation_matrix(rotation_xyzw: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices ``(3, 3) | (n, 3, 3)`` of quaternions ``(4,) | (n, 4)`` (x, y, z, w).

    The quaternions are normalised first; a zero quaternion gives the identity.
    """
    q = _as_rows(rotation_xyzw, 4, "rotation_xyzw")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(norm > 0.0, q / np.where(norm > 0.0, norm, 1.0), np.array([0.0, 0.0, 0.0, 1.0]))
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    m[..., 0, 1] = 2.0 * (x * y - z * w)
    m[..., 0, 2] = 2.0 * (x * z + y * w)
    m[..., 1, 0] = 2.0 * (x * y + z * w)
    m[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    m[..., 1, 2] = 2.0 * (y * z - x * w)
    m[..., 2, 0] = 2.0 * (x * z - y * w)
    m[..., 2, 1] = 2.0 * (y * z + x * w)
    m[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return m


@dataclass(frozen=True, slots=True)
class Pose:
    """A camera pose in our frame (right-handed, +Y up, metres; the camera looks down local -Z).

    Attributes
    ----------
    position : (3,) float
        Camera centre in world space, metres.
    rotation_xyzw : (4,) float
        Camera-to-world rotation, unit quaternion (x, y, z, w).
    vertical_fov_deg : float
        Vertical field of view, degrees.
    """

    position: NDArray[np.float64]
    rotation_xyzw: NDArray[np.float64]
    vertical_fov_deg: float

    def rotation_matrix(self) -> NDArray[np.float64]:
        """(3, 3) camera-to-world rotation; its columns are the camera's right, up and back axes."""
        return rotation_matrix(self.rotation_xyzw)

    def matrix(self) -> NDArray[np.float64]:
        """(4, 4) camera-to-world transform (world = M @ [local, 1])."""
        m = np.eye(4)
        m[:3, :3] = rotation_matrix(self.rotation_xyzw)
        m[:3, 3] = self.position
        return m

    @property
    def forward(self) -> NDArray[np.float64]:
        """(3,) unit world direction the camera looks along (its local -Z)."""
        return -rotation_matrix(self.rotation_xyzw)[:, 2]

    @property
    def up(self) -> NDArray[np.float64]:
        """(3,) unit world direction of the camera's up (its local +Y)."""
        return rotation_matrix(self.rotation_xyzw)[:, 1]

    @property
    def right(self) -> NDArray[np.float64]:
        """(3,) unit world direction of the camera's right (its local +X)."""
        return rotation_matrix(self.rotation_xyzw)[:, 0]


def pose_from_msg(pose: pb.CameraPose) -> Pose:
    """A :class:`Pose` from a ``CameraPose`` message; an unset or zero rotation is the identity."""
    p = pose.position
    r = pose.rotation
    rotation = np.array([r.x, r.y, r.z, r.w])
    norm = math.sqrt(r.x * r.x + r.y * r.y + r.z * r.z + r.w * r.w)
    if norm > 0.0:
        rotation /= norm
    else:
        rotation[3] = 1.0
    return Pose(np.array([p.x, p.y, p.z]), rotation, pose.vertical_fov_deg)


def _as_pose(pose: Pose | pb.CameraPose) -> Pose:
    return pose if isinstance(pose, Pose) else pose_from_msg(pose)


def camera_pose_to_unity(pose: Pose | pb.CameraPose) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Position (3,) in metres and rotation (4,) (x, y, z, w) of a Unity camera (which looks down
    its local +Z, +Y up) showing what ``pose`` shows. Unity's ``Camera.fieldOfView`` is vertical
    by default, so ``pose.vertical_fov_deg`` applies as it is.
    """
    pose = _as_pose(pose)
    # Flipping Z sends our camera's local -Z (forward) to Unity's local +Z: no extra rotation.
    return to_unity_position(pose.position), to_unity_rotation(pose.rotation_xyzw)


def camera_pose_to_unreal(pose: Pose | pb.CameraPose) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Position (3,) in centimetres and FQuat (4,) (x, y, z, w) of an Unreal camera (which looks
    down its local +X, +Z up, +Y right) showing what ``pose`` shows. Unreal's
    ``UCameraComponent::FieldOfView`` is horizontal: see :func:`horizontal_fov_deg`.
    """
    pose = _as_pose(pose)
    # Our camera's forward, right and up (-Z, +X, +Y) are Unreal's +X, +Y, +Z under this map.
    return to_unreal_position(pose.position), to_unreal_rotation(pose.rotation_xyzw)


def horizontal_fov_deg(vertical_fov_deg: float, aspect: float) -> float:
    """Horizontal field of view in degrees of a vertical one at ``aspect`` = width / height."""
    half = math.radians(vertical_fov_deg) / 2.0
    return math.degrees(2.0 * math.atan(math.tan(half) * aspect))


# --- messages from arrays ----------------------------------------------------------------------


def vec3(v: ArrayLike) -> pb.Vec3:
    """A ``Vec3`` from three numbers."""
    x, y, z = (float(c) for c in np.asarray(v, dtype=np.float64).reshape(3))
    return pb.Vec3(x=x, y=y, z=z)


def quat(q: ArrayLike) -> pb.Quat:
    """A ``Quat`` from four numbers (x, y, z, w)."""
    x, y, z, w = (float(c) for c in np.asarray(q, dtype=np.float64).reshape(4))
    return pb.Quat(x=x, y=y, z=z, w=w)


def transform_msg(position: ArrayLike, rotation_xyzw: ArrayLike | None = None, scale: ArrayLike | None = None) -> pb.Transform:
    """A ``Transform``; a rotation or scale left as None stays unset (identity, (1, 1, 1))."""
    msg = pb.Transform(position=vec3(position))
    if rotation_xyzw is not None:
        msg.rotation.CopyFrom(quat(rotation_xyzw))
    if scale is not None:
        msg.scale.CopyFrom(vec3(scale))
    return msg


def mesh_from_arrays(vertices: ArrayLike, faces: ArrayLike, *, flip_winding: bool = False) -> pb.Mesh:
    """A triangle ``Mesh`` from vertices ``(n, 3)`` (metres, local frame) and faces ``(m, 3)`` int.

    ``flip_winding=True`` reverses each triangle's vertex order (for triangles from Unity or
    Unreal, see the module docstring). Faces must index existing vertices.
    """
    v = np.asarray(vertices, dtype=np.float32)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be (n, 3), got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must be (m, 3), got shape {f.shape}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integers, got {f.dtype}")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"faces must index vertices in [0, {len(v)}), got [{f.min()}, {f.max()}]")
    if flip_winding:
        f = f[:, [0, 2, 1]]
    triangles = pb.TriangleMesh(vertices=v.ravel().tolist(), indices=f.astype(np.uint32).ravel().tolist())
    return pb.Mesh(triangles=triangles)


def pack_states(
    ids: Sequence[str],
    positions: ArrayLike,
    rotations: ArrayLike,
    scales: ArrayLike | None = None,
) -> tuple[list[str], NDArray[np.float64]]:
    """The bulk form of object states, for ``FrameUpdate.packed_ids`` and ``packed_transforms``.

    Parameters
    ----------
    ids : (n,) str
        Ids of targets or dynamic objects.
    positions : (n, 3) float
        World positions, metres.
    rotations : (n, 4) float
        World rotations, quaternions (x, y, z, w).
    scales : (n, 3) float or None
        Local scales; None means (1, 1, 1) for all.

    Returns
    -------
    packed_ids : list of str, length n
    packed_transforms : (n * 10,) float64
        Per id: px, py, pz, qx, qy, qz, qw, sx, sy, sz.
    """
    packed_ids = list(ids)
    if not all(isinstance(i, str) for i in packed_ids):
        raise TypeError("ids must be strings")
    n = len(packed_ids)
    p = np.asarray(positions, dtype=np.float64)
    q = np.asarray(rotations, dtype=np.float64)
    if p.shape != (n, 3):
        raise ValueError(f"positions must be ({n}, 3) for {n} ids, got shape {p.shape}")
    if q.shape != (n, 4):
        raise ValueError(f"rotations must be ({n}, 4) for {n} ids, got shape {q.shape}")
    packed = np.empty((n, PACKED_WIDTH))
    packed[:, 0:3] = p
    packed[:, 3:7] = q
    if scales is None:
        packed[:, 7:10] = 1.0
    else:
        s = np.asarray(scales, dtype=np.float64)
        if s.shape != (n, 3):
            raise ValueError(f"scales must be ({n}, 3) for {n} ids, got shape {s.shape}")
        packed[:, 7:10] = s
    return packed_ids, packed.reshape(-1)


def unpack_states(
    packed_ids: Sequence[str], packed_transforms: Sequence[float] | Any
) -> tuple[list[str], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Inverse of :func:`pack_states`: ids, positions (n, 3), rotations (n, 4), scales (n, 3)."""
    ids = list(packed_ids)
    packed = np.asarray(packed_transforms, dtype=np.float64)
    if packed.size != PACKED_WIDTH * len(ids):
        raise ValueError(f"{len(ids)} ids need {PACKED_WIDTH * len(ids)} doubles, got {packed.size}")
    packed = packed.reshape(len(ids), PACKED_WIDTH)
    return ids, packed[:, 0:3].copy(), packed[:, 3:7].copy(), packed[:, 7:10].copy()
