"""Whether camera places lie in a level's playable space: outside the level, inside solid, or inside.

- **Outside**: beyond the level mesh's axis-aligned bounding box (its vertices' minima and maxima
  per world axis, no margin), but for a level open to the sky (an outdoor terrain: under
  `OPEN_CEILING_SHARE` of its area in faces turned down), whose box has no top: above its highest
  hill is the sky a camera may stand in, judged by its rays as any point (on Recast's undulating
  terrain the box's top pulled 19-38% of the program's frames down toward their players, and kill
  coverage fell 0.931 -> 0.552). Game levels are closed where players can go, so nothing a camera
  should show lies past the box: a camera there looks at the level from outside (against the sky
  of a renderer, or the void). The box, not the convex hull, because it costs six comparisons,
  and a level's outer walls and floors stand on axis-aligned planes in every level we have (Quake
  maps are built from axis-aligned brushes; the OBJ levels' extremes are their floors and walls).
- **Solid**: inside the box but where a player could not be: inside a wall, a floor, a pillar, or
  in the void between a map's rooms. `RAYS` rays leave the point in fixed directions spread over
  the sphere; each that meets the mesh meets its first face either from the front (the side the
  face's normal points to) or from behind. The point is solid when more rays meet a face from
  behind than from the front, or when no ray meets anything.
- **Inside**: the rest.

Why back faces: a level mesh is not watertight (Quake's BSP compiler keeps only the faces that
border the playable space, sky, liquid and tool faces are left out by bsp.py; OBJ levels are
open at the top and have faces missing), so a parity (inside-outside) count fails. But its faces
face into the playable space: Quake's BSP faces face the empty leaves they border (bsp.py winds
its triangles counter-clockwise from that side), and the OBJ levels of ../shared/data/levels
(Recast's test meshes, Sauerbraten's zdm2) face their floors up and their walls into the rooms,
the side a game renders (back faces are culled). So from a point in the playable space a ray
meets faces from the front; from inside a wall slab it meets the slab's own faces from behind;
from the void between rooms it meets the rooms' walls from behind. A ray that meets nothing (up
through a missing sky, out of an open level) says nothing and is not counted: that is why the
vote is among the rays that hit, and why the box, not the vote, decides "outside". A point above
a courtyard whose sky the mesh leaves out, below the box's top, reads inside (only the floor
below meets its rays): this test cannot see sky that is not in the mesh.

Costs: one Embree scene of the mesh per level (`LevelInterior.of` caches it while the mesh
lives) and `RAYS` rays per point, in one call for all the points asked about.
"""

from __future__ import annotations

import enum
import threading
import weakref
from typing import ClassVar

import numpy as np
import numpy.typing as npt
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from camdirector.geometry.meshes import TriMesh

RAYS = 14  # directions per point: enough that a grazing ray or a missing face rarely tips the vote
OPEN_CEILING_SHARE = 0.05  # a level with less of its area in ceilings is open above (Quake maps 14-20%, the open
# terrain of ../shared/data/levels' undulating 1.3%, nav_test 38%)


class Place(enum.IntEnum):
    """Where a point is (module docstring)."""

    INSIDE = 0
    OUTSIDE = 1
    SOLID = 2


def sphere_directions(count: int) -> npt.NDArray[np.float64]:
    """(count, 3) unit vectors spread evenly over the sphere (a Fibonacci lattice). None is axis
    aligned, so no ray runs along an axis-aligned wall or floor (a coin toss for Embree)."""
    k = np.arange(count) + 0.5
    y = 1.0 - 2.0 * k / count
    radius = np.sqrt(1.0 - y * y)
    angle = np.pi * (3.0 - np.sqrt(5.0)) * k + 0.5  # turns the lattice off the axes: every ray 20 deg or more from each
    return np.stack([radius * np.cos(angle), y, radius * np.sin(angle)], axis=1)


