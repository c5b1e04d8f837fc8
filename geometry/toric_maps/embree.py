"""S-maps and V-maps by ray casting with Embree (embreex): the reference the GL backend is held to.

Paper: occlusion-anticipation-toric-space.md sections 4.1.1 and 4.1.2, computed by rays instead of
by deferred projection. For each sample point s and each texel, one segment from s to the texel's
torus point P: the S-map is whether it hits anything, the V-map the first hit's rigid velocity
v + w x (p - c) minus the torus point's velocity, in Toric angular rates.

All k * res * res rays go in one call per Embree scene. Static meshes share one scene built once
(embreex copies a mesh at about 1 us per triangle and cannot move vertices, DESIGN.md); each moving
object keeps a scene in its local frame and a query transforms the rays into it (o' = M^-1 o,
d' = M^-1 d: the ray parameter t names the same point in both frames), after a bounding-sphere test
that keeps only the rays passing near the object.
"""
from __future__ import annotations

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.toric import Torus
from camdirector.geometry.toric_maps.base import (
    NOT_OCCLUDED_DEPTH,
    SAMPLE_CLEARANCE_M,
    SEGMENT_END_MARGIN,
    MapWindow,
    OccluderScene,
    ShadowVelocityMaps,
    check_compute_args,
    texture_velocity,
    torus_point_velocity,
    torus_points,
    torus_tangents,
)

_NO_HIT = -1  # embreex's answer for a ray that hits nothing


def _embree_scene(meshes: list[TriMesh]) -> rtcore_scene.EmbreeScene:
    scene = rtcore_scene.EmbreeScene()
    vertices = np.concatenate([m.vertices for m in meshes]).astype(np.float32)
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    faces = np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]).astype(np.int32)
    TriangleMesh(scene, vertices, faces)
    return scene


