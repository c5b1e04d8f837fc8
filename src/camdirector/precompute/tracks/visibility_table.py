"""Remeshing of the navigation mesh and the dual visibility table (Section 4.5).

Remeshing: the paper remeshes the navmesh [Botsch and Kobbelt 2004] so that every triangle is
under a given area. A derived navmesh is fine along its outlines and coarse inside, so we remesh
from the outlines instead of splitting its triangles: each floor layer's outline (the simplified
polygons of the skeleton stage) is triangulated by a constrained Delaunay triangulation
(shapely), whose triangles are bisected at their longest edge until each is at most
`max_triangle_area_m2` with no edge longer than twice the side of a square of that area; vertices
take the height of the layer's navmesh under them. Compact triangles of about the same size
everywhere: what the visibility estimate needs.

Visibility: for every camera node and every refined triangle whose centroid lies within
`visibility_range_m`, `visibility_rays` Monte Carlo rays go from the node to uniformly random
points of the triangle raised by `visibility_target_height_fraction` of the agent height (where
an actor's body would be); the degree of visibility is the fraction of those rays that reach
their point (Embree, static level only). Pairs seen by no ray are not stored. The table is kept
both ways, as the paper does: per node the triangles it sees, per triangle the nodes that see it
(two CSR matrices of degrees in 1/255).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy import sparse
from scipy.spatial import cKDTree

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import UP_WORLD
from camdirector.precompute.tracks.navmesh import refine_triangles
from camdirector.precompute.tracks.skeleton import Skeleton, layer_height
from camdirector.precompute.tracks.track_settings import TrackSettings

_RAYS_PER_BATCH = 1 << 21


@dataclass(frozen=True)
class VisibilityTable:
    """Dual visibility of camera nodes (N) and refined navmesh triangles (T).

    node_indptr (N+1,) int64, node_triangles (nnz,) int32, node_degree (nnz,) uint8: the
    triangles each node sees, sorted, with their degree of visibility in 1/255;
    triangle_indptr (T+1,), triangle_nodes (nnz,) int32, triangle_degree (nnz,) uint8: the same
    per triangle.
    """

    node_indptr: np.ndarray
    node_triangles: np.ndarray
    node_degree: np.ndarray
    triangle_indptr: np.ndarray
    triangle_nodes: np.ndarray
    triangle_degree: np.ndarray

    @property
    def node_count(self) -> int:
        return len(self.node_indptr) - 1

    @property
    def triangle_count(self) -> int:
        return len(self.triangle_indptr) - 1

    def seen_triangles(self) -> np.ndarray:
        """(T,) bool: triangles seen by at least one node."""
        return np.diff(self.triangle_indptr) > 0


def remesh(navmesh: TriMesh, skeleton: Skeleton, settings: TrackSettings) -> TriMesh:
    """Navmesh remeshed to triangles of at most `max_triangle_area_m2` (module docstring)."""
    tri = navmesh.vertices[navmesh.faces]
    vertices, faces = [], []
    offset = 0
    for layer in range(skeleton.layer_count):
        own = tri[skeleton.triangle_layer == layer]
        for polygon in skeleton.outlines[layer]:
            cdt = shapely.constrained_delaunay_triangles(polygon)
            flat = np.asarray([np.asarray(t.exterior.coords)[:3] for t in cdt.geoms]).reshape(-1, 3, 2)
            if not len(flat):
                continue
            e1, e2 = flat[:, 1] - flat[:, 0], flat[:, 2] - flat[:, 0]
            ccw = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0.0
            flat[ccw] = flat[ccw][:, ::-1]  # clockwise in (x, z) is counter-clockwise seen from +Y: faces up
            v2, f = refine_triangles(
                np.column_stack([flat.reshape(-1, 2), np.zeros(3 * len(flat))]),
                np.arange(3 * len(flat)).reshape(-1, 3),
                max_area_m2=settings.max_triangle_area_m2,
                max_edge_m=2.0 * np.sqrt(settings.max_triangle_area_m2),
            )
            xz = v2[:, :2]
            vertices.append(np.column_stack([xz[:, 0], layer_height(xz, own), xz[:, 1]]))
            faces.append(f + offset)
            offset += len(xz)
    if not vertices:
        return TriMesh(vertices=np.empty((0, 3)), faces=np.empty((0, 3), np.int32))
    return TriMesh(vertices=np.vstack(vertices), faces=np.vstack(faces).astype(np.int32))


def build_visibility_table(
    nodes_world: np.ndarray, refined: TriMesh, scene: RayScene, settings: TrackSettings, rng: np.random.Generator
) -> VisibilityTable:
    """Monte Carlo dual visibility table of nodes (N, 3) against refined triangles (module docstring)."""
    triangles = refined.vertices[refined.faces]
    centroid = triangles.mean(axis=1)
    lift = settings.visibility_target_height_fraction * settings.agent_height_m * UP_WORLD
    corner = (triangles[:, 0] + lift).astype(np.float32)
    edge1 = (triangles[:, 1] - triangles[:, 0]).astype(np.float32)
    edge2 = (triangles[:, 2] - triangles[:, 0]).astype(np.float32)
    rays = settings.visibility_rays
    n_nodes, n_tris = len(nodes_world), len(triangles)
    rows, cols, degrees = [], [], []
    if n_nodes and n_tris:
        near = cKDTree(centroid).query_ball_point(nodes_world, settings.visibility_range_m)
        counts = np.fromiter((len(x) for x in near), dtype=np.int64, count=n_nodes)
        node_of_pair = np.repeat(np.arange(n_nodes), counts)
        tri_of_pair = np.fromiter((t for x in near for t in x), dtype=np.int64, count=int(counts.sum()))
        per_batch = max(1, _RAYS_PER_BATCH // rays)
        for lo in range(0, len(node_of_pair), per_batch):
            node = node_of_pair[lo : lo + per_batch]
            tri = tri_of_pair[lo : lo + per_batch]
            origin = nodes_world[node].astype(np.float32)
            a, e1, e2 = corner[tri], edge1[tri], edge2[tri]
            seen = np.zeros(len(node), dtype=np.int64)
            for _ in range(rays):  # uniform points on the triangles: sqrt(r1) folds the square onto them
                r1 = np.sqrt(rng.random(len(node), dtype=np.float32))
                r2 = rng.random(len(node), dtype=np.float32)
                target = a + (r1 * (1.0 - r2))[:, None] * e1 + (r1 * r2)[:, None] * e2
                seen += ~scene.occluded(origin, target)
            keep = seen > 0
            rows.append(node[keep])
            cols.append(tri[keep])
            degrees.append(np.round(255.0 * seen[keep] / rays).astype(np.uint8))
    row = np.concatenate(rows) if rows else np.empty(0, np.int64)
    col = np.concatenate(cols) if cols else np.empty(0, np.int64)
    deg = np.concatenate(degrees) if degrees else np.empty(0, np.uint8)
    by_node = sparse.csr_matrix((deg.astype(np.int16), (row, col)), shape=(n_nodes, n_tris))
    by_node.sort_indices()
    by_tri = by_node.tocsc()
    by_tri.sort_indices()
    return VisibilityTable(
        node_indptr=by_node.indptr.astype(np.int64),
        node_triangles=by_node.indices.astype(np.int32),
        node_degree=by_node.data.astype(np.uint8),
        triangle_indptr=by_tri.indptr.astype(np.int64),
        triangle_nodes=by_tri.indices.astype(np.int32),
        triangle_degree=by_tri.data.astype(np.uint8),
    )
