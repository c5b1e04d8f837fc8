"""S-maps and V-maps by ray casting with Embree (embreex): the reference the GL backend is held to.

Paper: occlusion-anticipation-toric-space.md sections 4.1.1 and 4.1.2, computed by rays instead of
by deferred projection. For each sample point s and each texel, one segment from s to the texel's
torus point P: the S-map is whether it hits anything, the V-map the first hit's rigid velocity
v + w x (p - c) minus the torus point's velocity, in Toric angular rates.

All k * res^2 rays go in one call per Embree scene and query kind. Occlusion is asked first for
every ray and first hits only for the rays that hit (first hits cost about three times more). The
static meshes share one scene built when the geometry changes (embreex copies a mesh at about
0.5-1 us per triangle and cannot move vertices, DESIGN.md). Moving objects, whose poses change
every frame, are handled in one of two ways (EmbreeMapSettings.rebuild_triangles_per_ray):

- few moving triangles (the usual case): world-space scenes of them are rebuilt per call, one
  Embree geometry per object, so a hit's geomID names the object;
- many: each object keeps a scene in its local frame and the rays that pass near its bounding
  sphere are transformed into it (o' = M^-1 o, d' = M^-1 d: the ray parameter names the same point
  in both frames), one query per object.

A sample point ignores its own target (section 4.1, "without the object o"): an object that some
sample ignores gets a world-space scene of its own, cast only with the other samples' rays.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.toric import Torus
from camdirector.geometry.toric_maps.base import (
    NOT_OCCLUDED_DEPTH,
    SAMPLE_CLEARANCE_M,
    SEGMENT_END_MARGIN,
    DynamicOccluder,
    MapWindow,
    OccluderScene,
    ShadowVelocityMaps,
    check_compute_args,
    texture_velocity,
    torus_points,
    torus_tangents,
)
from camdirector.geometry.transforms import quat_to_matrix

_NO_HIT = -1  # embreex's answer for a ray that hits nothing


@dataclass(frozen=True)
class EmbreeMapSettings:
    # Moving objects are rebuilt into world-space scenes when they have at most this many triangles
    # per ray of the call, else cast one by one in their local frames. Rebuilding costs about
    # 0.4 ms per 1,000 triangles per call here, the local casts about 1 ms per 2 samples at 64 x 64
    # whatever the triangle count (2-core CPU, 30 moving cylinders): rebuilding wins at 10 samples
    # with 2,000 moving triangles (6.6 vs 8.8 ms), loses at 2 samples (3.2 vs 2.6 ms).
    rebuild_triangles_per_ray: float = 0.125  # [0, 1000]

    def __post_init__(self) -> None:
        if not 0.0 <= self.rebuild_triangles_per_ray <= 1000.0:
            raise ValueError("EmbreeMapSettings: rebuild_triangles_per_ray must be in [0, 1000]")


def _embree_scene(meshes: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]]) -> rtcore_scene.EmbreeScene:
    """One Embree geometry per (vertices (n, 3), faces (m, 3)), geomID = list index."""
    scene = rtcore_scene.EmbreeScene()
    for vertices, faces in meshes:
        TriangleMesh(scene, np.ascontiguousarray(vertices, dtype=np.float32), np.ascontiguousarray(faces, dtype=np.int32))
    return scene


def _merged(meshes: list[TriMesh]) -> list[tuple[npt.NDArray[np.float64], npt.NDArray[np.signedinteger]]]:
    """All meshes as one geometry (fewer Embree objects; static hits need no id)."""
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return [(np.concatenate([m.vertices for m in meshes]), np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]))]


class EmbreeMapBackend:
    """MapBackend by ray casting; holds Embree scenes mirroring an OccluderScene."""

    name = "embree"

    def __init__(self, scene: OccluderScene, settings: EmbreeMapSettings = EmbreeMapSettings()):
        self.scene = scene
        self.settings = settings
        self._version = -1
        self._static: rtcore_scene.EmbreeScene | None = None
        self._local: dict[str, rtcore_scene.EmbreeScene] = {}

    def __reduce__(self) -> tuple[type[EmbreeMapBackend], tuple[OccluderScene, EmbreeMapSettings]]:
        """Pickled as its scene and settings: the Embree scenes are built again on first use."""
        return EmbreeMapBackend, (self.scene, self.settings)

    def _sync(self) -> None:
        if self._version == self.scene.geometry_version:
            return
        static = list(self.scene.static_meshes_world)
        self._static = _embree_scene(_merged(static)) if static else None
        self._local = {}  # per-object local scenes, built on demand
        self._version = self.scene.geometry_version

    def compute(
        self,
        torus: Torus,
        window: MapWindow,
        sample_points_world: npt.ArrayLike,
        *,
        exclude_ids: Sequence[str | None] | None = None,
        previous_torus: Torus | None = None,
        dt_s: float = 0.0,
    ) -> ShadowVelocityMaps:
        """See base.MapBackend.compute."""
        points, excluded = check_compute_args(window, sample_points_world, exclude_ids, previous_torus, dt_s)
        self._sync()
        k, n = len(points), window.resolution
        torus_world = torus_points(torus, window).reshape(-1, 3)  # (m, 3), m = res^2
        m = len(torus_world)
        rel = (torus_world[None, :, :] - points[:, None, :]).reshape(-1, 3)  # (k m, 3): P - s
        length = np.sqrt(np.einsum("ij,ij->i", rel, rel))  # (k m,)
        # Rays start SAMPLE_CLEARANCE_M from s (embreex has no tnear) and end just short of P.
        t_start = np.minimum(SAMPLE_CLEARANCE_M / np.maximum(length, 1e-12), 0.5).astype(np.float32)
        dirs = rel.astype(np.float32)
        start = np.repeat(points.astype(np.float32), m, axis=0)
        start += dirs * t_start[:, None]
        t_limit = np.float32(1.0 - SEGMENT_END_MARGIN) - t_start  # ray parameter from `start`
        t_best = t_limit.copy()
        hit_object = np.full(k * m, -1, dtype=np.int32)  # -1: static or none
        if self._static is not None:
            hit = np.flatnonzero(self._static.run(start, dirs, dists=t_limit.copy(), query="OCCLUDED") != _NO_HIT)
            if len(hit):
                t_best[hit] = self._static.run(start[hit], dirs[hit], dists=t_limit[hit].copy(), query="DISTANCE")
        objects = list(self.scene.dynamic.values())
        if objects:
            ids = list(self.scene.dynamic)
            own = np.array([ids.index(e) if e in self.scene.dynamic else -1 for e in excluded], dtype=np.int32)
            moving_triangles = sum(o.mesh_local.triangle_count for o in objects)
            if moving_triangles <= self.settings.rebuild_triangles_per_ray * k * m:
                self._cast_world(objects, own, start, dirs, t_best, hit_object, m)
            else:
                self._cast_local(
                    objects, points, rel.reshape(k, m, 3), length.reshape(k, m), t_start, start, dirs, own, t_best, hit_object
                )

        # Velocities only where occluded: the first hit's rigid motion minus the torus point's.
        hits = np.flatnonzero(t_best < t_limit)
        t_total = t_start[hits] + t_best[hits].astype(np.float64)
        texel = hits % m
        velocity_world = np.zeros((len(hits), 3))
        for index in np.unique(hit_object[hits]):
            if index >= 0:
                mine = np.flatnonzero(hit_object[hits] == index)
                hit_world = points[hits[mine] // m] + rel[hits[mine]] * t_total[mine, None]
                velocity_world[mine] = objects[index].point_velocity(hit_world)
        if previous_torus is not None:
            moved = (torus_world - torus_points(previous_torus, window).reshape(-1, 3)) / dt_s
            velocity_world -= moved[texel]
        d_theta, d_phi = torus_tangents(torus, window)
        shadow = np.zeros(k * m, dtype=np.float32)
        shadow[hits] = 1.0
        velocity = np.zeros((k * m, 2), dtype=np.float32)
        velocity[hits] = texture_velocity(velocity_world, d_theta.reshape(-1, 3)[texel], d_phi.reshape(-1, 3)[texel])
        depth = np.full(k * m, NOT_OCCLUDED_DEPTH, dtype=np.float32)
        depth[hits] = t_total * length[hits]
        return ShadowVelocityMaps(
            window=window,
            shadow=shadow.reshape(k, n, n),
            velocity_rad_s=velocity.reshape(k, n, n, 2),
            depth_m=depth.reshape(k, n, n),
        )

    def _cast_world(
        self,
        objects: list[DynamicOccluder],
        own: npt.NDArray[np.int32],
        start: npt.NDArray[np.float32],
        dirs: npt.NDArray[np.float32],
        t_best: npt.NDArray[np.float32],
        hit_object: npt.NDArray[np.int32],
        m: int,
    ) -> None:
        """First hits on the moving objects, posed in world-space scenes built for this call.

        Objects no sample ignores share one scene; each object some sample ignores (its own target)
        gets a scene of its own, cast only with the rays of the other samples.
        """
        ignored = sorted({int(i) for i in own if i >= 0})
        shared = [i for i in range(len(objects)) if i not in ignored]
        groups = [(shared, np.arange(len(own)))] if shared else []
        groups += [([i], np.flatnonzero(own != i)) for i in ignored]
        for members, samples in groups:
            if len(samples) == 0:
                continue
            scene = _embree_scene(
                [(objects[i].transform.apply(objects[i].mesh_local.vertices), objects[i].mesh_local.faces) for i in members]
            )
            rays = (samples[:, None] * m + np.arange(m)[None, :]).ravel() if len(samples) < len(own) else None
            s, d, t = (start, dirs, t_best) if rays is None else (start[rays], dirs[rays], t_best[rays])
            hit = np.flatnonzero(scene.run(s, d, dists=t.copy(), query="OCCLUDED") != _NO_HIT)
            if len(hit) == 0:
                continue
            found = scene.run(s[hit], d[hit], dists=t[hit].copy(), output=True)
            first = found["geomID"] != _NO_HIT
            index = hit[first] if rays is None else rays[hit[first]]
            t_best[index] = found["tfar"][first]
            hit_object[index] = np.asarray(members, dtype=np.int32)[found["geomID"][first]]

    def _cast_local(
        self,
        objects: list[DynamicOccluder],
        points: npt.NDArray[np.float64],
        rel: npt.NDArray[np.float64],
        length: npt.NDArray[np.float64],
        t_start: npt.NDArray[np.float32],
        start: npt.NDArray[np.float32],
        dirs: npt.NDArray[np.float32],
        own: npt.NDArray[np.int32],
        t_best: npt.NDArray[np.float32],
        hit_object: npt.NDArray[np.int32],
    ) -> None:
        """First hits on the moving objects, one local-frame scene each, for the rays that pass near.

        Culling, cheapest first, for all (object, sample) pairs at once: a pair is skipped when the
        object's bounding sphere lies outside the cone of the sample's rays or beyond the torus;
        for the pairs left, only the rays whose line passes within the sphere are cast.
        """
        k, m = length.shape
        unit = rel / np.maximum(length, 1e-12)[..., None]  # (k, m, 3)
        axis = unit.sum(axis=1)
        axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)  # (k, 3)
        half = np.arccos(np.clip(np.einsum("kmc,kc->km", unit, axis).min(axis=1), -1.0, 1.0))
        reach = length.max(axis=1)  # (k,) farthest torus point
        rotation = quat_to_matrix(np.stack([o.transform.rotation_xyzw for o in objects]))  # (N, 3, 3)
        scale = np.stack([o.transform.scale for o in objects])  # (N, 3)
        position = np.stack([o.transform.position_world for o in objects])  # (N, 3)
        centers = np.einsum("nij,nj->ni", rotation, np.stack([o.bound_center_local for o in objects]) * scale) + position
        radii = np.array([o.bound_radius_local for o in objects]) * np.abs(scale).max(axis=1)
        to_center = centers[:, None, :] - points[None, :, :]  # (N, k, 3)
        dist = np.linalg.norm(to_center, axis=2)
        off_axis = np.arccos(np.clip(np.einsum("nkc,kc->nk", to_center, axis) / np.maximum(dist, 1e-12), -1.0, 1.0))
        spread = np.arcsin(np.clip(radii[:, None] / np.maximum(dist, 1e-12), 0.0, 1.0))
        candidates = (dist <= radii[:, None]) | ((off_axis <= half + spread) & (dist - radii[:, None] <= reach))
        candidates &= own[None, :] != np.arange(len(objects))[:, None]
        object_ids = list(self.scene.dynamic)
        for index in np.flatnonzero(candidates.any(axis=1)):
            chosen = []
            for sample in np.flatnonzero(candidates[index]):
                along = unit[sample] @ to_center[index, sample]  # (m,)
                miss2 = dist[index, sample] ** 2 - along * along
                span = slice(sample * m, (sample + 1) * m)
                limit = (t_start[span] + t_best[span]) * length[sample]
                r2 = radii[index] ** 2
                near = (miss2 <= r2) & (along >= -radii[index]) & (along <= limit + radii[index])
                chosen.append(np.flatnonzero(near) + sample * m)
            rays = np.concatenate(chosen)
            if len(rays) == 0:
                continue
            object_id = object_ids[index]
            local = self._local.get(object_id)
            if local is None:
                mesh = objects[index].mesh_local
                local = self._local[object_id] = _embree_scene([(mesh.vertices, mesh.faces)])
            # world -> local: p_local = S^-1 R^T (p - t); the same linear map takes directions.
            to_local = rotation[index].T / scale[index][:, None]
            o = (start[rays].astype(np.float64) - position[index]) @ to_local.T
            d = dirs[rays].astype(np.float64) @ to_local.T
            t = local.run(o.astype(np.float32), d.astype(np.float32), dists=t_best[rays].copy(), query="DISTANCE")
            closer = t < t_best[rays]
            t_best[rays[closer]] = t[closer]
            hit_object[rays[closer]] = index

    def close(self) -> None:
        self._static = None
        self._local = {}
        self._version = -1
