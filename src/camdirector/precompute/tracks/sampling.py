"""Ray-cast camera samples from the skeleton (Section 4.2).

Origins are taken every `skeleton_spacing_m` along each skeleton segment, raised to the agent's
eye (`eye_height_fraction` of its height). From each origin, rays leave orthogonally to the
segment in the cinematographic directions of `ray_elevations_deg`: the horizontal normal of the
segment, on both sides, tilted up by each elevation (0 eye level, 30 high angle, -15 low angle,
90 bird's eye straight up, cast once). A ray that hits the level places its camera `epsilon_m`
before the hit; a ray that hits nothing places it at `d_max_m`. Samples closer than
`min_camera_distance_m` to their origin are dropped (a wall right beside the skeleton). With
`include_skeleton_points` the origins themselves join the cloud (Figure 6).

Footprint (ours; the paper keeps every sample, Section 4.2): given the navmesh, samples farther
than `footprint_margin_m` horizontally from it are dropped. On open terrain a ray leaving the
level's edge hits nothing and places its camera at d_max off the edge, where RANSAC strings such
samples into tracks beside the level that film it from outside. Test: the navmesh's edges are
split to at most the margin, and a sample is kept when a vertex lies within the margin of it in
(x, z): every sample over the navmesh is kept (a vertex is within margin / sqrt(3) of it), every
sample farther than the margin from it is dropped. Height is not tested, so a sample above or
below another floor counts as inside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import UP_WORLD
from camdirector.precompute.tracks.navmesh import refine_triangles
from camdirector.precompute.tracks.skeleton import Skeleton
from camdirector.precompute.tracks.track_settings import TrackSettings

SKELETON_DIRECTION = -1  # `direction` of samples that are skeleton points


@dataclass(frozen=True)
class CameraSamples:
    """position_world: (n, 3) camera positions, metres; origin_world: (n, 3) the skeleton point
    (at eye height) each was cast from; ray_world: (n, 3) unit ray direction (0 for skeleton
    points); direction: (n,) int index into `ray_elevations_deg`, SKELETON_DIRECTION for skeleton
    points; segment: (n,) int skeleton segment of the origin."""

    position_world: np.ndarray
    origin_world: np.ndarray
    ray_world: np.ndarray
    direction: np.ndarray
    side: np.ndarray
    segment: np.ndarray

    @property
    def group(self) -> np.ndarray:
        """(n,) int: one value per (direction, side), what RANSAC clusters separately."""
        return 3 * (self.direction + 1) + self.side + 1

    def __len__(self) -> int:
        return len(self.position_world)


def skeleton_origins(skeleton: Skeleton, spacing_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points every spacing_m along each segment (endpoints included, at least the midpoint):
    (p, 3) points on the navmesh, (p, 3) unit segment tangents, (p,) int segment index."""
    seg = skeleton.segments_world
    if not len(seg):
        return np.empty((0, 3)), np.empty((0, 3)), np.empty(0, np.int64)
    delta = seg[:, 1] - seg[:, 0]
    length = np.linalg.norm(delta, axis=1)
    count = np.maximum(np.floor(length / spacing_m).astype(np.int64) + 1, 1)
    index = np.repeat(np.arange(len(seg)), count)
    step = np.arange(len(index)) - np.repeat(np.cumsum(count) - count, count)
    frac = np.where(count[index] > 1, step / np.maximum(count[index] - 1, 1), 0.5)
    return seg[index, 0] + frac[:, None] * delta[index], delta[index] / length[index, None], index


def inside_footprint(points_world: np.ndarray, navmesh: TriMesh, margin_m: float) -> np.ndarray:
    """(n,) bool: points (n, 3) within margin_m of the navmesh in (x, z) (module docstring)."""
    if not len(points_world) or not navmesh.triangle_count:
        return np.zeros(len(points_world), dtype=bool)
    vertices, _ = refine_triangles(navmesh.vertices, navmesh.faces, max_edge_m=margin_m)
    distance, _ = cKDTree(vertices[:, [0, 2]]).query(points_world[:, [0, 2]], distance_upper_bound=margin_m)
    return np.isfinite(distance)


def sample_cameras(skeleton: Skeleton, scene: RayScene, settings: TrackSettings, navmesh: TriMesh | None = None) -> CameraSamples:
    """Camera samples of the module docstring; scene is the level (static geometry); navmesh,
    when given, bounds the samples to its footprint."""
    ground, tangent, segment = skeleton_origins(skeleton, settings.skeleton_spacing_m)
    origin = ground + settings.eye_height_fraction * settings.agent_height_m * UP_WORLD
    side = np.cross(tangent, UP_WORLD)
    side_norm = np.linalg.norm(side, axis=1, keepdims=True)
    flat = side_norm[:, 0] < 1e-6  # a vertical skeleton piece: any horizontal normal
    side = np.where(flat[:, None], np.array([1.0, 0.0, 0.0]), side / np.maximum(side_norm, 1e-12))
    rays, kinds, sides, owners = [], [], [], []
    for k, elevation in enumerate(np.radians(settings.ray_elevations_deg)):
        signs = (1.0,) if np.isclose(abs(elevation), np.pi / 2) else (1.0, -1.0)
        for sign in signs:
            rays.append(np.cos(elevation) * sign * side + np.sin(elevation) * UP_WORLD)
            kinds.append(np.full(len(origin), k))
            sides.append(np.full(len(origin), 0 if len(signs) == 1 else int(sign)))
            owners.append(np.arange(len(origin)))
    if not rays or not len(origin):
        return CameraSamples(
            np.empty((0, 3)),
            np.empty((0, 3)),
            np.empty((0, 3)),
            np.empty(0, np.int64),
            np.empty(0, np.int64),
            np.empty(0, np.int64),
        )
    ray = np.concatenate(rays)
    owner = np.concatenate(owners)
    kind = np.concatenate(kinds)
    side_of = np.concatenate(sides)
    hit_t = scene.first_hit(origin[owner], ray)
    distance = np.where(np.isfinite(hit_t), np.minimum(hit_t - settings.epsilon_m, settings.d_max_m), settings.d_max_m)
    position = origin[owner] + distance[:, None] * ray
    keep = distance >= max(settings.min_camera_distance_m, 1e-6)
    if navmesh is not None:
        keep &= inside_footprint(position, navmesh, settings.footprint_margin_m)
    position = position[keep]
    parts = [(position, origin[owner[keep]], ray[keep], kind[keep], side_of[keep], segment[owner[keep]])]
    if settings.include_skeleton_points:
        parts.append(
            (
                origin,
                origin,
                np.zeros_like(origin),
                np.full(len(origin), SKELETON_DIRECTION),
                np.zeros(len(origin), np.int64),
                segment,
            )
        )
    return CameraSamples(*(np.concatenate(p) for p in zip(*parts)))
