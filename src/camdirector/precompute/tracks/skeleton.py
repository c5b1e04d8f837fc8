"""Skeleton of the navigation mesh (Section 4.1): straight skeletons of its floor layers.

The paper takes the straight skeleton [Aichholzer et al. 1996] of the navmesh projected on the
ground plane where the projection does not overlap itself, and a mean curvature skeleton
[Tagliasacchi et al. 2012] of the extruded navmesh where floors overlap. We keep the straight
skeleton for both cases and make every input single-layer first (our documented equivalent of
the curve skeleton, as Recast's heightfield layers do for tiling):

1. layers: connected navmesh triangles are flood-filled into layers; a triangle joins the layer
   being grown unless its ground projection overlaps (by more than 1 cm^2) a triangle already in
   it at a height differing by more than the agent's climb. A multi-storey component becomes
   several layers (cut somewhere on its ramps or stairs); a flat one stays one layer;
2. outline: each layer's triangles are projected and merged into polygons with holes (shapely),
   cracks of T-junctions closed by a 1 cm closing, holes under `skeleton_min_hole_m2` filled (the
   slivers a derived navmesh leaves between its triangles, and posts thinner than the agent:
   each would ring the skeleton with a loop of tiny segments), outlines simplified by
   `skeleton_simplify_m`;
3. skeleton: SFCGAL's `approximate_medial_axis` (pysfcgal), the straight skeleton of each polygon
   without the arcs that end on the outline's vertices, then reduced to the topology the paper
   wants from it (corridors, intersections, forks, dead ends; Section 4.1), our documented
   cleanup: (a) spokes are pruned, repeatedly: a dead-end chain that reaches less than
   `skeleton_prune_m` beyond its junction's clearance (its distance to the outline) only runs
   into a niche or a bump of the wall, where a real dead end runs on past it (of a junction
   that has nothing but spokes, a room's star, the two longest stay: its line); (b) the chains
   between junctions and ends are simplified by Douglas-Peucker to
   `skeleton_line_tolerance_m`. Without (a) every niche of a wall sends rays along the corridor
   from a skeleton branch across it, and RANSAC finds short tracks across corridors; without (b)
   the medial axis of a ragged outline zigzags and its orthogonal rays scatter;
4. reprojection: skeleton vertices get the height of the layer triangle under them.

What this loses against a curve skeleton: skeleton lines stop where a layer is cut (a ramp
between two floors carries two skeleton pieces that nearly meet instead of one line); the graph's
linking step (Section 4.6 iii) joins the tracks on either side.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import shapely
from pysfcgal.geometry import Polygon as SfcgalPolygon
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from shapely.geometry.polygon import orient

from camdirector.geometry.meshes import TriMesh
from camdirector.precompute.tracks.navmesh import triangle_adjacency
from camdirector.precompute.tracks.track_settings import TrackSettings

_OVERLAP_M2 = 1e-4  # projections overlapping by less than this do not make two floors
_CLOSING_M = 0.01  # closes cracks between triangles meeting at T-junctions
_WELD_M = 1e-3  # medial axis segment ends closer than this are one vertex


@dataclass(frozen=True)
class Skeleton:
    """segments_world: (k, 2, 3) float64 metres, each a straight piece of the skeleton on the
    navmesh; layer: (k,) int the layer it lies in; triangle_layer: (m,) int layer of each navmesh
    triangle; layer_count: number of layers; outlines: per layer, its shapely polygons in (x, z)
    (`layer_outline`, which the remeshing reuses: they cost about 0.5 s on a level)."""

    segments_world: np.ndarray
    layer: np.ndarray
    triangle_layer: np.ndarray
    layer_count: int
    outlines: tuple[list, ...]

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.segments_world[:, 1] - self.segments_world[:, 0], axis=1).sum())


def _weld(segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (v, d) of segments (s, 2, d) whose ends closer than 1 mm are one, and the (s, 2)
    int vertex pairs of the segments."""
    ends = segments.reshape(-1, segments.shape[-1])
    _, first, inverse = np.unique(np.round(ends / _WELD_M).astype(np.int64), axis=0, return_index=True, return_inverse=True)
    return ends[first], inverse.reshape(-1, 2)


def segment_components(segments_world: np.ndarray) -> np.ndarray:
    """(k,) int connected component of each segment (k, 2, 3): segments meeting at an end (to 1 mm)
    are connected."""
    if not len(segments_world):
        return np.empty(0, np.int64)
    vertex = _weld(segments_world)[1]
    n = len(segments_world)
    # a graph over segments and vertices: segment i is node i, vertex v is node n + v
    rows = np.repeat(np.arange(n), 2)
    graph = sparse.coo_matrix((np.ones(2 * n), (rows, n + vertex.ravel())), shape=(n + vertex.max() + 1,) * 2)
    return connected_components(graph, directed=False)[1][:n]