def open_above(mesh: TriMesh) -> bool:
    """Whether the level is open to the sky (module docstring): faces turned down (ceilings,
    roofs' undersides: normal's y under -0.5) make under OPEN_CEILING_SHARE of its area."""
    v, f = mesh.vertices, mesh.faces
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # length: twice the face's area
    areas = np.linalg.norm(normals, axis=1)
    down = normals[:, 1] < -0.5 * areas
    return bool(areas[down].sum() < OPEN_CEILING_SHARE * max(areas.sum(), 1e-12))


class LevelInterior:
    """The places test of one level mesh (module docstring). Pickles as its mesh."""

    _cache: ClassVar[dict[int, tuple[weakref.ref[TriMesh], LevelInterior]]] = {}  # id(mesh) -> (the mesh, its interior)
    _cache_lock: ClassVar[threading.Lock] = threading.Lock()

    def __init__(self, mesh: TriMesh, rays: int = RAYS):
        self.mesh = mesh
        self.low, self.high = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)  # (3,) m: the box
        if open_above(mesh):
            self.high = np.array([self.high[0], np.inf, self.high[2]])  # the sky is the level's own
        self.directions = sphere_directions(rays)  # (rays, 3)
        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self._scene, mesh.vertices.astype(np.float32), mesh.faces)

    @classmethod
    def of(cls, mesh: TriMesh) -> LevelInterior:
        """The interior of the mesh, built once while the mesh object lives (the worker's level
        cache keeps one mesh per level: every session on it shares one Embree scene)."""
        with cls._cache_lock:
            cached = cls._cache.get(id(mesh))
            if cached is not None and cached[0]() is mesh:
                return cached[1]
            interior = cls(mesh)
            key = id(mesh)
            cls._cache[key] = (weakref.ref(mesh, lambda _: cls._cache.pop(key, None)), interior)
            return interior

    def __reduce__(self) -> tuple[type[LevelInterior], tuple[TriMesh, int]]:
        return LevelInterior, (self.mesh, len(self.directions))

    def places(self, points_world: npt.ArrayLike) -> npt.NDArray[np.int8]:
        """(n,) int8 `Place` of each point (n, 3) m (module docstring)."""
        points = np.atleast_2d(np.asarray(points_world, dtype=np.float64))
        out = np.full(len(points), Place.INSIDE, dtype=np.int8)
        outside = np.any((points < self.low) | (points > self.high), axis=1)
        out[outside] = Place.OUTSIDE
        rest = np.flatnonzero(~outside)
        if len(rest):
            m = len(self.directions)
            origins = np.repeat(points[rest], m, axis=0).astype(np.float32)
            directions = np.tile(self.directions, (len(rest), 1))
            answer = self._scene.run(origins, directions.astype(np.float32), output=1)
            hit = (answer["geomID"] >= 0).reshape(-1, m)
            # Embree's Ng is (v1 - v0) x (v2 - v0): the face's front normal for counter-clockwise winding
            behind = ((answer["Ng"].astype(np.float64) * directions).sum(axis=1) > 0.0).reshape(-1, m) & hit
            back, front = behind.sum(axis=1), (hit & ~behind).sum(axis=1)
            out[rest[(back > front) | ~hit.any(axis=1)]] = Place.SOLID
        return out

    def reach(self, origins_world: npt.ArrayLike, targets_world: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(n,) the share of each segment from origin to target, (n, 3) m each (an origin may be
        (3,)), before it first meets a level face (1 where it meets none): how far toward its
        target a camera can go without passing through the level."""
        targets = np.atleast_2d(np.asarray(targets_world, dtype=np.float64))
        origins = np.broadcast_to(np.asarray(origins_world, dtype=np.float64), targets.shape)
        t = self._scene.run(origins.astype(np.float32), (targets - origins).astype(np.float32), query="DISTANCE")
        reach: npt.NDArray[np.float64] = np.minimum(t.astype(np.float64), 1.0)
        return reach

    def bad(self, points_world: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """(n,) bool: whether each point (n, 3) m is outside the level or inside solid."""
        bad: npt.NDArray[np.bool_] = self.places(points_world) != Place.INSIDE
        return bad
