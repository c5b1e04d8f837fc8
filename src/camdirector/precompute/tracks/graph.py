"""The camera navigation graph (Section 4.6) and shortest paths on it.

Built in the paper's four steps:
(i)   insertion: every track becomes two end nodes and an edge; where two tracks pass within
      `intersection_tolerance_m` of each other (segment-to-segment closest points, so crossing
      tracks in 3D need not touch exactly), both get a node at their closest points and the two
      nodes are merged into one at their midpoint (a merge moves a track by at most half the
      tolerance); a static camera (a track of one point) is a lone node, merged the same way;
(ii)  splitting: edges longer than `max_edge_length_m` are cut into equal pieces;
(iii) linking: nodes of different connected components closer than `link_distance_m` and seeing
      each other (an Embree ray) are joined by an edge; of all such pairs between the same two
      components whose midpoints fall in the same cube of `link_distance_m`, only the shortest is
      kept (our choice: two long parallel tracks get a rung every few metres, not a full mesh);
(iv)  a KD-tree over the nodes, built when the graph is loaded (`RuntimeGraph`), not stored.

A* (`astar_many`) searches from a point on an edge towards several goal nodes at once, with the
distance to the goals' bounding box as heuristic (admissible and consistent).
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.ransac import Tracks
from camdirector.precompute.tracks.track_settings import TrackSettings

_SAMPLE_STEP_M = 1.0


@dataclass(frozen=True)
class CameraGraph:
    """nodes_world: (N, 3) float64 camera positions, metres; edges: (E, 2) int node pairs, i < j,
    unique; edge_is_link: (E,) bool, edges made by the linking step (iii)."""

    nodes_world: np.ndarray
    edges: np.ndarray
    edge_is_link: np.ndarray

    @property
    def edge_length_m(self) -> np.ndarray:
        return np.linalg.norm(self.nodes_world[self.edges[:, 1]] - self.nodes_world[self.edges[:, 0]], axis=1)


def closest_points_on_segments(p1, q1, p2, q2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points between segments p1-q1 and p2-q2 (each (k, 3)): parameters s, t (k,) in
    [0, 1] along each and the distances (k,) (Ericson, Real-Time Collision Detection, 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    tiny = 1e-12
    denom = a * e - b * b
    s = np.where(denom > tiny, np.clip((b * f - c * e) / np.where(denom > tiny, denom, 1.0), 0.0, 1.0), 0.0)
    t = np.where(e > tiny, (b * s + f) / np.where(e > tiny, e, 1.0), 0.0)
    s = np.where(t < 0.0, np.where(a > tiny, np.clip(-c / np.where(a > tiny, a, 1.0), 0.0, 1.0), 0.0), s)
    s = np.where(t > 1.0, np.where(a > tiny, np.clip((b - c) / np.where(a > tiny, a, 1.0), 0.0, 1.0), 0.0), s)
    t = np.clip(t, 0.0, 1.0)
    gap = (p1 + s[:, None] * d1) - (p2 + t[:, None] * d2)
    return s, t, np.linalg.norm(gap, axis=1)


def _candidate_pairs(start: np.ndarray, end: np.ndarray, tolerance: float) -> np.ndarray:
    """(p, 2) track index pairs i < j that may pass within tolerance (points every metre)."""
    length = np.linalg.norm(end - start, axis=1)
    count = np.floor(length / _SAMPLE_STEP_M).astype(np.int64) + 2
    owner = np.repeat(np.arange(len(start)), count)
    step = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
    frac = step / (count[owner] - 1)
    pts = start[owner] + frac[:, None] * (end - start)[owner]
    pairs = cKDTree(pts).query_pairs(0.5 * _SAMPLE_STEP_M * np.sqrt(2.0) + tolerance, output_type="ndarray")
    pairs = np.sort(owner[pairs], axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return np.unique(pairs, axis=0) if len(pairs) else pairs.reshape(0, 2)


def _find(parent: np.ndarray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


def insert_tracks(tracks: Tracks, settings: TrackSettings) -> tuple[np.ndarray, np.ndarray]:
    """Step (i): (nodes (N, 3), edges (E, 2)) with tracks joined at their intersections."""
    start, end = tracks.start_world, tracks.end_world
    pairs = _candidate_pairs(start, end, settings.intersection_tolerance_m)
    params: list[list[float]] = [[0.0, 1.0] for _ in range(len(tracks))]
    joins = []
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        s, t, gap = closest_points_on_segments(start[i], end[i], start[j], end[j])
        near = gap <= settings.intersection_tolerance_m
        for a, b, sa, tb in zip(i[near].tolist(), j[near].tolist(), s[near].tolist(), t[near].tolist()):
            params[a].append(sa)
            params[b].append(tb)
            joins.append((a, sa, b, tb))
    node_of: dict[tuple[int, float], int] = {}
    positions, edges = [], []
    for k, ts in enumerate(params):
        if np.allclose(start[k], end[k]):  # a static camera: one node for every parameter
            node_of.update({(k, value): len(positions) for value in ts})
            positions.append(start[k])
            continue
        chain = []
        for value in sorted(set(ts)):
            node_of[(k, value)] = len(positions)
            positions.append(start[k] + value * (end[k] - start[k]))
            chain.append(node_of[(k, value)])
        edges.extend(zip(chain[:-1], chain[1:]))
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    parent = np.arange(len(positions))
    for a, sa, b, tb in joins:
        ra, rb = _find(parent, node_of[(a, sa)]), _find(parent, node_of[(b, tb)])
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    root = np.array([_find(parent, i) for i in range(len(positions))], dtype=np.int64)
    roots, node_index = np.unique(root, return_inverse=True)
    merged = np.zeros((len(roots), 3))
    np.add.at(merged, node_index, positions)
    merged /= np.bincount(node_index, minlength=len(roots))[:, None]
    return merged, _clean_edges(node_index[np.asarray(edges, dtype=np.int64).reshape(-1, 2)])


def _clean_edges(edges: np.ndarray) -> np.ndarray:
    edges = np.sort(edges, axis=1)
    edges = edges[edges[:, 0] != edges[:, 1]]
    return np.unique(edges, axis=0) if len(edges) else edges.reshape(0, 2)


def edge_pieces(length_m: np.ndarray, max_length_m: float) -> np.ndarray:
    """(E,) int: the equal pieces step (ii) cuts edges of length_m (E,) into, at least 1."""
    return np.maximum(np.ceil(length_m / max_length_m).astype(np.int64), 1)


def split_edges(nodes: np.ndarray, edges: np.ndarray, max_length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Step (ii): every edge longer than max_length_m cut into equal pieces."""
    length = np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1)
    pieces = edge_pieces(length, max_length_m)
    new_nodes, new_edges = [nodes], [edges[pieces == 1]]
    next_id = len(nodes)
    for (a, b), k in zip(edges[pieces > 1], pieces[pieces > 1]):
        frac = np.arange(1, k)[:, None] / k
        new_nodes.append(nodes[a] + frac * (nodes[b] - nodes[a]))
        chain = np.concatenate([[a], next_id + np.arange(k - 1), [b]])
        new_edges.append(np.stack([chain[:-1], chain[1:]], axis=1))
        next_id += k - 1
    return np.vstack(new_nodes), _clean_edges(np.vstack(new_edges))


