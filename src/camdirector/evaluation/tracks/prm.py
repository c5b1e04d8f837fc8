"""A probabilistic roadmap (PRM) on the same level, the paper's baseline (Section 6.2).

Nodes are drawn at random over the navigation mesh (area-weighted triangles, uniform points),
`density_per_m2` per square metre of navmesh, each raised to a random camera height between the
agent's eye (0.9 of its height) and `d_max_m` above the floor, like our samples' range; a node
whose vertical segment down to the floor is blocked is redrawn once and otherwise dropped (it
would be inside geometry). Every pair of nodes closer than `link_distance_m` whose segment is
free is an edge. The result is a `CameraGraph`, so the same director, visibility table and
measures run on it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import UP_WORLD
from camdirector.precompute.tracks.graph import CameraGraph
from camdirector.precompute.tracks.navmesh import triangle_areas
from camdirector.precompute.tracks.track_settings import TrackSettings


def _draw(navmesh: TriMesh, count: int, settings: TrackSettings, rng: np.random.Generator):
    area = triangle_areas(navmesh.vertices, navmesh.faces)
    tri = rng.choice(len(area), size=count, p=area / area.sum())
    t = navmesh.vertices[navmesh.faces[tri]]
    r1, r2 = np.sqrt(rng.random(count)), rng.random(count)
    floor = (1 - r1)[:, None] * t[:, 0] + (r1 * (1 - r2))[:, None] * t[:, 1] + (r1 * r2)[:, None] * t[:, 2]
    low = 0.9 * settings.agent_height_m
    height = low + rng.random(count) * max(settings.d_max_m - low, 0.0)
    return floor, floor + height[:, None] * UP_WORLD


def build_prm(
    navmesh: TriMesh,
    scene: RayScene,
    settings: TrackSettings,
    density_per_m2: float,
    link_distance_m: float,
    rng: np.random.Generator,
) -> CameraGraph:
    """PRM of the module docstring."""
    count = max(1, int(round(density_per_m2 * triangle_areas(navmesh.vertices, navmesh.faces).sum())))
    floor, node = _draw(navmesh, count, settings, rng)
    blocked = scene.occluded(floor + 0.05 * UP_WORLD, node)
    if blocked.any():
        floor2, node2 = _draw(navmesh, int(blocked.sum()), settings, rng)
        node[blocked] = node2
        blocked[blocked] = scene.occluded(floor2 + 0.05 * UP_WORLD, node2)
    node = node[~blocked]
    pairs = cKDTree(node).query_pairs(link_distance_m, output_type="ndarray") if len(node) > 1 else np.empty((0, 2), np.int64)
    if len(pairs):
        pairs = pairs[~scene.occluded(node[pairs[:, 0]], node[pairs[:, 1]])]
    edges = np.unique(np.sort(pairs, axis=1), axis=0) if len(pairs) else np.empty((0, 2), np.int64)
    return CameraGraph(node, edges.astype(np.int64), np.zeros(len(edges), dtype=bool))
