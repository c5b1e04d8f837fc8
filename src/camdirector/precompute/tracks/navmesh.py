"""The navigation mesh: derived from a level's walkable surfaces when none is given, and its
connectivity (shared by the skeleton's layers and the actor's routes).

Derivation, in the spirit of Recast (rcMarkWalkableTriangles, rcFilterWalkableLowHeightSpans,
rcErodeWalkableArea, rcBuildRegions with minRegionArea), on triangles instead of voxels:

1. walkable: triangles whose up-facing normal is within `agent_max_slope_deg` of +Y (the file's
   winding decides up, as in Recast);
2. tested on cells: steps 3 and 4 run at the centroids of cells no wider than `navmesh_cell_m`
   over each walkable triangle; mixed triangles are bisected and tested again (derive_navmesh);
3. head clearance: a ray straight up of `agent_height_m` from a cell centroid must hit nothing;
4. erosion: eight horizontal rays of `agent_radius_m`, cast just above `agent_max_climb_m` (so a
   step lower than the climb is not a wall), must hit nothing;
5. regions: triangles are connected through shared vertices and through vertices stacked within
   `agent_max_climb_m` of each other (steps); regions smaller than `min_region_area_m2` go.

Limits (documented, not hidden): the resolution is a triangle of `navmesh_cell_m`, not Recast's
0.3 m voxel, so walls erode in steps of that size; ledges without a wall are not eroded; a gap
narrower than the agent between two walls survives when no centroid lands within a radius of
either wall; steps connect only where their edges' vertices stack within half a cell; winding
decides which side is up, so a level with flipped floors yields no walkable surface there.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from camdirector.geometry.meshes import MeshError, TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import UP_WORLD
from camdirector.precompute.tracks.track_settings import TrackSettings

_WELD_M = 1e-4  # vertices closer than this are one vertex
_SURFACE_LIFT_M = 0.05  # clearance rays start this far above the surface
_EROSION_RAYS = 8


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m,) float64 areas in m^2 of faces (m, 3) over vertices (n, 3)."""
    t = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


def refine_triangles(
    vertices: np.ndarray, faces: np.ndarray, *, max_edge_m: float = np.inf, max_area_m2: float = np.inf, max_rounds: int = 64
) -> tuple[np.ndarray, np.ndarray]:
    """Longest-edge bisection: split each triangle with an edge longer than max_edge_m or an area
    over max_area_m2 in two at the midpoint of its longest edge, until none is left (midpoints
    shared between triangles split on the same edge; T-junctions remain where a split triangle
    meets an unsplit one). Winding is kept; slivers shrink without multiplying.

    vertices (n, 3) float64, faces (m, 3) int -> (vertices (n', 3), faces (m', 3) int64).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    for _ in range(max_rounds):
        t = v[f]
        edge = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2)  # (m, 3): edges 01, 12, 20
        big = (edge.max(axis=1) > max_edge_m) | (triangle_areas(v, f) > max_area_m2)
        if not big.any():
            break
        fb = f[big]
        longest = edge[big].argmax(axis=1)
        rolled = np.take_along_axis(fb, (longest[:, None] + np.arange(3)) % 3, axis=1)  # longest edge is 0-1
        unique, inverse = np.unique(np.sort(rolled[:, :2], axis=1), axis=0, return_inverse=True)
        mid = len(v) + inverse.reshape(-1)
        v = np.vstack([v, 0.5 * (v[unique[:, 0]] + v[unique[:, 1]])])
        a, b, c = rolled.T
        f = np.vstack([f[~big], np.stack([a, mid, c], axis=1), np.stack([mid, b, c], axis=1)])
    return v, f


def weld_vertices(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices within 0.1 mm; returns (unique vertices (k, 3), faces (m, 3) remapped)."""
    key = np.round(vertices / _WELD_M).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return vertices[first], inverse.reshape(-1)[faces]


def triangle_adjacency(navmesh: TriMesh, climb_m: float, link_m: float) -> sparse.csr_matrix:
    """(m, m) bool adjacency of navmesh triangles: sharing a vertex (after welding), or holding
    vertices within link_m of each other horizontally and climb_m vertically (steps)."""
    vertices, faces = weld_vertices(navmesh.vertices, navmesh.faces)
    m, n = len(faces), len(vertices)
    incidence = sparse.csr_matrix((np.ones(3 * m, dtype=np.int32), (np.repeat(np.arange(m), 3), faces.reshape(-1))), shape=(m, n))
    pairs = cKDTree(vertices[:, [0, 2]]).query_pairs(link_m, output_type="ndarray") if link_m > 0 else np.empty((0, 2), int)
    if len(pairs):
        pairs = pairs[np.abs(vertices[pairs[:, 0], 1] - vertices[pairs[:, 1], 1]) <= climb_m]
    links = sparse.coo_matrix(
        (
            np.ones(2 * len(pairs), dtype=np.int32),
            (np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]])),
        ),
        shape=(n, n),
    ).tocsr() + sparse.identity(n, dtype=np.int32, format="csr")
    return ((incidence @ links @ incidence.T) > 0).tocsr()


