"""Actor routes on a level: Recast's test cases where they apply, else A* paths on the navmesh.

`RecastDemo/Bin/TestCases/nav_mesh_test.txt` lists path-find queries for nav_test.obj as lines
`pf sx sy sz ex ey ez includeFlags excludeFlags` (metres, the level's frame). A route is the A*
path over navmesh triangles (centroid to centroid across shared vertices or steps, costs in
metres) from the triangle nearest the start to the one nearest the end, walked at a constant
speed and sampled at a frame rate.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from camdirector.geometry.meshes import TriMesh
from camdirector.precompute.tracks.graph import adjacency_lists, astar_many
from camdirector.precompute.tracks.navmesh import navmesh_components, triangle_adjacency
from camdirector.precompute.tracks.settings import TrackSettings


@dataclass(frozen=True)
class ActorRoute:
    """time_s (F,), position_world (F, 3) the actor's feet, forward_world (F, 3) unit facing."""

    time_s: np.ndarray
    position_world: np.ndarray
    forward_world: np.ndarray


def read_recast_queries(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """(start (3,), end (3,)) of every `pf` line of a Recast test-case file."""
    queries = []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if len(parts) >= 7 and parts[0] == "pf":
            values = np.array([float(x) for x in parts[1:7]])
            queries.append((values[:3], values[3:]))
    return queries


class NavmeshPaths:
    """A* over the triangles of a navigation mesh (metres, world frame)."""

    def __init__(self, navmesh: TriMesh, settings: TrackSettings):
        self.centroids = navmesh.vertices[navmesh.faces].mean(axis=1)
        adjacency = triangle_adjacency(navmesh, settings.agent_max_climb_m, 0.5 * settings.navmesh_cell_m).tocoo()
        off = adjacency.row != adjacency.col
        rows, cols = adjacency.row[off], adjacency.col[off]
        order = np.argsort(rows, kind="stable")
        rows, cols = rows[order], cols[order]
        self._adjacency = adjacency_lists(np.searchsorted(rows, np.arange(len(self.centroids) + 1)), cols,
                                          np.linalg.norm(self.centroids[rows] - self.centroids[cols], axis=1))
        self._positions = self.centroids.tolist()
        self.component = navmesh_components(navmesh, settings)
        self._tree = cKDTree(self.centroids)

    def path(self, start_world: np.ndarray, end_world: np.ndarray) -> np.ndarray | None:
        """(p, 3) polyline from start to end through triangle centroids, or None when unconnected."""
        s = int(self._tree.query(start_world)[1])
        e = int(self._tree.query(end_world)[1])
        parent: dict[int, int] = {}
        found = astar_many(self._adjacency, self._positions, {s: 0.0}, {e}, np.inf, parent)
        if e not in found:
            return None
        chain = [e]
        while chain[-1] != s:
            chain.append(parent[chain[-1]])
        points = self.centroids[chain[::-1]]
        return np.vstack([points[:1] if s == e else points, points[-1:]])

    def random_path(self, rng: np.random.Generator, min_length_m: float, tries: int = 50) -> np.ndarray | None:
        """A path between random triangles of the largest region, at least min_length_m long when
        one of `tries` draws finds it (else the longest found)."""
        largest = np.flatnonzero(self.component == np.bincount(self.component).argmax())
        best, best_len = None, -1.0
        for _ in range(tries):
            a, b = rng.choice(largest, size=2)
            path = self.path(self.centroids[a], self.centroids[b])
            if path is None:
                continue
            length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
            if length > best_len:
                best, best_len = path, length
            if length >= min_length_m:
                break
        return best


def walk(polyline_world: np.ndarray, speed_m_s: float, frame_rate_hz: float) -> ActorRoute:
    """The actor walking a polyline (p, 3) at a constant speed, one sample per frame."""
    seg = np.diff(polyline_world, axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 1e-9
    points = np.vstack([polyline_world[:1], polyline_world[1:][keep]])
    cumulative = np.concatenate([[0.0], np.cumsum(length[keep])])
    total = cumulative[-1]
    times = np.arange(0.0, total / speed_m_s + 1e-9, 1.0 / frame_rate_hz)
    travelled = np.minimum(times * speed_m_s, total)
    position = np.stack([np.interp(travelled, cumulative, points[:, k]) for k in range(3)], axis=1)
    heading = np.diff(position, axis=0, append=position[-1:] + (position[-1:] - position[-2:-1] if len(position) > 1
                                                                 else np.array([[0.0, 0.0, 1.0]])))
    heading[:, 1] = 0.0
    norm = np.linalg.norm(heading, axis=1, keepdims=True)
    heading = np.where(norm > 1e-9, heading / np.maximum(norm, 1e-12), np.array([0.0, 0.0, 1.0]))
    return ActorRoute(times, position, heading)
