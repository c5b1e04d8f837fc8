"""Target moving strategy (Section 5.2): points of interest on the tracks near the actor and
their four sub-scores.

Candidate edges are the edges touching a node closer to the actor than the candidate radius
(the paper's user distance: the director passes the larger of `candidate_radius_m` and 1.5
times the shot's optimal distance); isolated nodes (static cameras) are candidates as
points. Points of interest (POI) on an edge: the projection of the actor's look-at point on the
edge (clamped to it) and the points of the edge at the optimal framing distance from it.

Sub-scores, each in [0, 1], higher is better:
- shot size: the optimal camera distance comes from the vertical field of view and the expected
  on-screen height of the actor, d* = H / (f * 2 tan(fov / 2)); the score is a Gaussian in
  ln(d / d*) of width `shot_size_tolerance_log`;
- direct visibility: the fraction of rays from the POI to points up the actor that reach them
  (Embree, with the dynamic occluders of the caller's RayScene);
- indirect visibility: the share of the remeshed navmesh triangles around the actor (centroids
  within `surroundings_radius_m`) that the POI sees, read from the dual table: per triangle its
  nodes (the triangle side of the table), interpolated between the POI's edge ends;
- distance: 1 - (graph distance from the current target) / `max_graph_distance_m`, by A* on the
  graph; POIs A* cannot reach within that distance are not strongly connected to the current
  target and are dropped (the paper's edge filter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.tracks.graph_search import RuntimeGraph, csr_rows
from camdirector.precompute.tracks.visibility_table import VisibilityTable


@dataclass(frozen=True)
class Pois:
    """Points on the graph: node_a, node_b (k,) int, t (k,) fraction from a to b (a == b: a
    node), position_world (k, 3)."""

    node_a: npt.NDArray[np.integer[Any]]
    node_b: npt.NDArray[np.integer[Any]]
    t: npt.NDArray[np.float64]
    position_world: npt.NDArray[np.float64]

    def __len__(self) -> int:
        return len(self.t)

    def take(self, index: npt.NDArray[np.intp] | npt.NDArray[np.bool_] | list[int]) -> Pois:
        return Pois(self.node_a[index], self.node_b[index], self.t[index], self.position_world[index])


def optimal_distance_m(actor_height_m: float, screen_fraction: float, vertical_fov_deg: float) -> float:
    """Camera distance at which the actor's height fills screen_fraction of the frame height, m."""
    return actor_height_m / (screen_fraction * 2.0 * math.tan(math.radians(vertical_fov_deg) / 2.0))


def candidate_pois(
    graph: RuntimeGraph,
    actor_world: npt.NDArray[np.float64],
    look_at_world: npt.NDArray[np.float64],
    distance_m: float,
    radius_m: float,
    nodes_only: bool,
) -> Pois:
    """POIs near the actor (module docstring); nodes_only: the nodes of those edges instead (static cameras)."""
    edge_ids, isolated = graph.edges_near(actor_world, radius_m)
    if nodes_only:
        nodes = np.unique(np.concatenate([graph.edges[edge_ids].reshape(-1), isolated]))
        return Pois(nodes, nodes, np.zeros(len(nodes)), graph.nodes_world[nodes])
    a, b = graph.edges[edge_ids, 0], graph.edges[edge_ids, 1]
    pa, d = graph.nodes_world[a], graph.nodes_world[b] - graph.nodes_world[a]
    dd = np.einsum("ij,ij->i", d, d)
    w = pa - look_at_world
    t_proj = np.clip(-np.einsum("ij,ij->i", w, d) / np.maximum(dd, 1e-12), 0.0, 1.0)
    # |w + t d|^2 = D^2  ->  dd t^2 + 2 (w.d) t + |w|^2 - D^2 = 0
    half_b = np.einsum("ij,ij->i", w, d)
    disc = half_b * half_b - dd * (np.einsum("ij,ij->i", w, w) - distance_m * distance_m)
    root = np.sqrt(np.maximum(disc, 0.0))
    t_near = (-half_b - root) / np.maximum(dd, 1e-12)
    t_far = (-half_b + root) / np.maximum(dd, 1e-12)
    ts = [t_proj]
    owners = [np.arange(len(a))]
    for t in (t_near, t_far):
        ok = (disc >= 0.0) & (t >= 0.0) & (t <= 1.0)
        ts.append(t[ok])
        owners.append(np.flatnonzero(ok))
    owner = np.concatenate(owners)
    t = np.concatenate(ts)
    na, nb = np.concatenate([a[owner], isolated]), np.concatenate([b[owner], isolated])
    t = np.concatenate([t, np.zeros(len(isolated))])
    position = graph.nodes_world[na] + t[:, None] * (graph.nodes_world[nb] - graph.nodes_world[na])
    return Pois(na, nb, t, position)