def _plane_height(triangles: np.ndarray, xz: np.ndarray) -> np.ndarray:
    """Height of each triangle's plane (k, 3, 3) above the points xz (k, 2)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2, d = (b - a)[:, [0, 2]], (c - a)[:, [0, 2]], xz - a[:, [0, 2]]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    det = np.where(np.abs(det) < 1e-12, 1e-12, det)
    u = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / det
    v = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / det
    return a[:, 1] + u * (b - a)[:, 1] + v * (c - a)[:, 1]


def split_layers(navmesh: TriMesh, settings: TrackSettings) -> tuple[np.ndarray, int]:
    """(m,) int layer of each triangle and the number of layers (step 1 of the module docstring)."""
    tri = navmesh.vertices[navmesh.faces]
    polys = shapely.polygons(tri[:, :, [0, 2]])
    tree = shapely.STRtree(polys)
    i, j = tree.query(polys, predicate="intersects")
    pair = i < j
    i, j = i[pair], j[pair]
    conflicts: list[list[int]] = [[] for _ in range(len(tri))]
    if len(i):
        overlap = shapely.intersection(polys[i], polys[j])
        big = shapely.area(overlap) > _OVERLAP_M2
        i, j, overlap = i[big], j[big], overlap[big]
        centre = shapely.get_coordinates(shapely.centroid(overlap))
        dy = np.abs(_plane_height(tri[i], centre) - _plane_height(tri[j], centre))
        for a, b in zip(i[dy > settings.agent_max_climb_m].tolist(), j[dy > settings.agent_max_climb_m].tolist()):
            conflicts[a].append(b)
            conflicts[b].append(a)
    adjacency = triangle_adjacency(navmesh, settings.agent_max_climb_m, 0.5 * settings.navmesh_cell_m)
    indptr, indices = adjacency.indptr, adjacency.indices
    layer = np.full(len(tri), -1, dtype=np.int64)
    count = 0
    for seed in range(len(tri)):
        if layer[seed] >= 0:
            continue
        layer[seed] = count
        queue = deque([seed])
        while queue:
            t = queue.popleft()
            for n in indices[indptr[t] : indptr[t + 1]].tolist():
                if layer[n] < 0 and not any(layer[c] == count for c in conflicts[n]):
                    layer[n] = count
                    queue.append(n)
        count += 1
    return layer, count


def layer_outline(triangles_xz: np.ndarray, simplify_m: float, min_hole_m2: float = 0.0) -> list:
    """Shapely polygons (CCW outside, CW holes) of the union of triangles (k, 3, 2), without the
    holes smaller than min_hole_m2."""
    merged = shapely.union_all(shapely.polygons(triangles_xz)).buffer(_CLOSING_M).buffer(-_CLOSING_M)
    parts = [p for p in getattr(merged, "geoms", [merged]) if p.geom_type == "Polygon" and p.area > 1e-6]
    parts = [shapely.Polygon(p.exterior, [r for r in p.interiors if shapely.Polygon(r).area >= min_hole_m2]) for p in parts]
    if simplify_m > 0.0:
        parts = [p.simplify(simplify_m, preserve_topology=True) for p in parts]
    return [orient(p, 1.0) for p in parts if p.geom_type == "Polygon" and p.area > 1e-6]


def _chains(segments: np.ndarray) -> tuple[np.ndarray, list[list[int]]]:
    """Vertices (v, 2) of segments (s, 2, 2) joined where they share an end (to 1 mm), and the
    chains: vertex index lists that run between vertices of degree other than 2 (a closed loop
    of degree-2 vertices is one chain starting and ending at the same vertex)."""
    vertices, pairs = _weld(segments)
    pairs = np.unique(np.sort(pairs[pairs[:, 0] != pairs[:, 1]], axis=1), axis=0)
    adjacency: list[list[int]] = [[] for _ in range(len(vertices))]
    for a, b in pairs.tolist():
        adjacency[a].append(b)
        adjacency[b].append(a)
    used: set[tuple[int, int]] = set()
    chains = []
    starts = [v for v in range(len(vertices)) if len(adjacency[v]) not in (0, 2)]
    starts += [v for v in range(len(vertices)) if len(adjacency[v]) == 2]  # loops last
    for start in starts:
        for nxt in adjacency[start]:
            if (start, nxt) in used:
                continue
            chain, prev, cur = [start], start, nxt
            used.add((start, nxt))
            used.add((nxt, start))
            while True:
                chain.append(cur)
                if len(adjacency[cur]) != 2 or cur == start:
                    break
                step = adjacency[cur][0] if adjacency[cur][1] == prev else adjacency[cur][1]
                if (cur, step) in used:
                    break
                used.add((cur, step))
                used.add((step, cur))
                prev, cur = cur, step
            chains.append(chain)
    return vertices, chains


def clean_axis(segments: np.ndarray, polygon, prune_m: float, tolerance_m: float) -> np.ndarray:
    """The medial axis segments (s, 2, 2) of polygon reduced to its topology (module docstring,
    step 3): spokes pruned, chains simplified."""
    if not len(segments):
        return segments
    boundary = polygon.boundary
    while True:
        vertices, chains = _chains(segments)
        degree = np.zeros(len(vertices), dtype=np.int64)
        for chain in chains:
            degree[chain[0]] += 1
            degree[chain[-1]] += 1
        spokes_at: dict[int, list[tuple[float, int]]] = {}
        for k, chain in enumerate(chains):
            a, b = degree[chain[0]], degree[chain[-1]]
            if (a == 1) == (b == 1):
                continue  # a chain between junctions, a loop, or a lone chain: structure, kept
            junction = chain[-1] if a == 1 else chain[0]
            length = float(np.linalg.norm(np.diff(vertices[chain], axis=0), axis=1).sum())
            clearance = float(shapely.distance(shapely.Point(vertices[junction]), boundary))
            if length < clearance + prune_m:
                spokes_at.setdefault(junction, []).append((length, k))
        drop: set[int] = set()
        for junction, spokes in spokes_at.items():
            spokes.sort()
            if len(spokes) == degree[junction]:
                spokes = spokes[:-2]  # a star of spokes only (a room): its two longest make its line
            drop.update(k for _, k in spokes)
        if not drop:
            break
        segments = np.asarray(
            [[vertices[c[i]], vertices[c[i + 1]]] for k, c in enumerate(chains) if k not in drop for i in range(len(c) - 1)],
            dtype=np.float64,
        ).reshape(-1, 2, 2)
        if not len(segments):
            return segments
    out: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] = []
    for chain in chains:
        line = (
            shapely.LineString(vertices[chain]).simplify(tolerance_m, preserve_topology=False)
            if tolerance_m > 0.0
            else shapely.LineString(vertices[chain])
        )
        pts = np.asarray(line.coords)
        out.extend(zip(pts[:-1], pts[1:]))
    return np.asarray(out, dtype=np.float64).reshape(-1, 2, 2)


def _medial_axis_2d(polygon) -> np.ndarray:
    """(s, 2, 2) segments of SFCGAL's approximate medial axis of one shapely polygon."""
    sfc = SfcgalPolygon(list(polygon.exterior.coords), [list(r.coords) for r in polygon.interiors])
    axis = sfc.approximate_medial_axis()
    if axis is None:
        return np.empty((0, 2, 2))
    segments: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] = []
    for line in axis.to_coordinates():
        pts = np.asarray(line, dtype=np.float64)[:, :2]
        segments.extend(zip(pts[:-1], pts[1:]))
    return np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)


