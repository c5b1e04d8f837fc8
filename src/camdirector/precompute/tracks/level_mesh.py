"""Level geometry from a file, converted to metres once, here.

Levels come in their own units (a Sauerbraten map in Cube 2 units of about 0.12 m); every later
stage works in metres, world frame, +Y up, so `m_per_unit` is applied at this one boundary. A
Quake BSP map (.bsp) is already in metres and world axes when decoded (geometry/bsp.py: 1/32 m
per Quake unit, Z up turned to Y up), so its scale stays 1 unless a different size is wanted.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from camdirector.geometry.bsp import from_bsp
from camdirector.geometry.meshes import MeshError, TriMesh, from_glb, from_obj

# Suffix -> decoder of the file's bytes; OBJ is text, the others binary.
_DECODERS = {".obj": from_obj, ".glb": from_glb, ".bsp": from_bsp}
LEVEL_SUFFIXES = tuple(_DECODERS)


def decode_level_mesh(data: bytes, suffix: str) -> TriMesh:
    """Triangles of a level file's bytes by its suffix (LEVEL_SUFFIXES, lower case), in the file's
    units (metres, world frame, for .bsp). Raises MeshError for an unknown suffix or a bad file."""
    decoder = _DECODERS.get(suffix)
    if decoder is None:
        raise MeshError(f"a level must be one of {', '.join(LEVEL_SUFFIXES)}, not {suffix!r}")
    return decoder(data)


def load_level_mesh(path: Path, m_per_unit: float = 1.0) -> TriMesh:
    """Triangles of an OBJ, binary glTF or Quake BSP file, scaled by m_per_unit to metres (world
    frame, +Y up). A .bsp is decoded in metres already, so m_per_unit multiplies those (1: as is).

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
    mesh = decode_level_mesh(data, suffix)
    return TriMesh(vertices=mesh.vertices * float(m_per_unit), faces=mesh.faces)