def shot_size_score(
    positions_world: npt.NDArray[np.float64], look_at_world: npt.NDArray[np.float64], distance_m: float, tolerance_log: float
) -> npt.NDArray[np.float64]:
    """(k,) Gaussian in ln(distance / optimal distance)."""
    d = np.maximum(np.linalg.norm(positions_world - look_at_world, axis=1), 1e-6)
    score: npt.NDArray[np.float64] = np.exp(-0.5 * (np.log(d / distance_m) / tolerance_log) ** 2)
    return score


def direct_visibility(
    positions_world: npt.NDArray[np.float64], actor_points_world: npt.NDArray[np.float64], scene: RayScene
) -> npt.NDArray[np.float64]:
    """(k, ...) fraction of the actor's points each position (k, 3) sees: actor_points_world
    (..., p, 3), the points at one moment (p, 3) -> (k,), or at m moments (m, p, 3) -> (k, m),
    all in one batch of rays."""
    points = np.asarray(actor_points_world)
    k, n = len(positions_world), points.size // 3
    if not k:
        return np.empty((0, *points.shape[:-2]))
    hidden = scene.occluded(np.repeat(positions_world, n, axis=0), np.tile(points.reshape(-1, 3), (k, 1)))
    seen: npt.NDArray[np.float64] = 1.0 - hidden.reshape(k, *points.shape[:-1]).mean(axis=-1)
    return seen


class IndirectVisibility:
    """Share of the actor's surroundings each node sees, from the triangle side of the dual table.

    refined_centroids_world (T, 3); table: the artifact's VisibilityTable.
    """

    def __init__(self, refined_centroids_world: npt.NDArray[np.float64], table: VisibilityTable):
        self._tree = cKDTree(refined_centroids_world) if len(refined_centroids_world) else None
        self._table = table

    def per_node(self, actor_world: npt.NDArray[np.float64], radius_m: float) -> npt.NDArray[np.float64]:
        """(N,) fraction in [0, 1] of the triangles within radius_m of the actor that each node sees
        (weighted by the degree of visibility); all ones when no triangle is that near."""
        n = self._table.node_count
        if not self._tree:
            return np.ones(n)
        near = np.asarray(self._tree.query_ball_point(actor_world, radius_m), dtype=np.int64)
        if not len(near):
            return np.ones(n)
        idx = csr_rows(self._table.triangle_indptr, near)
        seen = np.bincount(self._table.triangle_nodes[idx], weights=self._table.triangle_degree[idx], minlength=n)
        share: npt.NDArray[np.float64] = seen / (255.0 * len(near))
        return share


def graph_distance(graph: RuntimeGraph, current: tuple[int, int, float], pois: Pois, max_cost: float) -> npt.NDArray[np.float64]:
    """(k,) A* distance along the graph from the current target (a, b, t) to each POI, metres (inf
    beyond max_cost or unreachable)."""
    a0, b0, t0 = current
    goals = set(pois.node_a.tolist()) | set(pois.node_b.tolist())
    dist = graph.distances_from(a0, b0, t0, goals, max_cost)
    length = np.linalg.norm(graph.nodes_world[pois.node_b] - graph.nodes_world[pois.node_a], axis=1)
    inf = float("inf")
    da = np.array([dist.get(n, inf) for n in pois.node_a.tolist()])
    db = np.array([dist.get(n, inf) for n in pois.node_b.tolist()])
    out: npt.NDArray[np.float64] = np.minimum(da + pois.t * length, db + (1.0 - pois.t) * length)
    same = ((pois.node_a == a0) & (pois.node_b == b0)) if a0 != b0 else np.zeros(len(pois), bool)
    start_len = float(np.linalg.norm(graph.nodes_world[b0] - graph.nodes_world[a0]))
    out[same] = np.minimum(out[same], np.abs(pois.t[same] - t0) * start_len)
    return out