def layer_height(points_xz: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Heights (p,) of ground points (p, 2) on the layer's triangles (k, 3, 3): the containing
    triangle's plane, or the nearest triangle's where simplification moved a point off the layer."""
    polys = shapely.polygons(triangles[:, :, [0, 2]])
    tree = shapely.STRtree(polys)
    pts = shapely.points(points_xz)
    owner = tree.query_nearest(pts, all_matches=False, return_distance=False)[1]
    return _plane_height(triangles[owner], points_xz)


def extract_skeleton(navmesh: TriMesh, settings: TrackSettings) -> Skeleton:
    """Skeleton of a navigation mesh (metres, world frame): the module docstring's four steps."""
    triangle_layer, layer_count = split_layers(navmesh, settings)
    tri = navmesh.vertices[navmesh.faces]
    outlines = tuple(
        layer_outline(tri[triangle_layer == layer][:, :, [0, 2]], settings.skeleton_simplify_m, settings.skeleton_min_hole_m2)
        for layer in range(layer_count)
    )
    segments, layers = [], []
    for layer in range(layer_count):
        own = tri[triangle_layer == layer]
        for polygon in outlines[layer]:
            seg2 = clean_axis(_medial_axis_2d(polygon), polygon, settings.skeleton_prune_m, settings.skeleton_line_tolerance_m)
            if not len(seg2):
                continue
            height = layer_height(seg2.reshape(-1, 2), own).reshape(-1, 2)
            segments.append(np.stack([seg2[:, :, 0], height, seg2[:, :, 1]], axis=2))
            layers.append(np.full(len(seg2), layer))
    if not segments:
        return Skeleton(np.empty((0, 2, 3)), np.empty(0, np.int64), triangle_layer, layer_count, outlines)
    seg = np.concatenate(segments)
    keep = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1) > 1e-6
    return Skeleton(seg[keep], np.concatenate(layers)[keep], triangle_layer, layer_count, outlines)
