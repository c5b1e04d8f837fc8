"""One director session: its scene, the latest transforms, and the camera rig's state.

`Session.frame` runs INGEST, then its rig for the stages after it, in the order
pipeline/stages.py writes down. The rig is chosen once, at creation (`make_rig`), and asked only
through the rig contract (`CameraRig`, pipeline/camera_rig.py), whichever it is. The session
never raises inside the frame loop for a geometric difficulty: it degrades (holds the pose,
frames one target) and flags it in the diagnostics. `Session.close` releases what the rig holds
outside Python's memory (the occlusion maps' GL objects or Embree scenes); whoever ends a session
calls it.

A session whose rig runs compiled (the compiled frame path, `runs_compiled`) carries points by
transforms (the static meshes into the world, INGEST's aim points) with camdirector._native's
`carry`, the same bits on every x86-64 machine; the Python path keeps `RigidTransform.apply`,
whose numpy product goes through OpenBLAS, whose kernel (and so the last bits) is the CPU's.
"""

from __future__ import annotations

import operator
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

import camdirector._native as native
from camdirector.geometry.camera import CameraPose
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.camera_rig import CameraRig
from camdirector.pipeline.inputs import FrameInput, SceneSpec
from camdirector.pipeline.rigs import make_rig, runs_compiled
from camdirector.pipeline.stages import Stage
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style

_INGEST = Stage.INGEST.value  # its stage_ms key, read once: an enum member's value is a Python-level property
_AIM_OFFSET = operator.attrgetter("aim_offset_local")  # a TargetSpec's (3,) aim point in its frame

# A creation object's name (Session.creation_objects): "clock", "level", "level_mesh", or a kind
# ("static", "target", "dynamic") with the object's index or id.
CreationName = str | tuple[str, int | str]


@dataclass(frozen=True)
class CutRecord:
    """The session's last cut, for the monitors' before and after pictures: the two poses, the
    targets in each of the two frames, and the moving objects as they were at the cut (for both:
    keeping every object's frame before each frame would cost every frame what only a cut needs)."""

    frame_before: int
    pose_before: CameraPose
    targets_before: list[RigidTransform]
    frame: int
    pose_after: CameraPose
    targets_after: list[RigidTransform]
    dynamic: dict[str, tuple[TriMesh, RigidTransform]]


