"""PROJECTION and AMAP stages of the ANTICIPATION and NO_ANTICIPATION modes: the S-maps and V-maps
of the paper's 2r target sample points, refreshed on its amortized schedule, and the occlusion
anticipation map the search reads (occlusion-anticipation-toric-space.md, sections 4, 4.2, 6).

Built lazily, the first time a session enters a map mode: it keeps its own occluder scene (the
backends hold their own acceleration data). Each frame only records the moved objects' poses
(`ingest`: two dictionary operations in C, whatever the number of objects); the frames that
build maps (the amortized schedule, one in several) move the scene's objects, all at once, and
give them velocities by finite differences between the latest frame and the one before it (an
object the latest frame does not mention has not moved: velocity zero). So many moving objects
cost the frames between map builds nearly nothing.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.toric import Torus
from camdirector.geometry.toric_maps import OccluderScene, choose_backend, make_backend, probe_gl_renderer
from camdirector.geometry.toric_maps.base import MapWindow, WindowSettings
from camdirector.geometry.transforms import RigidTransform
from camdirector.precompute.stage_clock import StageClock
from camdirector.server.pipeline.stages import Stage
from camdirector.server.pipeline.style import MapBackendChoice, Style, VisibilityMode
from camdirector.server.pipeline.toric.anticipation import AnticipationMap, AnticipationSettings, StyleMaskSettings, shared_bank
from camdirector.server.pipeline.toric.target_sampling import TargetSampler


class OcclusionMaps:
    """The map modes' state for one session: occluder scene, backend, sampler and A-map."""

    def __init__(self, static_meshes_world: list[TriMesh], dynamic: dict[str, tuple[TriMesh, RigidTransform]],
                 sampler: TargetSampler, style: Style, rng: np.random.Generator):
        self.scene = OccluderScene(static_meshes_world)
        for object_id, (mesh, transform) in dynamic.items():
            self.scene.add_dynamic(object_id, mesh, transform)
        # Every object's pose as of the latest frame and as of the frame before (targets too: ignored),
        # the latest frame's moved (id, transform) pairs, and the two frames' times (None: none yet).
        self._latest: dict[str, RigidTransform] = {object_id: tf for object_id, (_, tf) in dynamic.items()}
        self._before: dict[str, RigidTransform] = dict(self._latest)
        self._moved: list[tuple[str, RigidTransform]] = []
        self._times_s: tuple[float | None, float | None] = (None, None)
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
            self.amap = AnticipationMap(self.sampler.target_count, settings, mask, shared_bank(settings))
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
        """Records this frame's poses of the moved objects (module docstring)."""
        self._before = self._latest.copy()
        self._latest.update(moved)
        self._moved = moved
        self._times_s = (time_s, self._times_s[0])

    def _move_scene(self) -> None:
        """Every dynamic object at its latest pose with its velocity (module docstring), in the
        occluder scene, in one call, before a map build."""
        ids = list(self.scene.dynamic)
        linear, angular = np.zeros((len(ids), 3)), np.zeros((len(ids), 3))
        now_s, before_s = self._times_s
        moving = [object_id for object_id, _ in self._moved if object_id in self.scene.dynamic]
        if moving and before_s is not None and now_s > before_s:
            row = {object_id: k for k, object_id in enumerate(ids)}
            rows = [row[object_id] for object_id in moving]
            now = [self._latest[object_id] for object_id in moving]
            before = [self._before[object_id] for object_id in moving]
            turn = Rotation.from_quat([tf.rotation_xyzw for tf in now]) * \
                Rotation.from_quat([tf.rotation_xyzw for tf in before]).inv()
            linear[rows] = (np.array([tf.position_world for tf in now])
                            - np.array([tf.position_world for tf in before])) / (now_s - before_s)
            angular[rows] = turn.as_rotvec() / (now_s - before_s)
        self.scene.set_motions(ids, [self._latest[object_id] for object_id in ids], linear, angular)

    def update(self, torus: Torus, theta: float, phi: float, time_s: float, target_transforms,
               target_ids: list[str], stages: StageClock) -> None:
        """Refreshes the maps due at time_s (2 of the 2r per update, one update every W / r s),
        lapping PROJECTION and AMAP on `stages` (neither when nothing was due)."""
        amap = self.amap
        if amap.due(time_s):
            self._move_scene()
            slots = amap.next_slots()
            self.sampler.redraw(slots, self.rng)
            window = MapWindow.around(torus, theta, phi, amap.settings.window, lattice=amap.window)
            previous_torus, dt_s = (self._previous[0], time_s - self._previous[1]) if self._previous else (None, 0.0)
            maps = self.backend.compute(torus, window, self.sampler.points_world(target_transforms, slots),
                                        exclude_ids=[target_ids[self.sampler.target_of(s)] for s in slots],
                                        previous_torus=previous_torus if dt_s > 0 else None,
                                        dt_s=max(dt_s, 0.0))
            stages.done(Stage.PROJECTION)
            amap.refresh(time_s, slots, maps, torus)
            stages.done(Stage.AMAP)
        self._previous = (torus, time_s)

    def invalidate(self) -> None:
        """After a cut: the old window is elsewhere."""
        self.amap.invalidate()

    def risk(self, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """The A-map as the search's RiskField; places off the window read as occluded."""
        return self.amap.lookup(theta, phi, outside=1.0)

    def close(self) -> None:
        """Releases the backend (its GL objects, or its Embree scenes); idempotent."""
        if self.backend is not None:
            self.backend.close()
            self.backend = None