def link_components(nodes: np.ndarray, edges: np.ndarray, scene: RayScene, link_distance_m: float) -> np.ndarray:
    """Step (iii): (L, 2) new edges between mutually visible nodes of different components."""
    if len(nodes) < 2 or link_distance_m <= 0.0:
        return np.empty((0, 2), np.int64)
    graph = sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(len(nodes),) * 2)
    label = connected_components(graph, directed=False)[1]
    pairs = cKDTree(nodes).query_pairs(link_distance_m, output_type="ndarray")
    pairs = pairs[label[pairs[:, 0]] != label[pairs[:, 1]]]
    if not len(pairs):
        return np.empty((0, 2), np.int64)
    pairs = np.where((label[pairs[:, 0]] < label[pairs[:, 1]])[:, None], pairs, pairs[:, ::-1])
    distance = np.linalg.norm(nodes[pairs[:, 0]] - nodes[pairs[:, 1]], axis=1)
    order = np.argsort(distance, kind="stable")
    pairs = pairs[order]
    free = ~scene.occluded(nodes[pairs[:, 0]], nodes[pairs[:, 1]])
    pairs = pairs[free]
    cell = np.floor(0.5 * (nodes[pairs[:, 0]] + nodes[pairs[:, 1]]) / link_distance_m).astype(np.int64)
    key = np.column_stack([label[pairs[:, 0]], label[pairs[:, 1]], cell])
    _, first = np.unique(key, axis=0, return_index=True)  # the shortest visible link per cell
    return _clean_edges(pairs[np.sort(first)])


def build_graph(tracks: Tracks, scene: RayScene, settings: TrackSettings) -> CameraGraph:
    """Camera navigation graph of filtered tracks (module docstring, steps i to iii)."""
    nodes, edges = insert_tracks(tracks, settings)
    nodes, edges = split_edges(nodes, edges, settings.max_edge_length_m)
    links = link_components(nodes, edges, scene, settings.link_distance_m)
    all_edges = np.vstack([edges, links])
    is_link = np.concatenate([np.zeros(len(edges), bool), np.ones(len(links), bool)])
    order = np.lexsort((all_edges[:, 1], all_edges[:, 0]))
    all_edges, is_link = all_edges[order], is_link[order]
    keep = np.ones(len(all_edges), dtype=bool)
    keep[1:] = np.any(all_edges[1:] != all_edges[:-1], axis=1)
    return CameraGraph(nodes, all_edges[keep], is_link[keep])


