"""The TORIC rig with its FRAMING_ONLY frames and its search compiled (issue 43; `--frame-path compiled`).

`CompiledToricRig` is `ToricRig` (rig.py) with parts of its stages run in camdirector._native:

- In every mode, FRAMING in `FramingCore` (framing.py's twin), which holds the one-target heading,
  and the framing error VISIBILITY measures (`FramingCore.error`, Framing.error's twin).
- While the style's visibility mode is FRAMING_ONLY or REACTIVE, MOTION and VISIBILITY too:
  MOTION in `MotionCore` (camera_motion.py's) and, in REACTIVE, `DeoccluderCore` (reactive.py's
  Deoccluder, its ray casts in the `Scene`), the three stages in one call (`toric_frame`), lapped
  where ToricRig.run laps them.
- In the search modes (ANTICIPATION, NO_ANTICIPATION, RAYCAST), MOTION's search in `SearchCore`
  (occlusion_search.py's `OcclusionSearch.step` and the pose at its answer), reading the A-map
  or ray casts, and drawing its candidates from the session's generator as the Python draws
  them; the particle stays in the Python `OcclusionSearch`, which the core moves each frame.
  After FRAMING and the maps' update, the search's MOTION and VISIBILITY are one native call
  (`search_frame`): the targets' sample points carried, the upright side (a MotionCore's
  `preferred_place` from ToricMotion's side, kept in Python), the step, the share seen and the
  framing error, lapped where ToricRig.run laps them. The points the maps read are carried by
  camdirector._native's `carry` (`CarriedTargetSampler`), a call per target.
- In the map modes, PROJECTION's ray casts and AMAP's per-sample predictions
  (compiled_maps.py); their schedule, window and aggregate stay Python.
- In FRAMING_ONLY, REACTIVE and the search modes, VISIBILITY's ray casts, and the search's, in a `Scene`
  (geometry/raycast.py RayScene's twin), built from the session's RayScene on the first compiled
  frame and moved with the session's moving objects (by the frame's decoded rows in one call,
  `move_scene`). A FRAMING_ONLY frame's state keeps the compiled torus, pickled as the Python one.

Python stays the reference: it answers the same FrameState within 1e-9 m and 1e-9 rad, with the
same flags and cuts (tests/pipeline/toric/test_compiled_rig.py; the search per call,
tests/native/test_search_native.py), and the compiled stages draw from the session's generator
exactly what the Python ones draw (VISIBILITY's sample points are the Python stage's). What a
FRAMING_ONLY or REACTIVE frame computes has the same bits on every x86-64 machine
(tests/worker/test_recordings_across_machines.py): the sample points are carried by the targets
with camdirector._native's `carry`, not numpy's product (OpenBLAS's kernel is the CPU's), and the
one-target heading starts as `FramingCore` computes it. The search and map modes' recordings
replay across machine kinds too, though their particle and their maps' schedule and aggregate
stay numpy (docs/frame_path.md says what that leaves open).

The cores hold the stages' state between frames. The FramingCore holds the one-target heading on
every frame. The motion and deoccluder cores hold the camera's place, rates and upright side and
the deoccluder's last correction while the mode is FRAMING_ONLY or REACTIVE: entering it copies
that from the Python stages into the cores (after the search hands the camera back, as rig.py
does), leaving it copies it back, so a change of mode moves the camera no more than the Python
rig would. A pickled rig (a checkpoint's snapshot) carries the state in its Python stages and
builds its cores and Scene again on its next compiled frame.
"""

from __future__ import annotations

import copyreg
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

import camdirector._native as native
from camdirector.geometry.camera import CameraPose
from camdirector.geometry.toric import Torus
from camdirector.geometry.transforms import RigidTransform
from camdirector.infra.stage_clock import StageClock
from camdirector.pipeline.inputs import FrameInput, SceneSpec
from camdirector.pipeline.stages import Stage
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import MAP_MODES, SEARCH_MODES, Style, VisibilityMode
from camdirector.pipeline.toric.compiled_maps import CompiledOcclusionMaps
from camdirector.pipeline.toric.frame import ToricFrame
from camdirector.pipeline.toric.rig import ToricRig, _fallback_pose
from camdirector.pipeline.toric.target_sampling import TargetSampler

_NO_ROTATION = np.array([0.0, 0.0, 0.0, 1.0])  # a core's initial facing, which its copied heading replaces
_COMPILED_MODES = (VisibilityMode.FRAMING_ONLY, VisibilityMode.REACTIVE)  # whose frames the cores run whole


