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
   cracks of T-junctions closed by a 1 cm closing, outlines simplified by `skeleton_simplify_m`;
3. skeleton: SFCGAL's `approximate_medial_axis` (pysfcgal), the straight skeleton of each polygon
   without the arcs that end on the outline's vertices: the corridors' centre lines, junctions and
   dead ends, not the spokes into every corner;
4. reprojection: skeleton vertices get the height of the layer triangle under them.

What this loses against a curve skeleton: skeleton lines stop where a layer is cut (a ramp
between two floors carries two skeleton pieces that nearly meet instead of one line); the graph's
linking step (Section 4.6 iii) joins the tracks on either side.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import shapely
from pysfcgal.geometry import Polygon as SfcgalPolygon
from shapely.geometry.polygon import orient

from camdirector.geometry.meshes import TriMesh
from camdirector.precompute.tracks.navmesh import triangle_adjacency
from camdirector.precompute.tracks.settings import TrackSettings

_OVERLAP_M2 = 1e-4   # projections overlapping by less than this do not make two floors
_CLOSING_M = 0.01    # closes cracks between triangles meeting at T-junctions


@dataclass(frozen=True)
class Skeleton:
    """segments_world: (k, 2, 3) float64 metres, each a straight piece of the skeleton on the
    navmesh; layer: (k,) int the layer it lies in; triangle_layer: (m,) int layer of each navmesh
    triangle; layer_count: number of layers."""

    segments_world: np.ndarray
    layer: np.ndarray
    triangle_layer: np.ndarray
    layer_count: int

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.segments_world[:, 1] - self.segments_world[:, 0], axis=1).sum())


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
            for n in indices[indptr[t]:indptr[t + 1]].tolist():
                if layer[n] < 0 and not any(layer[c] == count for c in conflicts[n]):
                    layer[n] = count
                    queue.append(n)
        count += 1
    return layer, count


def layer_outline(triangles_xz: np.ndarray, simplify_m: float) -> list:
    """Shapely polygons (CCW outside, CW holes) of the union of triangles (k, 3, 2)."""
    merged = shapely.union_all(shapely.polygons(triangles_xz)).buffer(_CLOSING_M).buffer(-_CLOSING_M)
    if simplify_m > 0.0:
        merged = merged.simplify(simplify_m, preserve_topology=True)
    parts = getattr(merged, "geoms", [merged])
    return [orient(p, 1.0) for p in parts if p.geom_type == "Polygon" and p.area > 1e-6]


def _medial_axis_2d(polygon) -> np.ndarray:
    """(s, 2, 2) segments of SFCGAL's approximate medial axis of one shapely polygon."""
    sfc = SfcgalPolygon(list(polygon.exterior.coords), [list(r.coords) for r in polygon.interiors])
    axis = sfc.approximate_medial_axis()
    if axis is None:
        return np.empty((0, 2, 2))
    segments = []
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
    segments, layers = [], []
    for layer in range(layer_count):
        own = tri[triangle_layer == layer]
        for polygon in layer_outline(own[:, :, [0, 2]], settings.skeleton_simplify_m):
            seg2 = _medial_axis_2d(polygon)
            if not len(seg2):
                continue
            height = layer_height(seg2.reshape(-1, 2), own).reshape(-1, 2)
            segments.append(np.stack([seg2[:, :, 0], height, seg2[:, :, 1]], axis=2))
            layers.append(np.full(len(seg2), layer))
    if not segments:
        return Skeleton(np.empty((0, 2, 3)), np.empty(0, np.int64), triangle_layer, layer_count)
    seg = np.concatenate(segments)
    keep = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1) > 1e-6
    return Skeleton(seg[keep], np.concatenate(layers)[keep], triangle_layer, layer_count)