class EmbreeMapBackend:
    """MapBackend by ray casting; holds Embree scenes mirroring an OccluderScene."""

    name = "embree"

    def __init__(self, scene: OccluderScene):
        self.scene = scene
        self._version = -1
        self._static: rtcore_scene.EmbreeScene | None = None
        self._dynamic: dict[str, rtcore_scene.EmbreeScene] = {}

    def _sync(self) -> None:
        if self._version == self.scene.geometry_version:
            return
        static = list(self.scene.static_meshes_world)
        self._static = _embree_scene(static) if static else None
        # Scenes of objects that are still there are kept: their local meshes do not change.
        self._dynamic = {oid: self._dynamic.get(oid) or _embree_scene([obj.mesh_local])
                         for oid, obj in self.scene.dynamic.items()}
        self._version = self.scene.geometry_version

    def compute(self, torus: Torus, window: MapWindow, sample_points_world, *, exclude_ids=None,
                previous_torus: Torus | None = None, dt_s: float = 0.0) -> ShadowVelocityMaps:
        """See base.MapBackend.compute. Cost: one Embree query of k * res^2 rays for the static
        scene, plus one per moving object for the rays that pass near it."""
        points, excluded = check_compute_args(window, sample_points_world, exclude_ids, previous_torus, dt_s)
        self._sync()
        k, n = len(points), window.resolution
        torus_world = torus_points(torus, window).reshape(1, -1, 3)                  # (1, m, 3), m = res^2
        m = torus_world.shape[1]
        rel = torus_world - points[:, None, :]                                       # (k, m, 3): P - s
        length = np.sqrt(np.einsum("kmc,kmc->km", rel, rel))                         # (k, m)
        # Rays start SAMPLE_CLEARANCE_M from s (embreex has no tnear) and end just short of P.
        t_start = np.minimum(SAMPLE_CLEARANCE_M / np.maximum(length, 1e-12), 0.5)
        start = (points[:, None, :] + rel * t_start[..., None]).astype(np.float32).reshape(-1, 3)
        dirs = rel.astype(np.float32).reshape(-1, 3)
        t_limit = ((1.0 - SEGMENT_END_MARGIN) - t_start).astype(np.float32).ravel()  # ray parameter from `start`
        t_best = t_limit.copy()
        hit_object = np.full(k * m, -1, dtype=np.int32)                              # -1: static or none
        if self._static is not None:
            # Occlusion for every ray, then first hits only where something was hit: the cheap
            # query does most of the work (first hits cost about 3x more per ray here).
            hit = np.flatnonzero(self._static.run(start, dirs, dists=t_limit.copy(), query="OCCLUDED") != _NO_HIT)
            if len(hit):
                t_best[hit] = self._static.run(start[hit], dirs[hit], dists=t_limit[hit].copy(), query="DISTANCE")
        self._cast_dynamic(points, rel, length, t_start, start, dirs, excluded, t_best, hit_object)

        occluded = t_best < t_limit
        t_total = t_start.ravel() + t_best.astype(np.float64)
        velocity_world = np.zeros((k * m, 3))
        objects = list(self.scene.dynamic.values())
        for index in np.unique(hit_object[occluded & (hit_object >= 0)]):
            rays = np.flatnonzero(occluded & (hit_object == index))
            hit_world = points[rays // m] + rel.reshape(-1, 3)[rays] * t_total[rays, None]
            velocity_world[rays] = objects[index].point_velocity(hit_world)
        relative = velocity_world.reshape(k, n, n, 3) - torus_point_velocity(torus, window, previous_torus, dt_s)
        d_theta, d_phi = torus_tangents(torus, window)
        shadow = occluded.reshape(k, n, n)
        velocity = texture_velocity(relative, d_theta, d_phi) * shadow[..., None]
        depth = np.where(occluded, t_total * length.ravel(), NOT_OCCLUDED_DEPTH).reshape(k, n, n)
        return ShadowVelocityMaps(window=window, shadow=shadow.astype(np.float32),
                                  velocity_rad_s=velocity.astype(np.float32), depth_m=depth.astype(np.float32))

    def _cast_dynamic(self, points, rel, length, t_start, start, dirs, excluded, t_best, hit_object) -> None:
        """First hits on the moving objects, updating t_best and hit_object in place.

        Culling, cheapest first: a (object, sample) pair is skipped when the object's bounding
        sphere lies outside the cone of the sample's rays or beyond the torus; for the pairs left,
        only the rays whose line passes within the sphere are cast, transformed into the object's
        frame.
        """
        if not self.scene.dynamic:
            return
        k, m = length.shape
        unit = rel / np.maximum(length, 1e-12)[..., None]                          # (k, m, 3)
        axis = unit.sum(axis=1)
        axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)      # (k, 3)
        cos_half = np.einsum("kmc,kc->km", unit, axis).min(axis=1)                  # (k,) cone half-angle cosine
        half = np.arccos(np.clip(cos_half, -1.0, 1.0))
        reach = length.max(axis=1)                                                  # (k,) farthest torus point
        for index, (object_id, obj) in enumerate(self.scene.dynamic.items()):
            center, radius = obj.bounding_sphere_world()
            to_center = center - points                                             # (k, 3)
            dist = np.linalg.norm(to_center, axis=1)
            off_axis = np.arccos(np.clip(np.einsum("kc,kc->k", to_center, axis) / np.maximum(dist, 1e-12), -1.0, 1.0))
            spread = np.arcsin(np.clip(radius / np.maximum(dist, 1e-12), 0.0, 1.0))
            candidates = (dist <= radius) | ((off_axis <= half + spread) & (dist - radius <= reach))
            rays = []
            for sample in np.flatnonzero(candidates):
                if excluded[sample] == object_id:  # the sample's own target does not hide it (section 4.1)
                    continue
                along = unit[sample] @ to_center[sample]                             # (m,)
                miss2 = dist[sample] ** 2 - along * along
                limit = (t_start[sample] + t_best[sample * m:(sample + 1) * m]) * length[sample]
                near = (miss2 <= radius * radius) & (along >= -radius) & (along <= limit + radius)
                rays.append(np.flatnonzero(near) + sample * m)
            rays = np.concatenate(rays) if rays else np.empty(0, dtype=np.intp)
            if len(rays) == 0:
                continue
            world_to_local = np.linalg.inv(obj.transform.matrix())
            o = start[rays].astype(np.float64) @ world_to_local[:3, :3].T + world_to_local[:3, 3]
            d = dirs[rays].astype(np.float64) @ world_to_local[:3, :3].T
            t = self._dynamic[object_id].run(o.astype(np.float32), d.astype(np.float32),
                                             dists=t_best[rays].copy(), query="DISTANCE")
            closer = t < t_best[rays]
            t_best[rays[closer]] = t[closer]
            hit_object[rays[closer]] = index

    def close(self) -> None:
        self._static = None
        self._dynamic = {}
        self._version = -1
