"""Occlusion queries by ray casting with Embree (embreex), for scenes with moving rigid objects.

embreex copies a mesh at about 1 us per triangle and cannot update vertices, so static geometry
lives in one Embree scene built once, and each dynamic object keeps its own scene in its local
frame: a query transforms the rays into each object's frame (o' = M^-1 o, d' = M^-1 d, so the ray
parameter t means the same point in both frames) instead of rebuilding anything when it moves.
"""
from __future__ import annotations

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.transforms import RigidTransform

_NO_HIT = -1
_EMBREE_MISS = 1e30  # embreex reports a miss as tfar = 1e37


def _embree_scene(meshes: list[TriMesh]) -> rtcore_scene.EmbreeScene:
    scene = rtcore_scene.EmbreeScene()
    for mesh in meshes:
        TriangleMesh(scene, mesh.vertices.astype(np.float32), mesh.faces)
    return scene


class RayScene:
    """Static meshes (world frame, built once) plus dynamic rigid objects (local frame + transform)."""

    def __init__(self, static_meshes_world: list[TriMesh]):
        self._static = _embree_scene(static_meshes_world) if static_meshes_world else None
        self._dynamic: dict[str, tuple[rtcore_scene.EmbreeScene, np.ndarray]] = {}

    def add_dynamic(self, object_id: str, mesh_local: TriMesh, transform: RigidTransform) -> None:
        self._dynamic[object_id] = (_embree_scene([mesh_local]), transform.inverse_matrix())

    def set_transform(self, object_id: str, transform: RigidTransform) -> None:
        scene, _ = self._dynamic[object_id]
        self._dynamic[object_id] = (scene, transform.inverse_matrix())

    def occluded(self, origins_world: np.ndarray, targets_world: np.ndarray) -> np.ndarray:
        """Whether the segment from each origin to its target crosses any geometry.

        origins_world, targets_world: (n, 3) float64 metres (an origin may be (3,), broadcast).
        Returns (n,) bool. The segment stops just short of the target so a point on a surface
        does not occlude itself.
        """
        targets = np.atleast_2d(targets_world)
        origins = np.broadcast_to(origins_world, targets.shape)
        directions = targets - origins
        tmax = np.full(len(targets), 1.0 - 1e-4, dtype=np.float32)
        hit = np.zeros(len(targets), dtype=bool)
        if self._static is not None:
            hit |= self._static.run(origins.astype(np.float32), directions.astype(np.float32),
                                    dists=tmax.copy(), query="OCCLUDED") != _NO_HIT
        for scene, world_to_local in self._dynamic.values():
            rest = ~hit
            if not rest.any():
                break
            o = origins[rest] @ world_to_local[:3, :3].T + world_to_local[:3, 3]
            d = directions[rest] @ world_to_local[:3, :3].T
            hit[rest] = scene.run(o.astype(np.float32), d.astype(np.float32),
                                  dists=tmax[rest].copy(), query="OCCLUDED") != _NO_HIT
        return hit

    def first_hit(self, origins_world: np.ndarray, directions_world: np.ndarray) -> np.ndarray:
        """Ray parameter of the nearest hit along each ray, in units of the direction's length.

        origins_world (n, 3) or (3,), directions_world (n, 3) float64. Returns (n,) float64, inf
        where nothing is hit.
        """
        directions = np.atleast_2d(directions_world)
        origins = np.broadcast_to(origins_world, directions.shape)
        best = np.full(len(directions), np.inf)
        scenes = [(self._static, None)] if self._static is not None else []
        scenes += list(self._dynamic.values())
        for scene, world_to_local in scenes:
            o, d = origins, directions
            if world_to_local is not None:
                o = origins @ world_to_local[:3, :3].T + world_to_local[:3, 3]
                d = directions @ world_to_local[:3, :3].T
            t = scene.run(o.astype(np.float32), d.astype(np.float32), query="DISTANCE").astype(np.float64)
            t[t >= _EMBREE_MISS] = np.inf
            best = np.minimum(best, t)
        return best