def csr_rows(indptr: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Positions (k,) into a CSR matrix's index/data arrays of all entries of the given rows."""
    rows = np.asarray(rows, dtype=np.int64)
    lengths = indptr[rows + 1] - indptr[rows]
    total = int(lengths.sum())
    if not total:
        return np.empty(0, np.int64)
    return np.repeat(indptr[rows], lengths) + (np.arange(total) - np.repeat(np.cumsum(lengths) - lengths, lengths))


def adjacency_lists(indptr: np.ndarray, neighbours: np.ndarray, weights: np.ndarray) -> list[list[tuple[int, float]]]:
    """CSR adjacency as Python lists of (neighbour, weight), what `astar_many` walks."""
    pairs = list(zip(neighbours.tolist(), weights.tolist()))
    bounds = indptr.tolist()
    return [pairs[bounds[i]:bounds[i + 1]] for i in range(len(bounds) - 1)]


def astar_many(adjacency: list[list[tuple[int, float]]], positions: list[list[float]], sources: dict[int, float],
               goals: set[int], max_cost: float, parent: dict[int, int] | None = None) -> dict[int, float]:
    """Graph distances from a start point to several goal nodes by A*.

    The start is given as `sources`: node -> cost already paid to reach it (the two ends of the
    start point's edge). adjacency: per node (neighbour, length in metres); positions: per node
    [x, y, z] metres. The heuristic is the distance to the goals' bounding box: never more than
    the distance to the nearest goal (admissible) and 1-Lipschitz (consistent), so a node is final
    when it leaves the heap; it costs a few float operations, where the distance to the nearest
    goal would cost a loop over goals per node. The search ends when every goal is reached or the
    frontier passes max_cost. Returns goal -> distance for the goals reached; `parent`, when
    given, receives each reached node's predecessor on its shortest path (sources have none).
    """
    remaining = set(goals)
    found: dict[int, float] = {}
    if not remaining:
        return found
    box = np.array([positions[g] for g in remaining])
    (x0, y0, z0), (x1, y1, z1) = box.min(axis=0).tolist(), box.max(axis=0).tolist()

    def h(n: int) -> float:
        x, y, z = positions[n]
        dx = x0 - x if x < x0 else (x - x1 if x > x1 else 0.0)
        dy = y0 - y if y < y0 else (y - y1 if y > y1 else 0.0)
        dz = z0 - z if z < z0 else (z - z1 if z > z1 else 0.0)
        return (dx * dx + dy * dy + dz * dz) ** 0.5

    best = dict(sources)
    heap = [(cost + h(n), cost, n) for n, cost in sources.items()]
    heapq.heapify(heap)
    closed: set[int] = set()
    while heap and remaining:
        f, cost, n = heapq.heappop(heap)
        if f > max_cost:
            break
        if n in closed:
            continue
        closed.add(n)
        if n in remaining:
            found[n] = cost
            remaining.discard(n)
        for m, w in adjacency[n]:
            c = cost + w
            if c < best.get(m, max_cost + 1.0) and m not in closed and c <= max_cost:
                best[m] = c
                if parent is not None:
                    parent[m] = n
                heapq.heappush(heap, (c + h(m), c, m))
    return found


class RuntimeGraph:
    """The graph as the runtime queries it: node KD-tree (step iv), CSR adjacency with edge
    lengths (metres) and edge ids, built once when a level is loaded.

    nodes_world (N, 3); edges (E, 2) int.
    """

    def __init__(self, nodes_world: np.ndarray, edges: np.ndarray):
        self.nodes_world = np.asarray(nodes_world, dtype=np.float64)
        self.edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        self.edge_length_m = np.linalg.norm(self.nodes_world[self.edges[:, 1]] - self.nodes_world[self.edges[:, 0]],
                                            axis=1)
        self.tree = cKDTree(self.nodes_world)
        n = len(self.nodes_world)
        src = np.concatenate([self.edges[:, 0], self.edges[:, 1]])
        dst = np.concatenate([self.edges[:, 1], self.edges[:, 0]])
        eid = np.tile(np.arange(len(self.edges)), 2)
        order = np.argsort(src, kind="stable")
        self.indptr = np.searchsorted(src[order], np.arange(n + 1))
        self.neighbours = dst[order]
        self.adjacent_edge = eid[order]
        self.weights = self.edge_length_m[self.adjacent_edge]
        self.degree = np.diff(self.indptr)
        self._adjacency = adjacency_lists(self.indptr, self.neighbours, self.weights)
        self._positions = self.nodes_world.tolist()

    def edges_near(self, point_world: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Edges touching a node within radius_m of point (3,), and the isolated nodes there:
        ((e,) int edge ids, (i,) int node ids)."""
        near = np.asarray(self.tree.query_ball_point(point_world, radius_m), dtype=np.int64)
        if not len(near):
            return np.empty(0, np.int64), near
        isolated = near[self.degree[near] == 0]
        return np.unique(self.adjacent_edge[csr_rows(self.indptr, near)]), isolated

    def distances_from(self, node_a: int, node_b: int, t: float, goals: set[int], max_cost: float) -> dict[int, float]:
        """A* graph distances (metres) from the point at fraction t of the way from node_a to node_b
        (node_a == node_b for a node) to each goal node reached within max_cost."""
        length = float(np.linalg.norm(self.nodes_world[node_b] - self.nodes_world[node_a]))
        sources = {node_a: t * length}
        if node_b != node_a:
            sources[node_b] = min(sources.get(node_b, np.inf), (1.0 - t) * length)
        return astar_many(self._adjacency, self._positions, sources, goals, max_cost)