class Session:
    portable = False  # whether points are carried by camdirector._native (module docstring); a class default for older snapshots

    def __init__(self, session_id: str, scene: SceneSpec, clock: Callable[[], float] = time.perf_counter, compiled: bool = False):
        """compiled: the rig's compiled twin where it has one (`make_rig`; the server's frame path)."""
        self.id = session_id
        self.portable = runs_compiled(scene.style.rig, compiled)
        self.clock = clock
        self.rng = np.random.default_rng(scene.seed)
        self.lens = scene.lens
        self.style = scene.style
        self.targets = scene.targets
        self.target_index = {t.id: i for i, t in enumerate(scene.targets)}
        self.target_transforms = [t.transform for t in scene.targets]
        self.static_ids = {o.id for o in scene.objects if not o.dynamic}
        self.movable_ids = {o.id for o in scene.objects if o.dynamic} | set(self.target_index)
        self.delay_s = scene.delay_s  # MATCH: the broadcast delay, which a game event's time may run ahead by
        static_meshes_world = [_to_world(o.mesh, o.transform, self.portable) for o in scene.objects if not o.dynamic]
        self.static_meshes_world = static_meshes_world  # and the level's, what the monitors draw (render/snapshots.py)
        self.level = scene.level
        self.level_mesh_world = scene.level.mesh_world if scene.level is not None else None
        level_meshes = [scene.level.mesh_world] if scene.level is not None else []  # TRACKS: the level occludes
        self.ray_scene = RayScene(static_meshes_world + level_meshes)
        self.dynamic = {o.id: (o.mesh, o.transform) for o in scene.objects if o.dynamic}  # latest transforms
        for object_id, (mesh, transform) in self.dynamic.items():
            self.ray_scene.add_dynamic(object_id, mesh, transform)
        # The stages after INGEST: one rig for the session's life (worker/codec.py refuses a change of rig).
        self.rig: CameraRig = make_rig(scene, self.ray_scene, static_meshes_world, self.dynamic, self.rng, clock, compiled)
        self.last_state: FrameState | None = None
        # The newest frame received, (frame, time_s): a MATCH session with a delay answers for an
        # earlier moment, so staleness and dt_s go by what arrived, not by what was answered.
        self.last_input: tuple[int, float] | None = None
        self.frames_answered = 0
        self.shot_id = 0
        self.last_cut: CutRecord | None = None

    def creation_objects(self) -> dict[CreationName, object]:
        """What the session was built from and never changes, by a name that a session built from
        the same creation request gives the same object: its meshes, its level, its clock. A
        checkpoint refers to these by name instead of copying them (worker/checkpointing.py)."""
        objects: dict[CreationName, object] = {"clock": self.clock, "level": self.level, "level_mesh": self.level_mesh_world}
        objects.update({("static", i): mesh for i, mesh in enumerate(self.static_meshes_world)})
        objects.update({("target", i): t.mesh for i, t in enumerate(self.targets)})
        objects.update({("dynamic", object_id): mesh for object_id, (mesh, _) in self.dynamic.items()})
        return {key: value for key, value in objects.items() if value is not None}

    def set_style(self, style: Style) -> None:
        """From the next frame on (the rig's set_style says what a change does)."""
        self.style = style
        self.rig.set_style(style)

    @property
    def has_deferred_work(self) -> bool:
        """Whether the rig left work for later (a TORIC rig's amortized map update,
        pipeline/toric/occlusion_maps.py; a MATCH rig's drawn plan, pipeline/match/rig.py), which a
        later frame does when nobody did it before."""
        return self.rig.has_deferred_work

    def do_deferred_work(self, whole: bool = True) -> bool:
        """Does the rig's deferred work now, or without `whole` a part of it (a worker's idle
        moment, or before a snapshot); what the session answers is the same either way."""
        return self.rig.do_deferred_work(whole)

    def close(self) -> None:
        """Releases the rig's resources (GL objects, Embree scenes); idempotent. The session
        answers no frame afterwards."""
        self.rig.close()

    def view_target_transforms(self) -> list[RigidTransform]:
        """The targets where the camera sees them: at the program's moment when the rig shows a
        delayed program (MATCH: the broadcast delay behind the game), else as of the latest frame."""
        program = self.rig.program_transforms
        return program if program is not None else self.target_transforms

    def is_stale(self, frame: int) -> bool:
        return self.last_input is not None and frame <= self.last_input[0]

    def frame(self, update: FrameInput) -> FrameState:
        """Runs one frame. The caller has checked that update.frame is newer than the last."""
        last = self.last_state
        last_time_s = None if self.last_input is None else self.last_input[1]
        dt_s = 0.0 if last_time_s is None else max(0.0, update.time_s - last_time_s)
        state = FrameState(frame=update.frame, time_s=update.time_s, dt_s=dt_s)
        if last_time_s is not None and update.time_s < last_time_s:
            state.flags.append("time_went_back")
        self.last_input = (update.frame, update.time_s)
        targets_before = list(self.view_target_transforms())  # a few references: the last cut's "before"
        # INGEST's lap, the frame's first, read off the clock as a StageClock's first lap into a fresh
        # dict is (the same readings, the same value), without making one: in a worker its object and
        # its enum lookups cost a compiled frame about as much as carrying the aim points.
        start_s = self.clock()
        # looked up once a frame, not once a moved object
        target_index, dynamic, set_transform = self.target_index, self.dynamic, self.ray_scene.set_transform
        for object_id, transform in update.states:
            index = target_index.get(object_id)
            if index is None:
                set_transform(object_id, transform)
                dynamic[object_id] = (dynamic[object_id][0], transform)
            else:
                self.target_transforms[index] = transform
        if self.portable:  # one point each, (3,) in and out: the same sums as a row's (map: no Python frame a target)
            state.aim_points_world = list(map(native.carry, map(_AIM_OFFSET, self.targets), self.target_transforms))
        else:
            placed = zip(self.target_transforms, self.targets)
            state.aim_points_world = [_carried(tf, t.aim_offset_local[None, :], False)[0] for tf, t in placed]
        state.stage_ms[_INGEST] = (self.clock() - start_s) * 1e3
        self.rig.run(state, update, self.target_transforms, last)  # the stages after INGEST, timed by the rig
        # The first pose is a cut (a MATCH session answers without a pose while its delay fills).
        state.cut = state.pose is not None and (state.cut or last is None or last.pose is None)
        if state.cut:
            self.shot_id += 1
            if last is not None and last.pose is not None and state.pose is not None:  # a few references, on the frames that cut
                self.last_cut = CutRecord(
                    last.frame,
                    last.pose,
                    targets_before,
                    state.frame,
                    state.pose,
                    list(self.view_target_transforms()),
                    dict(self.dynamic),
                )
        state.shot_id = self.shot_id
        self.last_state = state
        self.frames_answered += 1
        return state


def _carried(transform: RigidTransform, points_local: npt.NDArray[np.float64], portable: bool) -> npt.NDArray[np.float64]:
    """(n, 3) world points of (n, 3) local ones: by camdirector._native when `portable` (module docstring)."""
    if portable:
        carried: npt.NDArray[np.float64] = native.carry(points_local, transform)
        return carried
    return transform.apply(points_local)


def _to_world(mesh: TriMesh, transform: RigidTransform, portable: bool) -> TriMesh:
    return TriMesh(_carried(transform, mesh.vertices, portable), mesh.faces)
