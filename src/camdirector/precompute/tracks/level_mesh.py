"""Level geometry from a file, converted to metres once, here.

Levels come in their own units (a Sauerbraten map in Cube 2 units of about 0.12 m); every later
stage works in metres, world frame, +Y up, so `m_per_unit` is applied at this one boundary.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from camdirector.geometry.meshes import MeshError, TriMesh, from_glb, from_obj

LEVEL_SUFFIXES = (".obj", ".glb")


def load_level_mesh(path: Path, m_per_unit: float = 1.0) -> TriMesh:
    """Triangles of an OBJ or binary glTF file, scaled by m_per_unit to metres (world frame, +Y up).

    Raises MeshError for an unknown suffix, an unreadable file or a mesh without triangles, and
    ValueError for a non-positive scale.
    """
    if not (np.isfinite(m_per_unit) and m_per_unit > 0.0):
        raise ValueError(f"scale must be a positive number of metres per unit, got {m_per_unit}")
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in LEVEL_SUFFIXES:
        raise MeshError(f"{path.name}: a level must be one of {', '.join(LEVEL_SUFFIXES)}")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MeshError(f"cannot read {path}: {exc.strerror}") from None
    mesh = from_obj(data) if suffix == ".obj" else from_glb(data)
    return TriMesh(vertices=mesh.vertices * float(m_per_unit), faces=mesh.faces)
