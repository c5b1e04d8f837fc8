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

An amortized update (2 of the 2r maps, every slot already holding one) is computed apart from
the frame it is due on: that frame draws its sample points, keeps the objects' poses and schedules
the next update; the scene's move to those poses, its maps, their A_s and the aggregate A they
make are computed when the session's worker is idle (`do_deferred_work`, called by
worker/table.py's `idle_work`, a piece at a time) or, at the latest, by the update that applies
them, `AnticipationSettings.apply_after_frames` (1) frames later; on `serve --workers 0` the
compiled maps hand it to the front's maps thread instead, which it is taken back from if that has
not begun it (compiled_maps.py). The same numbers either way:
the scene is moved from the poses kept, and an aggregate made ahead is used only if the A-map has
not changed since (`AnticipationMap.prepare`). Why: an update costs a few
frames' worth of computing, and a worker's sessions created together update in the same period;
computed inline, their updates queued the frames behind them. Apart, the frame that draws an
update answers as fast as the others, and the maps are computed while its worker waits for
requests (the figures: docs/toric.md). The search reads each amortized update one frame after it
is due, inside the paper's 0.1 s update period and 0.5 s horizon (section 6), and always on that
frame: what a session answers does not depend on when its worker was idle. (Later than one frame
cost the demo scene's visibility: docs/toric.md.) A refill (the first update, and the first after a
cut) is computed and applied at once: the search has no A-map without it.
"""

from __future__ import annotations

from concurrent.futures import Future, wait
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.toric import Torus
from camdirector.geometry.toric_maps import OccluderScene, choose_backend, make_backend, probe_gl_renderer
from camdirector.geometry.toric_maps.base import MapBackend, MapWindow, ShadowVelocityMaps, WindowSettings
from camdirector.geometry.transforms import RigidTransform
from camdirector.infra.stage_clock import StageClock
from camdirector.pipeline.inputs import DynamicObjects
from camdirector.pipeline.stages import Stage
from camdirector.pipeline.style import MapBackendChoice, Style, VisibilityMode
from camdirector.pipeline.toric.anticipation_map import AnticipationMap, PreparedAggregate
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.occlusion_prediction import shared_bank
from camdirector.pipeline.toric.style_masks import StyleMaskSettings
from camdirector.pipeline.toric.target_sampling import TargetSampler

_SceneMotion = tuple[
    list[tuple[str, RigidTransform]], dict[str, RigidTransform], dict[str, RigidTransform], tuple[float | None, float | None]
]


@dataclass
class _DeferredUpdate:
    """An amortized update drawn on the frame it was due on, not yet applied (module docstring)."""

    time_s: float
    slots: list[int]
    torus: Torus
    window: MapWindow
    points_world: npt.NDArray[np.float64]  # (k, 3): the slots' sample points, world metres
    exclude_ids: list[str]  # k: the target each point lies on
    previous_torus: Torus | None
    dt_s: float
    frames_left: int  # updates (one a frame) until it is applied
    # The scene's motion as of the frame it was drawn on: that frame's moved (id, transform) pairs,
    # every object's pose then and the frame before, the two frames' times (_move_scene's inputs);
    # None once the scene has been moved (or in a snapshot of an older version, which moved it at once).
    scene_motion: _SceneMotion | None = None
    maps: ShadowVelocityMaps | None = None  # once computed, until A_s is
    predicted: npt.NDArray[np.float32] | None = None  # (k, res, res) A_s, once computed
    aggregate: PreparedAggregate | None = None  # the A-map's aggregate with A_s stored, once made ahead
    # The maps thread's task computing the fields above (CompiledOcclusionMaps._start), until it is
    # joined or taken back; None when they are computed on the session's own thread.
    computing: Future[bool] | None = None
    # Once handed to the maps thread, its frame laps no stage of the computing, whichever thread did
    # it: the frame's laps (its diagnostics) do not depend on the threads' timing.
    handed: bool = False

    def take_back(self) -> bool:
        """Whether this update is the caller's to compute: never handed to the maps thread, or
        taken back from it before it began."""
        if self.computing is not None and self.computing.cancel():
            self.computing = None
        return self.computing is None

    def join(self) -> None:
        """Waits for the maps thread, if it computes this update; raises what it raised."""
        computing, self.computing = self.computing, None
        if computing is not None:
            computing.result()

    def __getstate__(self) -> dict[str, object]:
        """Pickled computed, with no thread: the same numbers as waiting for it on its frame."""
        self.join()
        return self.__dict__.copy()


class OcclusionMaps:
    """The map modes' state for one session: occluder scene, backend, sampler and A-map."""

    _amap_class: type[AnticipationMap] = AnticipationMap  # whose aggregate the A-map forms

    def __init__(
        self,
        static_meshes_world: list[TriMesh],
        dynamic: DynamicObjects,
        sampler: TargetSampler,
        style: Style,
        rng: np.random.Generator,
    ) -> None:
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
        self._previous: tuple[Torus, float] | None = None
        self._deferred: _DeferredUpdate | None = None
        self.amap = self._anticipation_map(self._settings(style), StyleMaskSettings(kind=style.mask))
        self._backend_key = self._backend_of(style)
        self.backend: MapBackend | None = make_backend(self._backend_key, self.scene)  # None once closed

    def _settings(self, style: Style) -> AnticipationSettings:
        return AnticipationSettings(
            samples_per_target=self.sampler.settings.samples_per_target,
            anticipate=style.visibility != VisibilityMode.NO_ANTICIPATION,
            window=WindowSettings(resolution=style.map_resolution),
        )

    def _anticipation_map(self, settings: AnticipationSettings, mask: StyleMaskSettings) -> AnticipationMap:
        """A new, empty A-map of `_amap_class`, its kernel bank warmed (shared_bank), not on a frame."""
        return self._amap_class(self.sampler.target_count, settings, mask, shared_bank(settings))

    def _backend_of(self, style: Style) -> str:
        return {MapBackendChoice.GL: "gl", MapBackendChoice.EMBREE: "embree"}.get(style.map_backend) or choose_backend(
            self.scene.triangle_count, probe_gl_renderer(), style.map_resolution
        )

    def set_style(self, style: Style) -> None:
        """A new map resolution, anticipation switch or backend starts the maps afresh; a new mask
        applies at once. A deferred update is computed with the backend it was drawn for, and
        dropped with the A-map when that starts afresh."""
        self.do_deferred_work()
        settings = self._settings(style)
        mask = StyleMaskSettings(kind=style.mask)
        if self.amap.settings != settings:
            self._deferred = None
            self.amap = self._anticipation_map(settings, mask)
        else:
            self.amap.set_mask(mask)
        backend_name = self._backend_of(style)
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

    def _scene_motion(self) -> _SceneMotion:
        """What `_move_scene` reads, kept as of this frame (the next frame's ingest replaces
        _moved, _before and _times_s, and updates _latest in place)."""
        return self._moved, dict(self._latest), self._before, self._times_s

    def _move_scene(self, motion: _SceneMotion) -> None:
        """Every dynamic object at its pose of `motion`'s frame with its velocity (module
        docstring), in the occluder scene, in one call, before a map build."""
        moved, latest, before_poses, (now_s, before_s) = motion
        ids = list(self.scene.dynamic)
        linear, angular = np.zeros((len(ids), 3)), np.zeros((len(ids), 3))
        moving = [object_id for object_id, _ in moved if object_id in self.scene.dynamic]
        if moving and now_s is not None and before_s is not None and now_s > before_s:
            row = {object_id: k for k, object_id in enumerate(ids)}
            rows = [row[object_id] for object_id in moving]
            now = [latest[object_id] for object_id in moving]
            before = [before_poses[object_id] for object_id in moving]
            linear[rows] = (np.array([tf.position_world for tf in now]) - np.array([tf.position_world for tf in before])) / (
                now_s - before_s
            )
            angular[rows] = self._turn_rates(
                np.array([tf.rotation_xyzw for tf in before]), np.array([tf.rotation_xyzw for tf in now]), now_s - before_s
            )
        self.scene.set_motions(ids, [latest[object_id] for object_id in ids], linear, angular)

    def _turn_rates(
        self, before_xyzw: npt.NDArray[np.float64], now_xyzw: npt.NDArray[np.float64], dt_s: float
    ) -> npt.NDArray[np.float64]:
        """(m, 3) rad/s, world frame: the angular velocities of m objects turned from before_xyzw to
        now_xyzw, (m, 4) quaternions each, in dt_s > 0 seconds (scipy's rotation vector of the turn)."""
        turn = Rotation.from_quat(now_xyzw) * Rotation.from_quat(before_xyzw).inv()
        rates: npt.NDArray[np.float64] = turn.as_rotvec() / dt_s
        return rates

    def update(
        self,
        torus: Torus,
        theta: float,
        phi: float,
        time_s: float,
        target_transforms: list[RigidTransform],
        target_ids: list[str],
        stages: StageClock,
    ) -> None:
        """Applies a deferred update whose frame has come, then draws the update due at time_s
        (2 of the 2r maps, one update every W / r s), computed and applied at once when it is a
        refill, deferred otherwise (module docstring); laps PROJECTION and AMAP on `stages` for
        the maps computed and applied in this call (neither when none were)."""
        self._apply_deferred(stages)
        amap = self.amap
        if amap.due(time_s):
            refill = not amap.filled
            slots = amap.next_slots()
            self.sampler.redraw(slots, self.rng)
            amap.schedule(time_s, slots)
            previous_torus, dt_s = (self._previous[0], time_s - self._previous[1]) if self._previous else (None, 0.0)
            self._settle()  # one update at a time uses the scene and the backend
            self._deferred = _DeferredUpdate(
                time_s,
                slots,
                torus,
                MapWindow.around(torus, theta, phi, amap.settings.window, lattice=amap.window),
                self.sampler.points_world(target_transforms, slots),
                [target_ids[self.sampler.target_of(s)] for s in slots],
                previous_torus if dt_s > 0 else None,
                max(dt_s, 0.0),
                frames_left=0 if refill else amap.settings.apply_after_frames,
                scene_motion=self._scene_motion(),
            )
            if self._deferred.frames_left > 0:
                self._start(self._deferred)
            else:
                self._apply_deferred(stages, count=False)
        self._previous = (torus, time_s)

    def _start(self, update: _DeferredUpdate) -> None:
        """Where an amortized update is computed, once drawn: here, in the session's thread's idle
        moments or on its frame (do_deferred_work); CompiledOcclusionMaps hands it to a thread."""

    def _settle(self) -> None:
        """The deferred update taken back from the maps thread, or waited for if that has begun
        it, before the scene, the backend or the A-map change or go."""
        if self._deferred is not None and not self._deferred.take_back():
            self._deferred.join()

    @property
    def has_deferred_work(self) -> bool:
        """Whether a deferred update waits to be computed (its maps, their A_s, or its aggregate)
        that this thread may compute: not one the maps thread has begun."""
        update = self._deferred
        if update is None or update.aggregate is not None:
            return False
        return update.computing is None or not (update.computing.running() or update.computing.done())

    def do_deferred_work(self, stages: StageClock | None = None, whole: bool = True) -> bool:
        """Computes the deferred update's maps, their A_s and the aggregate A they make, without
        applying them (they reach the search on their frame); laps PROJECTION and AMAP on `stages`
        when given. Without `whole` only one of the three (the scene's move and the maps, else A_s,
        else the aggregate), so that a worker's idle moment delays a request that arrives meanwhile
        by less. An update handed to the maps thread is taken back if that has not begun it, else
        waited for with `whole` (and left to it without). Answers whether there was work to do."""
        update = self._deferred
        if update is None or update.aggregate is not None:
            return False
        if not update.take_back():
            if whole:
                update.join()
            return whole
        return self._compute(update, stages, whole)

    def _compute(self, update: _DeferredUpdate, stages: StageClock | None, whole: bool) -> bool:
        """do_deferred_work's pieces, on this thread or the maps thread (there whole, without stages)."""
        if update.predicted is None and update.maps is None:
            assert self.backend is not None  # closing drops the deferred update with the backend
            if update.scene_motion is not None:
                self._move_scene(update.scene_motion)
                update.scene_motion = None
            update.maps = self.backend.compute(
                update.torus,
                update.window,
                update.points_world,
                exclude_ids=update.exclude_ids,
                previous_torus=update.previous_torus,
                dt_s=update.dt_s,
            )
            if stages is not None:
                stages.done(Stage.PROJECTION)
            if not whole:
                return True
        if update.predicted is None:
            assert update.maps is not None  # computed above, or by an earlier piece
            update.predicted = self._predict(update.maps)
            update.maps = None
            if not whole:
                return True
        update.aggregate = self.amap.prepare(update.slots, update.predicted, update.window, update.torus)
        if stages is not None:
            stages.done(Stage.AMAP)
        return True

    def _predict(self, maps: ShadowVelocityMaps) -> npt.NDArray[np.float32]:
        """A_s (k, res, res) of freshly computed maps (AnticipationMap.predict)."""
        return self.amap.predict(maps)

    def _apply_deferred(self, stages: StageClock, count: bool = True) -> None:
        """One frame nearer for the deferred update (with `count`); on its frame, it is computed
        if no idle moment (nor the maps thread) did, and stored in the A-map; AMAP lapped, and
        PROJECTION too when this frame computed the maps of an update never handed to that thread."""
        update = self._deferred
        if update is None:
            return
        if count:
            update.frames_left -= 1
        if update.frames_left > 0:
            return
        self.do_deferred_work(None if update.handed else stages)
        self._deferred = None
        assert update.predicted is not None  # do_deferred_work computed it, whole
        self.amap.store(update.time_s, update.slots, update.predicted, update.window, update.torus, update.aggregate)
        stages.done(Stage.AMAP)

    def invalidate(self) -> None:
        """After a cut: the old window is elsewhere (a deferred update of it is dropped)."""
        self._settle()
        self._deferred = None
        self.amap.invalidate()

    def risk(self, theta: npt.ArrayLike, phi: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The A-map as the search's RiskField; places off the window read as occluded."""
        return self.amap.lookup(theta, phi, outside=1.0)

    def close(self) -> None:
        """Releases the backend (its GL objects, or its Embree scenes); idempotent."""
        if self._deferred is not None and not self._deferred.take_back():
            assert self._deferred.computing is not None  # begun: its outcome no longer matters, but the backend is in use
            wait([self._deferred.computing])
        self._deferred = None
        if self.backend is not None:
            self.backend.close()
            self.backend = None