class CarriedTargetSampler(TargetSampler):
    """TargetSampler whose points are carried by camdirector._native's `carry` (RigidTransform.apply's
    twin within rounding, the same bits on every x86-64 machine): all slots in one call per target."""

    def points_world(
        self, target_transforms: Sequence[RigidTransform], slots: Sequence[int] | None = None
    ) -> npt.NDArray[np.float64]:
        """(len(slots), 3) world metres: the slots' points (all slots if None) under the targets' transforms."""
        if len(target_transforms) != self.target_count:
            raise ValueError("points_world: one transform per target")
        r = self.settings.samples_per_target
        if slots is None:
            return np.concatenate(
                [native.carry(self.points_local[t * r : (t + 1) * r], transform) for t, transform in enumerate(target_transforms)]
            )
        out = np.empty((len(slots), 3))
        for row, slot in enumerate(slots):
            out[row] = native.carry(self.points_local[slot], target_transforms[self.target_of(int(slot))])
        return out


class CompiledToricRig(ToricRig):
    """`ToricRig` with its stages compiled as the module docstring says; the same arguments."""

    _sampler_class = CarriedTargetSampler
    _framing_core: Any = None  # the FramingCore, on every frame: made at creation, and again after a restore
    # Made on demand, never at creation: a rig that never runs FRAMING_ONLY builds no motion core.
    _cores: tuple[Any, Any] | None = None  # (MotionCore, DeoccluderCore) while they hold the state
    _scene: Any = None  # the Scene, made on the first compiled frame
    _runs = 0  # frames run; the Scene was last moved in frame `_scene_run` of them (it holds `dynamic` as of then)
    _scene_run = -1
    _search_core: Any = None  # the SearchCore, made on the first compiled search step
    _side_core: Any = None  # a MotionCore that chooses the search's upright side (ToricMotion's side kept in Python)
    _packed: tuple[list[str], npt.NDArray[np.float64]] | None = None  # the frame's FrameInput.packed, till the Scene takes it

    def __init__(self, scene: SceneSpec, *rest: Any) -> None:
        """ToricRig's arguments. The one-target heading starts as `FramingCore` computes it from
        the target's rotation (the libm crate's atan2), not as Framing does (numpy's product through
        OpenBLAS, then the system's libm: the CPU's bits), so a compiled session starts the same on
        every machine; the two agree within rounding."""
        super().__init__(scene, *rest)
        self._framing_core = native.FramingCore(
            self.lens, self.style, scene.targets[0].transform.rotation_xyzw, self.framing.settings
        )
        self.framing.heading_rad = self._framing_core.heading_rad

    @property
    def compiled(self) -> bool:
        """Whether the compiled stages hold the camera (the last frame, or the next, is FRAMING_ONLY or REACTIVE)."""
        return self._cores is not None

    def set_style(self, style: Style) -> None:
        super().set_style(style)
        if self._framing_core is not None:
            self._framing_core.set_style(style)
        if self._cores is not None:
            self._cores[0].set_style(style)  # the deoccluder's settings are not the style's
        if self._search_core is not None:
            self._search_core.set_style(style)
        if self._side_core is not None:
            self._side_core.set_style(style)

    def __getstate__(self) -> dict[str, object]:
        """The rig's state with the stages' state in its Python stages; no native object."""
        if self._framing_core is not None:
            self.framing.heading_rad, self.framing._last_aim = self._framing_core.heading_rad, self._framing_core.last_aim
        if self._cores is not None:
            self._python_from_cores()
        state = self.__dict__.copy()
        state.update(_framing_core=None, _cores=None, _scene=None, _search_core=None, _side_core=None, _packed=None)
        return state

    def run(
        self, state: FrameState, update: FrameInput, target_transforms: list[RigidTransform], last: FrameState | None
    ) -> None:
        """ToricRig.run, on the side of the style's visibility mode (module docstring)."""
        compiled = self.style.visibility in _COMPILED_MODES
        if compiled and self._cores is None:
            if self._searching:
                self._end_search(last)
            self._cores = self._cores_from_python()
        elif not compiled and self._cores is not None:
            self._python_from_cores()
            self._cores = None
        self._runs += 1
        self._packed = update.packed
        if compiled:
            self._run_cores(state, update, target_transforms, last)
        else:
            super().run(state, update, target_transforms, last)
        self._packed = None

    def _run_cores(
        self, state: FrameState, update: FrameInput, target_transforms: list[RigidTransform], last: FrameState | None
    ) -> None:
        """ToricRig.run for a frame of the cores (FRAMING_ONLY, REACTIVE): FRAMING, MOTION and
        VISIBILITY in one native call (`toric_frame`, the cores' code in the order ToricRig.run's
        stage methods call it), lapped on the session's clock at the same readings as ToricRig.run's
        StageClock (a clock that ticks per reading laps both the same). The Scene is moved first,
        inside FRAMING's lap (ToricRig.run moves it in MOTION in REACTIVE, in VISIBILITY otherwise)."""
        assert self._cores is not None  # run() made them for this mode
        toric = state.toric = ToricFrame()
        start_s = self.clock()
        if self.maps is not None:  # a map mode's maps, kept after it, take every frame's objects (ToricRig.run)
            self.maps.ingest(update.states, update.time_s)
        # the pose the frame keeps when MOTION answers none (a degenerate torus), as ToricRig.run's
        held = last.pose if last is not None else _fallback_pose(state, self.lens.vertical_fov_deg)
        motion, deoccluder = self._cores
        (
            toric.a_world,
            toric.b_world,
            toric.b_is_gaze_point,
            toric.torus,  # the compiled torus: the wire reads its alpha; pickled, it is a Torus (_reduce_torus)
            toric.theta,
            toric.phi,
            pose,
            flags,
            state.visibility,
            state.framing_error,
        ) = native.toric_frame(
            self._framing(),
            motion,
            deoccluder if self.style.visibility == VisibilityMode.REACTIVE else None,
            self._moved_scene(),
            state.aim_points_world,
            self.visibility.samples_local,
            target_transforms,
            held,
            state.time_s,
            state.dt_s,
            self.clock,
            start_s,
            state.stage_ms,
        )
        state.pose = held if pose is None else CameraPose(*pose)
        state.flags.extend(flags)
        state.cut = state.cut or self._style_cut
        self._style_cut = False

    def _framing(self) -> Any:
        """The FramingCore; after a restore, made again from the Python Framing's heading."""
        if self._framing_core is None:
            framing = self.framing
            core = native.FramingCore(self.lens, self.style, _NO_ROTATION, framing.settings)
            core.heading_rad, core.last_aim = framing.heading_rad, framing._last_aim
            self._framing_core = core
        return self._framing_core

    def _cores_from_python(self) -> tuple[Any, Any]:
        motion, deoccluder = self.motion, self.deoccluder
        motion_core = native.MotionCore(self.style, self.lens, motion.settings)
        motion_core.theta, motion_core.phi, motion_core.rate = motion.theta, motion.phi, motion.rate
        motion_core.position_world, motion_core.side, motion_core.side_key = motion.position_world, motion.side, motion._side_key
        deoccluder_core = native.DeoccluderCore(deoccluder.settings)
        deoccluder_core.offset_from_a, deoccluder_core.displacement = deoccluder._offset_from_a, deoccluder._displacement
        deoccluder_core.damp_time_s, deoccluder_core.time_s = deoccluder._damp_time_s, deoccluder._time_s
        return motion_core, deoccluder_core

    def _python_from_cores(self) -> None:
        assert self._cores is not None
        (motion_core, deoccluder_core), motion = self._cores, self.motion
        motion.theta, motion.phi, motion.rate = motion_core.theta, motion_core.phi, motion_core.rate
        motion.position_world, motion.side, motion._side_key = motion_core.position_world, motion_core.side, motion_core.side_key
        deoccluder = self.deoccluder
        deoccluder._offset_from_a, deoccluder._displacement = deoccluder_core.offset_from_a, deoccluder_core.displacement
        deoccluder._damp_time_s, deoccluder._time_s = deoccluder_core.damp_time_s, deoccluder_core.time_s

    def _build_maps(self) -> None:
        self.maps = CompiledOcclusionMaps(self.static_meshes_world, self.dynamic, self.sampler, self.style, self.rng)

    def _move_and_see(
        self,
        state: FrameState,
        toric: ToricFrame,
        target_transforms: list[RigidTransform],
        last: FrameState | None,
        stages: StageClock,
    ) -> None:
        """ToricRig._move_and_see for a frame of a search mode: the maps' update (map modes) in
        Python, then the search's MOTION (the points, the upright side, the SearchCore's step and
        pose, which moves the Python search's particle) and VISIBILITY in one native call
        (`search_frame`), lapped where ToricRig laps them. A degenerate torus holds the camera as
        ToricRig's does."""
        torus = toric.torus
        if self.style.visibility not in SEARCH_MODES or torus is None:
            super()._move_and_see(state, toric, target_transforms, last, stages)
            return
        self._begin_search(torus, state.time_s)
        search, motion, sampler = self.search, self.motion, self.sampler
        points_local, amap = sampler.points_local, None
        if self.style.visibility in MAP_MODES:
            stages.done(Stage.MOTION)  # the search's set-up; the maps lap their own stages
            assert self.maps is not None and search.theta is not None  # built with the mode; started above
            points_local = points_local.copy()  # the update may redraw some, after the frame's points were taken
            self.maps.update(torus, search.theta, search.phi, state.time_s, target_transforms, self.target_ids, stages)
            amap = self.maps.amap
        if self._search_core is None:
            self._search_core = native.SearchCore(search.settings, self.style, self.lens)
        if self._side_core is None:
            self._side_core = native.MotionCore(self.style, self.lens, motion.settings)
        (
            toric.theta,
            toric.phi,
            cut,
            strategy,
            (search.theta, search.phi, search.velocity_world, search.shot_start_s, search._occluded_since_s),
            pose,
            motion.side,
            motion._side_key,
            state.visibility,
            state.framing_error,
        ) = native.search_frame(
            self._search_core,
            self._side_core,
            self._framing(),
            self._moved_scene(),
            torus,
            (search.theta, search.phi, search.velocity_world, search.shot_start_s, search._occluded_since_s),
            motion.side,
            motion._side_key,
            points_local,
            target_transforms,
            search.rng,
            amap,
            self.visibility.samples_local,
            toric.a_world,
            toric.b_world,
            toric.b_is_gaze_point,
            state.time_s,
            state.dt_s,
            self.clock,
            stages.last_s,
            state.stage_ms,
        )
        state.cut = cut
        state.flags.append(f"search_{strategy}")
        if cut and self.maps is not None:
            self.maps.invalidate()  # after VISIBILITY's lap: it computes nothing the frame shows
        state.pose = CameraPose(*pose)
        motion.position_world = state.pose.position_world

    def _frame(self, state: FrameState, toric: ToricFrame) -> None:
        """FRAMING in the FramingCore (Framing.run's twin): A, B and the compiled torus into `toric`."""
        toric.a_world, toric.b_world, toric.b_is_gaze_point, toric.torus, flags = self._framing().run(
            state.aim_points_world, state.dt_s
        )
        state.flags.extend(flags)

    def _see(self, state: FrameState, toric: ToricFrame, target_transforms: list[RigidTransform]) -> None:
        """VISIBILITY in the search modes (the only ones ToricRig.run runs here): the share seen in
        the Scene of VisibilityEstimate's sample points, carried by camdirector._native (session.py
        says why); the framing error the FramingCore's (Framing.error's twin)."""
        pose = state.pose
        assert pose is not None and self.style.visibility in SEARCH_MODES  # run() answers a pose before VISIBILITY
        state.visibility = self._moved_scene().visible_share_of(
            pose.position_world, self.visibility.samples_local, target_transforms
        )
        state.framing_error = self._framing().error(
            pose.position_world, pose.rotation_xyzw, toric.a_world, toric.b_world, toric.b_is_gaze_point
        )

    def _moved_scene(self) -> Any:
        """The Scene, its moving objects where the session's are now (INGEST moves the RayScene's).
        When it was moved the frame before, only this frame's states moved anything since: by the
        frame's decoded rows in one call when it has them (INGEST made `dynamic`'s transforms of
        the same rows). Otherwise (frames of another mode since, a frame decoded in Python) every
        moving object by its transform."""
        if self._scene is None:
            self._scene = native.Scene(self.ray_scene.static_meshes_world)
            for object_id, (mesh, transform) in self.dynamic.items():
                self._scene.add_dynamic(object_id, mesh, transform)
        elif self._scene_run == self._runs - 1 and self._packed is not None:
            native.move_scene(self._scene, *self._packed)
        elif self._scene_run != self._runs:
            for object_id, (_, transform) in self.dynamic.items():
                self._scene.set_transform(object_id, transform)
        self._packed, self._scene_run = None, self._runs
        return self._scene


def _reduce_torus(torus: Any) -> tuple[type[Torus], tuple[Any, ...]]:
    """A compiled torus pickled as geometry.toric's Torus (copyreg): what a frame's state held
    before it kept the compiled one, so a snapshot holds and restores the same Torus as then.
    Its arrays are fresh copies, its own."""
    return Torus, (
        torus.a_world,
        torus.b_world,
        torus.alpha,
        torus.axis_world,
        torus.ref_world,
        torus.side_world,
        torus.length_ab_m,
        torus.arc_radius_m,
        torus.mid_world,
        torus.basis,
        torus.center_offset_m,
    )


copyreg.pickle(native.Torus, _reduce_torus)
