"""One director session: its scene, the latest transforms, and the camera rig's state.

`Session.frame` runs the pipeline stages in the order pipeline.py writes down; a session created
with the TRACKS rig runs tracks_rig.py after INGEST instead of the Toric stages. The session never
raises inside the frame loop for a geometric difficulty: it degrades (holds the pose, frames one
target) and flags it in the diagnostics.
"""
from __future__ import annotations

import math
import time
from typing import Callable

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform, matrix_to_quat
from camdirector.geometry.toric import torus_angles
from camdirector.server.camera_motion import ToricMotion, pose_on_torus
from camdirector.server.occlusion_maps import OcclusionMaps
from camdirector.server.occlusion_search import OcclusionSearch, RaycastRisk, SearchSettings
from camdirector.server.reactive import Deoccluder
from camdirector.server.framing import Framing
from camdirector.server.pipeline import FrameState, Stage
from camdirector.server.style import MAP_MODES, SEARCH_MODES, Style, VisibilityMode
from camdirector.server.target_sampling import TargetSampler
from camdirector.server.tracks_rig import TracksRig
from camdirector.server.visibility import VisibilityEstimate
from camdirector.server.wire import FrameInput, SceneSpec


class Session:
    def __init__(self, session_id: str, scene: SceneSpec, clock: Callable[[], float] = time.perf_counter):
        self.id = session_id
        self.clock = clock
        self.rng = np.random.default_rng(scene.seed)
        self.lens = scene.lens
        self.style = scene.style
        self.targets = scene.targets
        self.target_index = {t.id: i for i, t in enumerate(scene.targets)}
        self.target_transforms = [t.transform for t in scene.targets]
        self.static_ids = {o.id for o in scene.objects if not o.dynamic}
        self.movable_ids = {o.id for o in scene.objects if o.dynamic} | set(self.target_index)
        self.static_meshes_world = [_to_world(o.mesh, o.transform) for o in scene.objects if not o.dynamic]
        level_meshes = [scene.level.mesh_world] if scene.level is not None else []  # TRACKS: the level occludes
        self.ray_scene = RayScene(self.static_meshes_world + level_meshes)
        self.dynamic = {o.id: (o.mesh, o.transform) for o in scene.objects if o.dynamic}  # latest transforms
        for object_id, (mesh, transform) in self.dynamic.items():
            self.ray_scene.add_dynamic(object_id, mesh, transform)
        self.framing = Framing(self.lens, self.style, scene.targets[0].transform.rotation_xyzw)
        self.motion = ToricMotion(self.style, self.lens)
        self.visibility = VisibilityEstimate(self.ray_scene, [t.mesh for t in scene.targets], self.rng)
        self.sampler = TargetSampler([t.mesh for t in scene.targets], self.rng)  # the paper's 2r points
        self.maps: OcclusionMaps | None = None  # built when a map mode is first asked for
        if self.style.visibility in MAP_MODES:  # now, so the first frame does not pay for it
            self._build_maps()
        self.search = OcclusionSearch(SearchSettings(), self.rng)
        self.deoccluder = Deoccluder(self.ray_scene)
        self._searching = False  # whether the search particle holds the camera's place
        # The TRACKS rig replaces framing, motion and visibility (tracks_rig.py); None for TORIC.
        self.tracks = TracksRig(scene.level, self.lens, self.style, self.rng, clock) if scene.level is not None else None
        self.last_state: FrameState | None = None
        self.frames_answered = 0
        self.shot_id = 0
        self._style_cut = False

    def set_style(self, style: Style) -> None:
        """From the next frame on. A changed composition cannot be reached smoothly: it is a cut.
        The rig itself never changes (wire.py refuses it)."""
        if self.tracks is not None:  # TRACKS reads only shot size and movement
            self.style = style
            self.tracks.set_style(style)
            return
        if (style.screen_a, style.screen_b) != (self.style.screen_a, self.style.screen_b):
            self._style_cut = True
        self.style = style
        self.framing.set_style(style)
        self.motion.set_style(style)
        if self.maps is not None:
            self.maps.set_style(style)
        elif style.visibility in MAP_MODES:
            self._build_maps()

    def _build_maps(self) -> None:
        self.maps = OcclusionMaps(self.static_meshes_world, self.dynamic, self.sampler, self.style, self.rng)

    def is_stale(self, frame: int) -> bool:
        return self.last_state is not None and frame <= self.last_state.frame

    def frame(self, update: FrameInput) -> FrameState:
        """Runs one frame. The caller has checked that update.frame is newer than the last."""
        last = self.last_state
        dt_s = 0.0 if last is None else max(0.0, update.time_s - last.time_s)
        state = FrameState(frame=update.frame, time_s=update.time_s, dt_s=dt_s)
        if last is not None and update.time_s < last.time_s:
            state.flags.append("time_went_back")
        t0 = self.clock()
        for object_id, transform in update.states:  # Stage.INGEST
            index = self.target_index.get(object_id)
            if index is None:
                self.ray_scene.set_transform(object_id, transform)
                self.dynamic[object_id] = (self.dynamic[object_id][0], transform)
            else:
                self.target_transforms[index] = transform
        state.aim_points_world = [tf.apply(t.aim_offset_local[None, :])[0]
                                  for tf, t in zip(self.target_transforms, self.targets)]
        t1 = self.clock()
        if self.tracks is not None:  # Stage.MOTION and Stage.VISIBILITY of the TRACKS rig
            self.tracks.run(state, self.target_transforms[0], self.ray_scene, None if last is None else last.pose)
        else:
            self._toric_stages(state, update)
        state.stage_ms[Stage.INGEST.name.lower()] = (t1 - t0) * 1e3
        state.cut = state.cut or last is None or self._style_cut
        self._style_cut = False
        if state.cut:
            self.shot_id += 1
        state.shot_id = self.shot_id
        self.last_state = state
        self.frames_answered += 1
        return state

    def _toric_stages(self, state: FrameState, update: FrameInput) -> None:
        """FRAMING, PROJECTION, AMAP, MOTION and VISIBILITY of the TORIC rig, timed into state."""
        last = self.last_state
        t1 = self.clock()
        self.framing.run(state)  # Stage.FRAMING
        if self.maps is not None:
            self.maps.ingest(update.states, update.time_s)
        t2 = self.clock()
        self._move(state)  # Stage.PROJECTION, Stage.AMAP, Stage.MOTION
        if state.pose is None:
            state.pose = last.pose if last is not None else _fallback_pose(state, self.lens.vertical_fov_deg)
        t3 = self.clock()
        self.visibility.run(state, self.target_transforms)  # Stage.VISIBILITY
        t4 = self.clock()
        map_ms = sum(state.stage_ms.values())  # projection and A-map, filled by _move
        state.stage_ms.update({
            Stage.FRAMING.name.lower(): (t2 - t1) * 1e3,
            Stage.MOTION.name.lower(): (t3 - t2) * 1e3 - map_ms,
            Stage.VISIBILITY.name.lower(): (t4 - t3) * 1e3,
        })


    def _move(self, state: FrameState) -> None:
        """MOTION: the rig of the style's visibility mode (FRAMING_ONLY: camera_motion.py; REACTIVE:
        that plus reactive.py; RAYCAST and the map modes: occlusion_search.py)."""
        mode = self.style.visibility
        if mode not in SEARCH_MODES or state.torus is None:
            if self._searching:  # hand the camera's place back to the toric rig
                self.motion.theta, self.motion.position_world = self.search.theta, self.last_state.pose.position_world
                self._searching = False
            self.motion.run(state)
            if mode == VisibilityMode.REACTIVE and state.pose is not None:
                state.pose, pulled = self.deoccluder.run(state.pose, state.a_world, state.time_s, state.dt_s)
                if pulled:
                    state.flags.append("pulled_in")
            return
        torus = state.torus
        if not self._searching:
            if self.motion.position_world is None:
                theta, phi, _, _ = self.motion.preferred_place(torus)
            else:
                theta, phi = torus_angles(torus, self.motion.position_world)
            self.search.start(theta, phi, state.time_s)
            self._searching = True
        points = self.sampler.points_world(self.target_transforms)

        def occluded(cameras_world: np.ndarray) -> np.ndarray:
            return self.visibility.occluded_fraction(cameras_world, points)

        if mode in MAP_MODES:
            state.stage_ms.update(self.maps.update(torus, self.search.theta, self.search.phi, state.time_s,
                                                   self.target_transforms, [t.id for t in self.targets]))
            risk = self.maps
        else:
            risk = RaycastRisk(torus, occluded)
        side = math.copysign(1.0, self.motion.preferred_place(torus)[1])  # upright half for cuts
        result = self.search.step(torus, state.dt_s, state.time_s, risk, occluded, side,
                                  self.style.max_speed_m_s, self.style.max_accel_m_s2)
        state.theta, state.phi, state.cut = result.theta, result.phi, result.cut
        state.flags.append(f"search_{result.strategy}")
        if result.cut and self.maps is not None:
            self.maps.invalidate()
        state.pose = pose_on_torus(torus, result.theta, result.phi, self.style, self.lens, state.b_is_gaze_point)
        self.motion.position_world = state.pose.position_world


def _to_world(mesh: TriMesh, transform: RigidTransform) -> TriMesh:
    return TriMesh(transform.apply(mesh.vertices), mesh.faces)


def _fallback_pose(state: FrameState, fov_deg: float) -> CameraPose:
    """Only when the very first frame has no usable torus: behind and above A, looking at it."""
    target = state.aim_points_world[0]
    position = target + np.array([0.0, 2.0, 6.0])
    forward = (target - position) / np.linalg.norm(target - position)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return CameraPose(position, matrix_to_quat(np.stack([right, up, -forward], axis=1)), fov_deg)
