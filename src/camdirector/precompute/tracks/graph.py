"""The camera navigation graph (Section 4.6), built offline.

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
(iv)  a KD-tree over the nodes, built when the graph is loaded (pipeline/tracks/graph_search.py's
      `RuntimeGraph`), not stored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
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
    node_positions: list[npt.NDArray[np.float64]] = []
    edges: list[tuple[int, int]] = []
    for k, ts in enumerate(params):
        if np.allclose(start[k], end[k]):  # a static camera: one node for every parameter
            node_of.update({(k, value): len(node_positions) for value in ts})
            node_positions.append(start[k])
            continue
        chain = []
        for value in sorted(set(ts)):
            node_of[(k, value)] = len(node_positions)
            node_positions.append(start[k] + value * (end[k] - start[k]))
            chain.append(node_of[(k, value)])
        edges.extend(zip(chain[:-1], chain[1:]))
    positions = np.asarray(node_positions, dtype=np.float64).reshape(-1, 3)
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
