"""S-maps and V-maps by ray casting, compiled: embree.py's method on camdirector._native's
deterministic BVH (native/src/maps.rs), the same bits on every x86-64 machine, for the compiled
frame path (issue 43, docs/frame_path.md).

Paper: occlusion-anticipation-toric-space.md sections 4.1.1 and 4.1.2, computed by rays as
embree.py computes them: for each sample point s and each texel, one segment from s to the
texel's torus point P; the S-map is whether it hits anything but the sample's own target, the
V-map the first hit's rigid velocity v + w x (p - c) minus the torus point's velocity, in Toric
angular rates. Embree casts in float32 and this backend in float64, so the two agree but within
rounding of an edge (tests/geometry/toric_maps/test_backends.py holds them to each other).

The occluder scene's meshes are copied into a _native.Scene when its geometry changes (static
meshes in one BVH, each moving object in its local frame); a call moves the Scene's objects
where the OccluderScene's are and casts every ray with the GIL released.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

import camdirector._native as native
from camdirector.geometry.toric import Torus
from camdirector.geometry.toric_maps.base import MapWindow, OccluderScene, ShadowVelocityMaps, check_compute_args
from camdirector.geometry.transforms import RigidTransform


def share_texels(threads: int) -> None:
    """Lets each later map update of this process share its texels among `threads` threads (1: the
    caller's alone). The maps are the same bits whatever the count (native/src/maps.rs)."""
    native.set_map_threads(threads)


def hand_updates_apart(on: bool) -> None:
    """Whether this process's sessions compute their amortized map updates on a thread of their own
    (pipeline/toric/compiled_maps.py): on where one thread answers every session's frames
    (`serve --workers 0`), whose other core that thread takes; off in worker processes, whose
    cores the workers already fill (there it cost ANTICIPATION capacity: docs/frame_path.md)."""
    NativeMapBackend.apart = on


def share_texels_here(threads: int) -> None:
    """share_texels for the calling thread's later map updates alone, over the process's count
    (pipeline/toric/compiled_maps.py: the maps thread keeps to one core)."""
    native.set_map_threads_here(threads)


class NativeMapBackend:
    """MapBackend by compiled ray casting; holds a _native.Scene mirroring an OccluderScene."""

    name = "native"
    apart = False  # the process's hand_updates_apart

    def __init__(self, scene: OccluderScene) -> None:
        self.scene = scene
        self._version = -1
        self._native: Any = None  # the _native.Scene, made on first use
        self._placed: dict[str, RigidTransform] = {}  # where the Scene's objects were moved to

    def __reduce__(self) -> tuple[type[NativeMapBackend], tuple[OccluderScene]]:
        """Pickled as its scene: the compiled Scene is built again on first use."""
        return NativeMapBackend, (self.scene,)

    def _synced(self) -> Any:
        """The Scene, rebuilt after a geometry change, its objects where the OccluderScene's are."""
        if self._native is None or self._version != self.scene.geometry_version:
            self._native = native.Scene(list(self.scene.static_meshes_world))
            for object_id, obj in self.scene.dynamic.items():
                self._native.add_dynamic(object_id, obj.mesh_local, obj.transform)
            self._placed = {object_id: obj.transform for object_id, obj in self.scene.dynamic.items()}
            self._version = self.scene.geometry_version
        for object_id, obj in self.scene.dynamic.items():
            if self._placed[object_id] is not obj.transform:
                self._native.set_transform(object_id, obj.transform)
                self._placed[object_id] = obj.transform
        return self._native

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
        scene = self._synced()
        objects = list(self.scene.dynamic.values())
        rows = {object_id: k for k, object_id in enumerate(self.scene.dynamic)}
        shadow, velocity, depth = native.shadow_velocity_maps(
            scene,
            torus,
            window,
            points,
            [-1 if e is None else rows.get(e, -1) for e in excluded],
            np.array([o.transform.position_world for o in objects]).reshape(-1, 3),
            np.array([o.linear_velocity_m_s for o in objects]).reshape(-1, 3),
            np.array([o.angular_velocity_rad_s for o in objects]).reshape(-1, 3),
            previous_torus,
            dt_s,
        )
        return ShadowVelocityMaps(window=window, shadow=shadow, velocity_rad_s=velocity, depth_m=depth)

    def close(self) -> None:
        self._native = None
        self._placed = {}
        self._version = -1
