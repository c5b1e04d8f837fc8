"""Occlusion queries by ray casting with Embree (embreex), for scenes with moving rigid objects.

embreex copies a mesh at about 1 us per triangle and has neither instancing nor vertex updates,
so static geometry lives in one Embree scene built once, and the dynamic objects' meshes stay in
their local frames: a query transforms the rays into each object's frame (o' = M^-1 o,
d' = M^-1 d, so the ray parameter t means the same point in both frames) instead of rebuilding
anything when an object moves (RayScene says how many objects share one scene and one call,
and how a few are cast one by one).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.transforms import RigidTransform, quat_to_matrix

_NO_HIT = -1
_EMBREE_MISS = 1e30  # embreex reports a miss as tfar = 1e37
# Up to this many moving objects each is cast alone, in its own scene, with no culling: a few
# small numpy calls per object cost less than the shared scene's fixed ones (the demo's 3 moving
# obstacles: 35 us a query less, 13% of a FRAMING_ONLY frame).
SOLO_MAX_OBJECTS = 4


# RayScene._pose_arrays: bounding sphere centres (m, 3) and radii (m,), world -> local A (m, 3, 3) and b (m, 3).
_PoseArrays = tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]


def _embree_scene(meshes: list[TriMesh]) -> rtcore_scene.EmbreeScene:
    scene = rtcore_scene.EmbreeScene()
    for mesh in meshes:
        TriangleMesh(scene, mesh.vertices.astype(np.float32), mesh.faces)
    return scene


def _rebuilt(
    static_meshes_world: list[TriMesh], solo_max_objects: int, objects: list[tuple[str, TriMesh, RigidTransform]]
) -> RayScene:
    """A RayScene unpickled (RayScene.__reduce__): built again from its meshes, objects in their order."""
    scene = RayScene(static_meshes_world, solo_max_objects)
    for object_id, mesh_local, transform in objects:
        scene.add_dynamic(object_id, mesh_local, transform)
    return scene


class RayScene:
    """Static meshes (world frame, built once) plus dynamic rigid objects (local frame + transform).

    Moving an object only stores its transform; nothing is rebuilt. A query casts every ray
    against the static scene, then against the moving objects with rays moved into each object's
    frame (module docstring), all objects in one Embree call:

    - every object's local mesh lies within `reach` of its local origin, so a sphere of radius
      reach * (largest scale) about its world position bounds it; objects whose sphere misses the
      box around all the segments are dropped;
    - every remaining (object, ray) pair's ray, moved into the object's frame, is clipped to the
      local sphere |x| <= reach (exact in that frame, whatever the scale); pairs with nothing left
      are dropped, so the clip is also the per-pair cull;
    - one Embree scene holds every object's local mesh, object i shifted by its own offset on a
      grid whose spacing exceeds two reaches: a clipped ray shifted by the same offset can meet only
      its own object's copy. So 100 moving objects cost one call, not 100.

    Positions, radii and world-to-local matrices are made from the stored transforms once per
    change of pose, on the first query after it; the shared local scene once per object added.

    With at most `solo_max_objects` moving objects, each is cast alone instead: every ray moved
    into its frame, against a scene of its mesh alone (no offset), as many calls as objects whose
    sphere meets the box around the segments (`occluded`; `first_hit`'s rays are unbounded). Both
    ways give the same answers (tests/geometry/test_raycast.py).

    Pickles as its meshes and objects' transforms; unpickling builds its Embree scenes again (a
    session's checkpoint, worker/checkpointing.py): the same triangles answer the same.
    """

    def __init__(self, static_meshes_world: list[TriMesh], solo_max_objects: int = SOLO_MAX_OBJECTS):
        self._static_meshes = list(static_meshes_world)
        self._static = _embree_scene(static_meshes_world) if static_meshes_world else None
        self._index: dict[str, int] = {}  # object id -> row
        self._meshes_local: list[TriMesh] = []
        self._reach_local: list[float] = []  # per object: farthest vertex from the local origin
        self._transforms: list[RigidTransform] = []
        # scene, offsets (m, 3), reach (m,)
        self._local: tuple[rtcore_scene.EmbreeScene, npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None
        self._poses: _PoseArrays | None = None  # _pose_arrays(); None: moved since
        self._solo_max = solo_max_objects
        # per object, cast one by one: its scene and world -> local matrix (None: moved since)
        self._solo: list[tuple[rtcore_scene.EmbreeScene, npt.NDArray[np.float64] | None]] = []

    def __reduce__(self) -> tuple[Callable[..., RayScene], tuple[list[TriMesh], int, list[tuple[str, TriMesh, RigidTransform]]]]:
        objects = [(object_id, self._meshes_local[row], self._transforms[row]) for object_id, row in self._index.items()]
        return _rebuilt, (self._static_meshes, self._solo_max, objects)

    @property
    def static_meshes_world(self) -> list[TriMesh]:
        """The static meshes it was built from (world frame): what a twin of it is built from."""
        return list(self._static_meshes)

    def add_dynamic(self, object_id: str, mesh_local: TriMesh, transform: RigidTransform) -> None:
        if object_id in self._index:
            raise ValueError(f"dynamic object {object_id!r} already added")
        self._index[object_id] = len(self._transforms)
        self._meshes_local.append(mesh_local)
        squared = np.einsum("ij,ij->i", mesh_local.vertices, mesh_local.vertices)
        self._reach_local.append(float(np.sqrt(squared.max())) * (1.0 + 1e-6) + 1e-6)
        self._transforms.append(transform)
        self._local = self._poses = None
        self._solo = []

    def set_transform(self, object_id: str, transform: RigidTransform) -> None:
        row = self._index[object_id]
        self._transforms[row] = transform
        self._poses = None
        if self._solo:
            self._solo[row] = (self._solo[row][0], None)

    def _each(
        self, box: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None
    ) -> list[tuple[rtcore_scene.EmbreeScene, npt.NDArray[np.float64]]]:
        """Per object, for casting a few one by one (class docstring): its own scene and its
        world-to-local matrix (4, 4), made on first use after a move. With `box`, (lo, hi) (3,)
        world metres around every segment of a query, only the objects whose bounding sphere
        meets it (in scalars: a few objects' numpy calls would cost more than they save)."""
        if not self._solo:
            self._solo = [(_embree_scene([mesh]), None) for mesh in self._meshes_local]
        if box is not None:
            (lo_x, lo_y, lo_z), (hi_x, hi_y, hi_z) = box[0].tolist(), box[1].tolist()
        out = []
        for k, (scene, world_to_local) in enumerate(self._solo):
            if box is not None:
                transform = self._transforms[k]
                x, y, z = transform.position_world.tolist()
                gap_x, gap_y, gap_z = max(lo_x - x, x - hi_x, 0.0), max(lo_y - y, y - hi_y, 0.0), max(lo_z - z, z - hi_z, 0.0)
                radius = self._reach_local[k] * max(abs(c) for c in transform.scale.tolist())
                if gap_x * gap_x + gap_y * gap_y + gap_z * gap_z > radius * radius:
                    continue
            if world_to_local is None:
                world_to_local = self._transforms[k].inverse_matrix()
                self._solo[k] = (scene, world_to_local)
            out.append((scene, world_to_local))
        return out

    def _local_scene(self) -> tuple[rtcore_scene.EmbreeScene, npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """The shared scene of local meshes, their offsets (m, 3) on a cubic grid and reaches (m,)."""
        if self._local is None:
            reach = np.array(self._reach_local)
            side = math.ceil(len(reach) ** (1.0 / 3.0) - 1e-9)
            spacing = 2.0 * float(reach.max()) * 1.25
            k = np.arange(len(reach))
            offsets = spacing * np.stack([k % side, (k // side) % side, k // (side * side)], axis=1).astype(np.float64)
            scene = _embree_scene([TriMesh(m.vertices + o, m.faces) for m, o in zip(self._meshes_local, offsets)])
            self._local = scene, offsets, reach
        return self._local

    def _pose_arrays(self) -> _PoseArrays:
        """Bounding spheres, world centres (m, 3) and radii (m,), and world -> local x' = A x + b,
        A (m, 3, 3) = S^-1 R^T, b (m, 3) = -A p, made for all objects at once after a move (one
        vectorized pass costs less than one per object, or one per query, from ten objects on)."""
        if self._poses is None:
            transforms = self._transforms
            positions = np.array([tf.position_world for tf in transforms])
            scales = np.array([tf.scale for tf in transforms])
            linear = quat_to_matrix(np.array([tf.rotation_xyzw for tf in transforms])).transpose(0, 2, 1) / scales[:, :, None]
            self._poses = (
                positions,
                np.array(self._reach_local) * np.abs(scales).max(axis=1),
                linear,
                -np.einsum("mij,mj->mi", linear, positions),
            )
        return self._poses

    def _cast_dynamic(
        self, origins: npt.NDArray[np.float64], directions: npt.NDArray[np.float64], t_max: npt.NDArray[np.float64], query: str
    ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.float64]]:
        """Rays o + t d, 0 <= t <= t_max, (n, 3), (n, 3), (n,), against every moving object.
        Returns (ray index (p,), ray parameter of the hit (p,) float64) of the hits; a ray may appear
        once per object it hits. query: "OCCLUDED" (the parameter is then that of the segment's
        entry into the object's sphere, a lower bound) or "DISTANCE"."""
        none = np.zeros(0, dtype=np.int64), np.zeros(0)
        if not len(origins):
            return none
        centres, radii, linear, translation = self._pose_arrays()
        # Objects whose sphere meets the box around all the segments.
        ends = origins + directions * t_max[:, None]
        gap = np.maximum(
            np.maximum(np.minimum(origins, ends).min(axis=0) - centres, centres - np.maximum(origins, ends).max(axis=0)), 0.0
        )  # (m, 3)
        candidates = np.flatnonzero((gap * gap).sum(axis=1) <= radii * radii)
        if not len(candidates):
            return none
        # Every (candidate, ray) pair in the candidate's frame, clipped to its local sphere
        # |o + t d| <= reach: the clip is the per-pair cull (no world-space test before it).
        scene, offsets, reach = self._local_scene()
        # Products written as matmul and sums: einsum's set-up costs ~7 us a call at these sizes.
        a_local_t = linear[candidates].transpose(0, 2, 1)
        o = origins @ a_local_t + translation[candidates][:, None, :]  # (c, n, 3)
        d = directions @ a_local_t
        a = np.maximum((d * d).sum(axis=2), 1e-300)
        half_b = (o * d).sum(axis=2)
        disc = half_b * half_b - a * ((o * o).sum(axis=2) - (reach[candidates] ** 2)[:, None])
        root = np.sqrt(np.maximum(disc, 0.0))
        t_in = np.maximum((-half_b - root) / a, 0.0)
        t_out = np.minimum((-half_b + root) / a, t_max[None, :])
        near, ray = np.nonzero((disc > 0.0) & (t_out > t_in))
        if not len(ray):
            return none
        d, t_in = d[near, ray], t_in[near, ray]
        start = (o[near, ray] + t_in[:, None] * d + offsets[candidates[near]]).astype(np.float32)
        dists = (t_out[near, ray] - t_in).astype(np.float32)
        if query == "OCCLUDED":
            hit = scene.run(start, d.astype(np.float32), dists=dists, query=query) != _NO_HIT
            return ray[hit], t_in[hit]
        # A clipped ray that misses keeps tfar = its dists: the geometry id says whether it hit.
        answer = scene.run(start, d.astype(np.float32), dists=dists, output=1)
        hit = answer["geomID"] != _NO_HIT
        return ray[hit], t_in[hit] + answer["tfar"][hit].astype(np.float64)

    def occluded(self, origins_world: npt.ArrayLike, targets_world: npt.ArrayLike) -> npt.NDArray[np.bool_]:
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
            hit |= (
                self._static.run(origins.astype(np.float32), directions.astype(np.float32), dists=tmax.copy(), query="OCCLUDED")
                != _NO_HIT
            )
        if 0 < len(self._transforms) <= self._solo_max:
            box = np.minimum(origins, targets).min(axis=0), np.maximum(origins, targets).max(axis=0)
            for scene, world_to_local in self._each(box):
                rest = ~hit
                if not rest.any():
                    break
                o = origins[rest] @ world_to_local[:3, :3].T + world_to_local[:3, 3]
                d = directions[rest] @ world_to_local[:3, :3].T
                hit[rest] = scene.run(o.astype(np.float32), d.astype(np.float32), dists=tmax[rest], query="OCCLUDED") != _NO_HIT
        elif self._transforms:
            rest = np.flatnonzero(~hit)
            hit[rest[self._cast_dynamic(origins[rest], directions[rest], tmax[rest].astype(np.float64), "OCCLUDED")[0]]] = True
        return hit

    def first_hit(self, origins_world: npt.ArrayLike, directions_world: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Ray parameter of the nearest hit along each ray, in units of the direction's length.

        origins_world (n, 3) or (3,), directions_world (n, 3) float64. Returns (n,) float64, inf
        where nothing is hit.
        """
        directions = np.atleast_2d(directions_world)
        origins = np.broadcast_to(origins_world, directions.shape)
        best = np.full(len(directions), np.inf)
        if self._static is not None:
            best = self._static.run(origins.astype(np.float32), directions.astype(np.float32), query="DISTANCE").astype(
                np.float64
            )
            best[best >= _EMBREE_MISS] = np.inf
        if 0 < len(self._transforms) <= self._solo_max:
            for scene, world_to_local in self._each():
                o = origins @ world_to_local[:3, :3].T + world_to_local[:3, 3]
                d = directions @ world_to_local[:3, :3].T
                t = scene.run(o.astype(np.float32), d.astype(np.float32), query="DISTANCE").astype(np.float64)
                np.minimum(best, np.where(t >= _EMBREE_MISS, np.inf, t), out=best)
        elif self._transforms:
            ray, t = self._cast_dynamic(origins, directions, np.minimum(best, 1e12), "DISTANCE")
            np.minimum.at(best, ray, t)
        return best
