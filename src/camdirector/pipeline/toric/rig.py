"""The TORIC rig of a session: framing on the Toric manifold and the camera's motion on it, with
the visibility mode of the session's style (pipeline/stages.py: FRAMING, PROJECTION, AMAP,
MOTION and VISIBILITY; the TRACKS rig, pipeline/tracks/rig.py, replaces all five).

Per frame `ToricRig.run` frames the targets (framing.py), moves the camera by the style's
visibility mode (FRAMING_ONLY: camera_motion.py; REACTIVE: that plus reactive.py; RAYCAST and the
map modes: occlusion_search.py, the map modes with occlusion_maps.py), then, from the final pose,
estimates the targets' visibility (visibility.py) and measures the framing error (framing.py:
`Framing.error`; in VISIBILITY, the other measure of what the frame shows). The occlusion maps are
built when a map mode is first asked for, at creation when the style starts in one, so the first
frame does not pay for them; `close()` releases their backend (its GL objects, or Embree scenes)
when the session ends.

`ToricRig` implements `CameraRig` (pipeline/camera_rig.py): of what only some rigs do, it draws
the A-map (`anticipation_map`, in the map modes) and defers its amortized map updates
(`do_deferred_work`); for the rest (no player inputs, the targets as of the latest frame) it
answers as `RigBase` does. Its part of a frame's state is `ToricFrame` (frame.py).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.toric import Torus, torus_angles
from camdirector.geometry.transforms import RigidTransform, matrix_to_quat
from camdirector.infra.stage_clock import StageClock
from camdirector.pipeline.camera_rig import AnticipationView, RigBase
from camdirector.pipeline.inputs import DynamicObjects, FrameInput, SceneSpec
from camdirector.pipeline.stages import Stage
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import MAP_MODES, SEARCH_MODES, Style, VisibilityMode
from camdirector.pipeline.toric.camera_motion import ToricMotion, pose_on_torus
from camdirector.pipeline.toric.frame import ToricFrame
from camdirector.pipeline.toric.framing import Framing
from camdirector.pipeline.toric.occlusion_maps import OcclusionMaps
from camdirector.pipeline.toric.occlusion_search import (
    OcclusionSearch,
    RaycastRisk,
    RiskField,
    SearchResult,
    SearchSettings,
)
from camdirector.pipeline.toric.reactive import Deoccluder
from camdirector.pipeline.toric.target_sampling import TargetSampler
from camdirector.pipeline.toric.visibility import VisibilityEstimate


class ToricRig(RigBase):
    """The Toric camera of one session; implements `CameraRig` (module docstring). ray_scene,
    static_meshes_world and dynamic (object id -> (mesh, latest transform)) are the session's,
    kept current by INGEST."""

    _sampler_class = TargetSampler  # the maps' and the search's sample points (the compiled rig's carries them)

    def __init__(
        self,
        scene: SceneSpec,
        ray_scene: RayScene,
        static_meshes_world: list[TriMesh],
        dynamic: DynamicObjects,
        rng: np.random.Generator,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.lens = scene.lens
        self.style = scene.style
        self.target_ids = [t.id for t in scene.targets]
        self.static_meshes_world = static_meshes_world
        self.dynamic = dynamic
        self.ray_scene = ray_scene
        self.rng = rng
        self.clock = clock
        self.framing = Framing(self.lens, self.style, scene.targets[0].transform.rotation_xyzw)
        self.motion = ToricMotion(self.style, self.lens)
        self.visibility = VisibilityEstimate(ray_scene, [t.mesh for t in scene.targets], rng)
        self.sampler = self._sampler_class([t.mesh for t in scene.targets], rng)  # the paper's 2r points
        self.search = OcclusionSearch(SearchSettings(), rng)
        self.deoccluder = Deoccluder(ray_scene)
        self._searching = False  # whether the search particle holds the camera's place
        self._style_cut = False
        self.maps: OcclusionMaps | None = None
        if self.style.visibility in MAP_MODES:  # last: nothing after it can fail and leave its GL objects behind
            self._build_maps()

    def set_style(self, style: Style) -> None:
        """From the next frame on. A changed composition cannot be reached smoothly: it is a cut."""
        if (style.screen_a, style.screen_b) != (self.style.screen_a, self.style.screen_b):
            self._style_cut = True
        self.style = style
        self.framing.set_style(style)
        self.motion.set_style(style)
        if self.maps is not None:
            self.maps.set_style(style)
        elif style.visibility in MAP_MODES:
            self._build_maps()

    def anticipation_map(self, state: FrameState | None) -> AnticipationView | None:
        """The A-map (n, n), rows theta and columns phi, and the texel (i, j) of the camera of
        `state`, the last answered frame; None unless the style is a map mode and the maps have
        been computed once."""
        if state is None or state.toric is None or self.maps is None or self.style.visibility not in MAP_MODES:
            return None
        amap = self.maps.amap
        if amap.a_map is None or amap.window is None:  # set together, by the first update
            return None
        i, j = amap.window.texel_coords(state.toric.theta, state.toric.phi)
        return amap.a_map, (float(i), float(j))

    @property
    def thread_bound(self) -> bool:
        """Whether the maps' backend is GL's (its objects in the making thread's EGL context)."""
        return self.maps is not None and self.maps.backend_name == "gl"

    def _build_maps(self) -> None:
        self.maps = OcclusionMaps(self.static_meshes_world, self.dynamic, self.sampler, self.style, self.rng)

    def do_deferred_work(self, whole: bool = True) -> bool:
        """Computes a deferred map update now, or without `whole` a part of it (occlusion_maps.py);
        answers whether there was work to do."""
        return self.maps is not None and self.maps.do_deferred_work(whole=whole)

    @property
    def has_deferred_work(self) -> bool:
        return self.maps is not None and self.maps.has_deferred_work

    def close(self) -> None:
        """Releases the occlusion maps' backend; idempotent."""
        if self.maps is not None:
            self.maps.close()
            self.maps = None

    def run(
        self, state: FrameState, update: FrameInput, target_transforms: list[RigidTransform], last: FrameState | None
    ) -> None:
        """FRAMING, PROJECTION, AMAP, MOTION and VISIBILITY into state and its part `state.toric`,
        timed into state.stage_ms; a composition changed by set_style since the last frame makes
        this frame a cut."""
        toric = state.toric = ToricFrame()
        stages = StageClock(clock=self.clock, timings_ms=state.stage_ms)
        self._frame(state, toric)
        if self.maps is not None:
            self.maps.ingest(update.states, update.time_s)
        stages.done(Stage.FRAMING)
        self._move_and_see(state, toric, target_transforms, last, stages)
        state.cut = state.cut or self._style_cut
        self._style_cut = False

    def _move_and_see(
        self,
        state: FrameState,
        toric: ToricFrame,
        target_transforms: list[RigidTransform],
        last: FrameState | None,
        stages: StageClock,
    ) -> None:
        """MOTION (with the maps' stages in the map modes), then VISIBILITY, lapped on `stages`."""
        self._move(state, toric, target_transforms, last, stages)
        if state.pose is None:
            state.pose = last.pose if last is not None else _fallback_pose(state, self.lens.vertical_fov_deg)
        assert state.pose is not None  # this rig answers a pose on every frame
        stages.done(Stage.MOTION)
        self._see(state, toric, target_transforms)
        stages.done(Stage.VISIBILITY)

    def _frame(self, state: FrameState, toric: ToricFrame) -> None:
        """FRAMING: A, B and the torus into `toric`."""
        self.framing.run(state, toric)

    def _see(self, state: FrameState, toric: ToricFrame, target_transforms: list[RigidTransform]) -> None:
        """VISIBILITY, from the frame's final pose: the targets' estimated visibility and the
        framing error."""
        assert state.pose is not None  # run() answers a pose before VISIBILITY
        self.visibility.run(state, target_transforms)
        state.framing_error = self.framing.error(state.pose, toric)

    def _end_search(self, last: FrameState | None) -> None:
        """Hands the camera's place back from the search to the toric motion (a search mode left)."""
        assert last is not None and last.pose is not None  # the search ran on an earlier frame
        self.motion.theta, self.motion.position_world = self.search.theta, last.pose.position_world
        self._searching = False

    def _move(
        self,
        state: FrameState,
        toric: ToricFrame,
        target_transforms: list[RigidTransform],
        last: FrameState | None,
        stages: StageClock,
    ) -> None:
        """MOTION: the rig of the style's visibility mode (FRAMING_ONLY: camera_motion.py; REACTIVE:
        that plus reactive.py; RAYCAST and the map modes: occlusion_search.py), with PROJECTION and
        AMAP lapped on `stages` in the map modes when the maps are due."""
        mode = self.style.visibility
        if mode not in SEARCH_MODES or toric.torus is None:
            if self._searching:
                self._end_search(last)
            self.motion.run(state, toric)
            if mode == VisibilityMode.REACTIVE and state.pose is not None:
                assert toric.a_world is not None  # FRAMING placed it
                state.pose, pulled = self.deoccluder.run(state.pose, toric.a_world, state.time_s, state.dt_s)
                if pulled:
                    state.flags.append("pulled_in")
            return
        torus = toric.torus
        self._begin_search(torus, state.time_s)
        points = self.sampler.points_world(target_transforms)  # before the maps' update redraws some
        if mode in MAP_MODES:
            stages.done(Stage.MOTION)  # the search's set-up; the maps lap their own stages
            assert self.maps is not None  # built when the style entered a map mode
            assert self.search.theta is not None  # the search started above
            self.maps.update(torus, self.search.theta, self.search.phi, state.time_s, target_transforms, self.target_ids, stages)
        side = math.copysign(1.0, self.motion.preferred_place(torus)[1])  # upright half for cuts
        result, state.pose = self._search_step(torus, state, points, side, toric.b_is_gaze_point)
        toric.theta, toric.phi, state.cut = result.theta, result.phi, result.cut
        state.flags.append(f"search_{result.strategy}")
        if result.cut and self.maps is not None:
            self.maps.invalidate()
        self.motion.position_world = state.pose.position_world

    def _begin_search(self, torus: Torus, time_s: float) -> None:
        """Starts the search's particle where the camera is (at the preferred place before any
        pose) on the first frame of a search mode; nothing while it searches."""
        if self._searching:
            return
        if self.motion.position_world is None:
            theta, phi, _, _ = self.motion.preferred_place(torus)
        else:
            theta, phi = torus_angles(torus, self.motion.position_world)
        self.search.start(theta, phi, time_s)
        self._searching = True

    def _search_step(
        self, torus: Torus, state: FrameState, points_world: npt.NDArray[np.float64], side: float, level: bool
    ) -> tuple[SearchResult, CameraPose]:
        """MOTION's search for one frame (occlusion_search.py) against the mode's risk field (the
        maps, or ray casts to the target sample points `points_world` (k, 3) metres), cut
        candidates on the `side` half, and the camera's pose at its answer (`level`: B is only a
        gaze-room point, pose_on_torus)."""

        def occluded(cameras_world: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            return self.visibility.occluded_fraction(cameras_world, points_world)

        risk: RiskField
        if self.style.visibility in MAP_MODES:
            assert self.maps is not None  # built when the style entered a map mode
            risk = self.maps
        else:
            risk = RaycastRisk(torus, occluded)
        result = self.search.step(
            torus, state.dt_s, state.time_s, risk, occluded, side, self.style.max_speed_m_s, self.style.max_accel_m_s2
        )
        return result, pose_on_torus(torus, result.theta, result.phi, self.style, self.lens, level)


def _fallback_pose(state: FrameState, fov_deg: float) -> CameraPose:
    """Only when the very first frame has no usable torus: behind and above A, looking at it."""
    target = state.aim_points_world[0]
    position = target + np.array([0.0, 2.0, 6.0])
    forward = (target - position) / np.linalg.norm(target - position)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return CameraPose(position, matrix_to_quat(np.stack([right, up, -forward], axis=1)), fov_deg)
