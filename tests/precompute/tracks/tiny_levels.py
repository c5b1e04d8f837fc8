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
    return boxes(
        ((0, -0.2, 0), (length, 0, width)), ((0, 0, -0.1), (length, wall, 0)), ((0, 0, width), (length, wall, width + 0.1))
    )


def l_room() -> TriMesh:
    """An L of two 4 m wide corridors: along x (z in 0..4) and along z (x in 0..4)."""
    return boxes(
        ((0, -0.2, 0), (24, 0, 4)),
        ((0, -0.2, 4), (4, 0, 24)),
        ((0, 0, -0.1), (24, 3, 0)),
        ((24, 0, 0), (24.1, 3, 4)),
        ((4, 0, 4), (24, 3, 4.1)),
        ((-0.1, 0, 0), (0, 3, 24)),
        ((4, 0, 4), (4.1, 3, 24)),
        ((0, 0, 24), (4, 3, 24.1)),
    )


def two_floors() -> TriMesh:
    """A 20 x 8 ground floor and, 4 m above, a 20 x 4 gallery over half of it."""
    return boxes(((0, -0.2, 0), (20, 0, 8)), ((0, 3.8, 4), (20, 4, 8)))


def two_open_floors() -> TriMesh:
    """Two wall-less 20 x 8 and 6 x 6 slabs (top at y=0), 22 m apart along z: further than the
    visibility range, so nothing above one sees the other."""
    return boxes(((0, -0.2, 0), (20, 0, 8)), ((0, -0.2, 30), (6, 0, 36)))


def two_rooms(wall=0.02) -> TriMesh:
    """Two 12 x 12 rooms (x in 0..12 and 20..32, z in 0..12) joined by a corridor 8 m long and 2.4 m
    wide (x in 12..20, z in 4.8..7.2), 3 m walls `wall` thick all round: the tops of 2 cm walls are
    too small a region to walk on, though they meet."""
    floors = [((0, -0.2, 0), (12, 0, 12)), ((12, -0.2, 4.8), (20, 0, 7.2)), ((20, -0.2, 0), (32, 0, 12))]
    walls = [
        ((-wall, 0, 0), (0, 3, 12)),
        ((32, 0, 0), (32 + wall, 3, 12)),  # the far ends
        ((12, 0, 4.8 - wall), (20, 3, 4.8)),
        ((12, 0, 7.2), (20, 3, 7.2 + wall)),
    ]  # the corridor's sides
    for x0 in (0.0, 20.0):  # each room's long sides
        walls += [((x0, 0, -wall), (x0 + 12, 3, 0)), ((x0, 0, 12), (x0 + 12, 3, 12 + wall))]
    for x in (12.0, 20.0 - wall):  # the walls between the rooms and the corridor, either side of its door
        walls += [((x, 0, 0), (x + wall, 3, 4.8)), ((x, 0, 7.2), (x + wall, 3, 12))]
    return boxes(*floors, *walls)
