"""PROJECTION and AMAP stages of the ANTICIPATION and NO_ANTICIPATION modes: the S-maps and V-maps
of the paper's 2r target sample points, refreshed on its amortized schedule, and the occlusion
anticipation map the search reads (occlusion-anticipation-toric-space.md, sections 4, 4.2, 6).

Built lazily, the first time a session enters a map mode: it keeps its own occluder scene (the
backends hold their own acceleration data), fed each frame with the moved objects and their
velocities, estimated here by finite differences of successive transforms (an object a frame
does not mention has not moved: velocity zero).
"""
from __future__ import annotations

import functools
import time

import numpy as np
from scipy.spatial.transform import Rotation

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.toric import Torus
from camdirector.geometry.toric_maps import OccluderScene, choose_backend, make_backend, probe_gl_renderer
from camdirector.geometry.toric_maps.base import MapWindow, WindowSettings
from camdirector.geometry.transforms import RigidTransform
from camdirector.server.pipeline.style import MapBackendChoice, Style, VisibilityMode
from camdirector.server.pipeline.toric.anticipation import AnticipationMap, AnticipationSettings, KernelBank, StyleMaskSettings
from camdirector.server.pipeline.toric.target_sampling import TargetSampler


@functools.lru_cache(maxsize=8)
def _kernel_bank(settings: AnticipationSettings) -> KernelBank:
    """One warmed bank per worker process and settings (warming takes about 0.07 s)."""
    bank = KernelBank(settings)
    bank.warm()
    return bank


class OcclusionMaps:
    """The map modes' state for one session: occluder scene, backend, sampler and A-map."""

    def __init__(self, static_meshes_world: list[TriMesh], dynamic: dict[str, tuple[TriMesh, RigidTransform]],
                 sampler: TargetSampler, style: Style, rng: np.random.Generator):
        self.scene = OccluderScene(static_meshes_world)
        for object_id, (mesh, transform) in dynamic.items():
            self.scene.add_dynamic(object_id, mesh, transform)
        self._last_pose = {object_id: (transform, None) for object_id, (_, transform) in dynamic.items()}
        self._moving: set[str] = set()
        self.sampler = sampler
        self.rng = rng
        self._backend_key = None
        self.backend = None
        self.amap: AnticipationMap | None = None
        self._previous: tuple[Torus, float] | None = None
        self.set_style(style)

    def set_style(self, style: Style) -> None:
        """A new map resolution, anticipation switch or backend starts the maps afresh; a new mask
        applies at once."""
        settings = AnticipationSettings(
            samples_per_target=self.sampler.settings.samples_per_target,
            anticipate=style.visibility != VisibilityMode.NO_ANTICIPATION,
            window=WindowSettings(resolution=style.map_resolution))
        mask = StyleMaskSettings(kind=style.mask)
        if self.amap is None or self.amap.settings != settings:
            self.amap = AnticipationMap(self.sampler.target_count, settings, mask, _kernel_bank(settings))
        else:
            self.amap.set_mask(mask)
        backend_name = {MapBackendChoice.GL: "gl", MapBackendChoice.EMBREE: "embree"}.get(style.map_backend) or \
            choose_backend(self.scene.triangle_count, probe_gl_renderer(), style.map_resolution)
        if backend_name != self._backend_key:
            if self.backend is not None:
                self.backend.close()
            self.backend = make_backend(backend_name, self.scene)
            self._backend_key = backend_name

    @property
    def backend_name(self) -> str:
        return self._backend_key

    def ingest(self, moved: list[tuple[str, RigidTransform]], time_s: float) -> None:
        """Poses and finite-difference velocities of the dynamic objects for this frame."""
        seen = set()
        for object_id, transform in moved:
            if object_id not in self._last_pose:
                continue  # a target
            seen.add(object_id)
            previous, at_s = self._last_pose[object_id]
            linear = angular = np.zeros(3)
            if at_s is not None and time_s > at_s:
                dt = time_s - at_s
                linear = (transform.position_world - previous.position_world) / dt
                turn = Rotation.from_quat(transform.rotation_xyzw) * Rotation.from_quat(previous.rotation_xyzw).inv()
                angular = turn.as_rotvec() / dt
            self.scene.set_motion(object_id, transform, linear, angular)
            self._last_pose[object_id] = (transform, time_s)
        for object_id in self._moving - seen:  # not mentioned: it stopped
            self.scene.set_motion(object_id, self._last_pose[object_id][0])
            self._last_pose[object_id] = (self._last_pose[object_id][0], time_s)
        self._moving = seen

    def update(self, torus: Torus, theta: float, phi: float, time_s: float, target_transforms,
               target_ids: list[str]) -> dict[str, float]:
        """Refreshes the maps due at time_s (2 of the 2r per update, one update every W / r s).
        Returns stage times in ms ({} when nothing was due)."""
        amap = self.amap
        timings: dict[str, float] = {}
        if amap.due(time_s):
            t0 = time.perf_counter()
            slots = amap.next_slots()
            self.sampler.redraw(slots, self.rng)
            window = MapWindow.around(torus, theta, phi, amap.settings.window, lattice=amap.window)
            previous_torus, dt_s = (self._previous[0], time_s - self._previous[1]) if self._previous else (None, 0.0)
            maps = self.backend.compute(torus, window, self.sampler.points_world(target_transforms, slots),
                                        exclude_ids=[target_ids[self.sampler.target_of(s)] for s in slots],
                                        previous_torus=previous_torus if dt_s > 0 else None,
                                        dt_s=max(dt_s, 0.0))
            t1 = time.perf_counter()
            amap.refresh(time_s, slots, maps, torus)
            timings = {"projection": (t1 - t0) * 1e3, "amap": (time.perf_counter() - t1) * 1e3}
        self._previous = (torus, time_s)
        return timings

    def invalidate(self) -> None:
        """After a cut: the old window is elsewhere."""
        self.amap.invalidate()

    def risk(self, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """The A-map as the search's RiskField; places off the window read as occluded."""
        return self.amap.lookup(theta, phi, outside=1.0)

    def close(self) -> None:
        if self.backend is not None:
            self.backend.close()
