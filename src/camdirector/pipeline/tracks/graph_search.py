"""The camera navigation graph as the director queries it (Section 4.6, step iv, and Section 5.2):
a KD-tree over the nodes, CSR adjacency, and A* distances, built once when a level is loaded.

A* (`astar_many`) searches from a point on an edge towards several goal nodes at once, with the
distance to the goals' bounding box as heuristic (admissible and consistent). The graph itself is
built offline (precompute/tracks/graph.py).
"""

from __future__ import annotations

import heapq
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree


def csr_rows(indptr: npt.NDArray[np.integer[Any]], rows: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """Positions (k,) into a CSR matrix's index/data arrays of all entries of the given rows."""
    row_ids = np.asarray(rows, dtype=np.int64)
    lengths = indptr[row_ids + 1] - indptr[row_ids]
    total = int(lengths.sum())
    if not total:
        return np.empty(0, np.int64)
    positions: npt.NDArray[np.int64] = np.repeat(indptr[row_ids], lengths) + (
        np.arange(total) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    )
    return positions


def adjacency_lists(
    indptr: npt.NDArray[np.integer[Any]], neighbours: npt.NDArray[np.integer[Any]], weights: npt.NDArray[np.float64]
) -> list[list[tuple[int, float]]]:
    """CSR adjacency as Python lists of (neighbour, weight), what `astar_many` walks."""
    pairs = list(zip(neighbours.tolist(), weights.tolist()))
    bounds = indptr.tolist()
    return [pairs[bounds[i] : bounds[i + 1]] for i in range(len(bounds) - 1)]


def astar_many(
    adjacency: list[list[tuple[int, float]]],
    positions: list[list[float]],
    sources: dict[int, float],
    goals: set[int],
    max_cost: float,
    parent: dict[int, int] | None = None,
) -> dict[int, float]:
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
        return float((dx * dx + dy * dy + dz * dz) ** 0.5)

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

    def __init__(self, nodes_world: npt.NDArray[np.float64], edges: npt.NDArray[np.integer[Any]]) -> None:
        self.nodes_world = np.asarray(nodes_world, dtype=np.float64)
        self.edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        self.edge_length_m = np.linalg.norm(self.nodes_world[self.edges[:, 1]] - self.nodes_world[self.edges[:, 0]], axis=1)
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

    def edges_near(
        self, point_world: npt.NDArray[np.float64], radius_m: float
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
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