def navmesh_components(navmesh: TriMesh, settings: TrackSettings) -> np.ndarray:
    """(m,) int connected-region label of each navmesh triangle (steps up to the climb connect)."""
    adjacency = triangle_adjacency(navmesh, settings.agent_max_climb_m, 0.5 * settings.navmesh_cell_m)
    return connected_components(adjacency, directed=False)[1]


def _compact(vertices: np.ndarray, faces: np.ndarray) -> TriMesh:
    used, remapped = np.unique(faces.reshape(-1), return_inverse=True)
    return TriMesh(vertices=vertices[used], faces=remapped.reshape(-1, 3).astype(np.int32))


def _lattice_centroids(triangles: np.ndarray, n: int) -> np.ndarray:
    """Centroids of the n^2 sub-triangles of a regular n-split of each triangle: (k, 3, 3) -> (k, n^2, 3)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = (i + j) <= n - 1
    down = (i + j) <= n - 2
    bary = (
        np.concatenate([np.stack([i[up] + 1 / 3, j[up] + 1 / 3], axis=1), np.stack([i[down] + 2 / 3, j[down] + 2 / 3], axis=1)])
        / n
    )  # (n^2, 2)
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return a[:, None] + bary[None, :, :1] * (b - a)[:, None] + bary[None, :, 1:] * (c - a)[:, None]


def _room_for_agent(points: np.ndarray, scene: RayScene, settings: TrackSettings) -> np.ndarray:
    """(k,) bool: head clearance and agent radius free around walkable points (k, 3) (steps 3, 4)."""
    lifted = points + _SURFACE_LIFT_M * UP_WORLD
    ok = ~scene.occluded(lifted, lifted + (settings.agent_height_m - _SURFACE_LIFT_M) * UP_WORLD)
    if settings.agent_radius_m > 0.0 and ok.any():
        probe_height = min(settings.agent_max_climb_m + _SURFACE_LIFT_M, 0.9 * settings.agent_height_m)
        angles = np.arange(_EROSION_RAYS) * (2.0 * np.pi / _EROSION_RAYS)
        ring = settings.agent_radius_m * np.stack([np.cos(angles), np.zeros_like(angles), np.sin(angles)], axis=1)
        idx = np.flatnonzero(ok)
        origins = np.repeat(points[idx] + probe_height * UP_WORLD, _EROSION_RAYS, axis=0)
        blocked = scene.occluded(origins, origins + np.tile(ring, (len(idx), 1))).reshape(-1, _EROSION_RAYS)
        ok[idx[blocked.any(axis=1)]] = False
    return ok


def derive_navmesh(level: TriMesh, scene: RayScene, settings: TrackSettings) -> TriMesh:
    """Walkable surfaces of a level (metres, world frame) as a navigation mesh (module docstring).

    The tests of steps 3 and 4 run at the centroids of a lattice of cells no wider than
    `navmesh_cell_m` over each walkable triangle: a triangle whose cells all pass is kept whole,
    one whose cells all fail goes, and a mixed one is bisected at its longest edge and tested
    again, down to `navmesh_cell_m` (there its centroid decides). So open floors stay coarse and
    only the outlines are fine. scene: a RayScene of the same level. Raises MeshError when
    nothing is walkable.
    """
    vertices, faces = weld_vertices(level.vertices, level.faces.astype(np.int64))
    t = vertices[faces]
    normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    walkable = normal[:, 1] >= np.cos(np.radians(settings.agent_max_slope_deg))
    if not walkable.any():
        raise MeshError("no walkable surface: no triangle faces up within the slope limit")
    pending = faces[walkable]
    kept: list[np.ndarray] = []
    while len(pending):
        t = vertices[pending]
        longest = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2).max(axis=1)
        splits = np.clip(np.ceil(longest / settings.navmesh_cell_m), 1, 64).astype(int)
        all_ok = np.zeros(len(pending), dtype=bool)
        any_ok = np.zeros(len(pending), dtype=bool)
        for n in np.unique(splits):
            sel = np.flatnonzero(splits == n)
            ok = _room_for_agent(_lattice_centroids(t[sel], n).reshape(-1, 3), scene, settings).reshape(len(sel), -1)
            all_ok[sel], any_ok[sel] = ok.all(axis=1), ok.any(axis=1)
        kept.append(pending[all_ok])
        mixed = any_ok & ~all_ok & (splits > 1)
        vertices, bisected = refine_triangles(vertices, pending[mixed], max_edge_m=0.0, max_rounds=1)
        pending = bisected
    faces = np.concatenate(kept) if kept else np.empty((0, 3), np.int64)
    if not len(faces):
        raise MeshError("no walkable surface: every walkable triangle lacks head clearance or agent room")
    candidate = _compact(vertices, faces)
    label = navmesh_components(candidate, settings)
    area = np.bincount(label, weights=triangle_areas(candidate.vertices, candidate.faces))
    big = area[label] >= settings.min_region_area_m2
    if not big.any():
        raise MeshError(f"no walkable region of at least {settings.min_region_area_m2} m^2")
    return _compact(candidate.vertices, candidate.faces[big])
