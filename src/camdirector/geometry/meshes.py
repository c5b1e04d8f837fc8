"""Triangle meshes: decoding (glTF binary, OBJ, raw arrays, primitives) and validation.

Every constructor returns a `TriMesh` in the object's local frame, or raises `MeshError` with a
message fit for a client.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import trimesh

# Triangles with a smaller area are dropped: they hide nothing and upset ray casting.
MIN_TRIANGLE_AREA_M2 = 1e-14


class MeshError(ValueError):
    """A mesh that cannot be used, with the reason."""


@dataclass(frozen=True)
class TriMesh:
    """vertices: (n, 3) float64 metres, local frame; faces: (m, 3) int32 indices into vertices."""

    vertices: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int32]

    @property
    def triangle_count(self) -> int:
        return int(self.faces.shape[0])


def from_arrays(vertices: npt.ArrayLike, faces: npt.ArrayLike) -> TriMesh:
    """Validated mesh from flat or shaped arrays: vertices (3n,) or (n, 3), faces (3m,) or (m, 3).

    Non-finite coordinates, out-of-range indices and meshes without one proper triangle are
    refused; zero-area triangles are dropped.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim == 1:
        if v.size % 3:
            raise MeshError(f"vertex array length {v.size} is not a multiple of 3")
        v = v.reshape(-1, 3)
    if f.ndim == 1:
        if f.size % 3:
            raise MeshError(f"index array length {f.size} is not a multiple of 3")
        f = f.reshape(-1, 3)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise MeshError("vertices must be (n, 3) and faces (m, 3)")
    if f.shape[0] == 0 or v.shape[0] == 0:
        raise MeshError("mesh is empty: no triangles")
    if not np.all(np.isfinite(v)):
        raise MeshError("mesh has NaN or infinite vertex coordinates")
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise MeshError(f"triangle index out of range (mesh has {v.shape[0]} vertices)")
    tri = v[f]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    keep = area2 > 2.0 * MIN_TRIANGLE_AREA_M2
    if not np.any(keep):
        raise MeshError("mesh is degenerate: every triangle has zero area")
    return TriMesh(vertices=v, faces=f[keep].astype(np.int32))


def _from_trimesh_file(data: bytes, file_type: str) -> TriMesh:
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=file_type, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types on bad input
        raise MeshError(f"cannot parse {file_type} mesh: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(f"{file_type} payload holds no triangles")
    return from_arrays(loaded.vertices, loaded.faces)


def from_glb(data: bytes) -> TriMesh:
    """All triangle primitives of a binary glTF 2.0 file, node transforms applied."""
    if len(data) < 12 or data[:4] != b"glTF":
        raise MeshError("glb payload does not start with the glTF magic")
    return _from_trimesh_file(data, "glb")


def from_obj(data: bytes) -> TriMesh:
    """Wavefront OBJ text; polygons are fan-triangulated."""
    return _from_trimesh_file(data, "obj")


def _positive(**values: float) -> None:
    for name, value in values.items():
        if not (np.isfinite(value) and value > 0):
            raise MeshError(f"primitive {name} must be a positive finite number, got {value}")


# trimesh builds cylinders and capsules along +Z; our primitives stand along +Y. (trimesh leaves
# rotation_matrix unannotated: the name below says what it takes and returns.)
_rotation_matrix: Callable[[float, list[float]], npt.NDArray[np.float64]] = trimesh.transformations.rotation_matrix
_Z_TO_Y = _rotation_matrix(-np.pi / 2.0, [1.0, 0.0, 0.0])


def _stood_up(m: trimesh.Trimesh, portable: bool) -> TriMesh:
    """A +Z mesh of trimesh's turned to stand along +Y. `portable` (the compiled frame path) turns
    it exactly, (x, y, z) -> (x, z, -y), the same bits on every machine; otherwise by _Z_TO_Y's
    product, as always (its cos(-pi/2) is 6e-17, not 0, and the product goes through OpenBLAS,
    whose kernel, and so the last bits, is the CPU's)."""
    if portable:
        v = m.vertices
        return from_arrays(np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1), m.faces)
    m.apply_transform(_Z_TO_Y)
    return from_arrays(m.vertices, m.faces)


def box(size_xyz: Iterable[float]) -> TriMesh:
    """Axis-aligned box of full extents size_xyz (3,) metres, centred on the origin."""
    sx, sy, sz = (float(s) for s in size_xyz)
    _positive(size_x=sx, size_y=sy, size_z=sz)
    m = trimesh.creation.box(extents=(sx, sy, sz))
    return from_arrays(m.vertices, m.faces)


def sphere(radius_m: float) -> TriMesh:
    _positive(radius=radius_m)
    m = trimesh.creation.icosphere(subdivisions=2, radius=radius_m)
    return from_arrays(m.vertices, m.faces)


def cylinder(radius_m: float, height_m: float, sections: int = 24, portable: bool = False) -> TriMesh:
    """Cylinder along +Y; portable: stood up exactly (`_stood_up`)."""
    _positive(radius=radius_m, height=height_m)
    return _stood_up(trimesh.creation.cylinder(radius=radius_m, height=height_m, sections=sections), portable)


def capsule(radius_m: float, height_m: float, portable: bool = False) -> TriMesh:
    """Capsule of total height height_m (caps included) along +Y; portable: stood up exactly (`_stood_up`)."""
    _positive(radius=radius_m, height=height_m)
    if height_m < 2.0 * radius_m:
        raise MeshError("capsule height must be at least twice its radius")
    return _stood_up(trimesh.creation.capsule(height=height_m - 2.0 * radius_m, radius=radius_m, count=[16, 8]), portable)
