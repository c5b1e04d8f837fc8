"""Hand-built levels for the camera-tracks tests: boxes in metres, +Y up."""
from __future__ import annotations

import numpy as np

from camdirector.geometry.meshes import TriMesh, box


def boxes(*specs) -> TriMesh:
    """One mesh of axis-aligned boxes, each (min_xyz, max_xyz)."""
    vertices, faces = [], []
    for lo, hi in specs:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        b = box(hi - lo)
        faces.append(b.faces + sum(len(v) for v in vertices))
        vertices.append(b.vertices + (lo + hi) / 2.0)
    return TriMesh(np.vstack(vertices), np.vstack(faces).astype(np.int32))


def corridor(length=30.0, width=4.0, wall=3.0) -> TriMesh:
    """Floor slab top at y=0 along x, 10 cm walls on both sides (z = 0 and z = width): their tops
    are too small a region to walk on."""
    return boxes(((0, -0.2, 0), (length, 0, width)), ((0, 0, -0.1), (length, wall, 0)),
                 ((0, 0, width), (length, wall, width + 0.1)))


def l_room() -> TriMesh:
    """An L of two 4 m wide corridors: along x (z in 0..4) and along z (x in 0..4)."""
    return boxes(((0, -0.2, 0), (24, 0, 4)), ((0, -0.2, 4), (4, 0, 24)),
                 ((0, 0, -0.1), (24, 3, 0)), ((24, 0, 0), (24.1, 3, 4)), ((4, 0, 4), (24, 3, 4.1)),
                 ((-0.1, 0, 0), (0, 3, 24)), ((4, 0, 4), (4.1, 3, 24)), ((0, 0, 24), (4, 3, 24.1)))


def two_floors() -> TriMesh:
    """A 20 x 8 ground floor and, 4 m above, a 20 x 4 gallery over half of it."""
    return boxes(((0, -0.2, 0), (20, 0, 8)), ((0, 3.8, 4), (20, 4, 8)))


def two_open_floors() -> TriMesh:
    """Two wall-less 20 x 8 and 6 x 6 slabs (top at y=0), 22 m apart along z: further than the
    visibility range, so nothing above one sees the other."""
    return boxes(((0, -0.2, 0), (20, 0, 8)), ((0, -0.2, 30), (6, 0, 36)))
