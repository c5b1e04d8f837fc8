"""The TRACKS rig of a session: the runtime graph director (topology-aware camera tracks, Section
5) following target 0 on a precomputed level.

Per frame (`TracksRig.run`, the MOTION and VISIBILITY stages of pipeline/stages.py for this
rig): the actor is target 0, its feet at its transform's position (the local origin the primitives
stand on), its facing the transform's local +Z (the convention of docs/protocol.md), which the
director uses for the line of action only while the actor stands still (it takes the velocity from
successive positions otherwise). Direct visibility rays go through the session's RayScene: the
level's geometry plus the session's own static and dynamic objects at their current transforms. The
pose is the director's camera position looking at its look-at point with no roll (+Y up;
`geometry.camera.level_look_rotation` at the screen centre) and the lens's field of view; `cut` and
`visibility` are the director's (its shot count is the session's `shot_id`); the cut reason is
flagged `tracks_cut_<reason>` and the director's three stage timings go to `stage_ms` as
`cut_check`, `target_update` and `camera_update` (`TracksStage`; a step that finds no shot is all
`target_update`). The director's settings are its defaults (settings.py) with the
session lens's vertical field of view, so shot sizes mean the same on the client's screen. Until a
first shot is found (the actor is away from every track) the camera waits behind and above the
actor, flagged `tracks_no_track_near_actor`, with visibility 0.

`TracksRig` implements `CameraRig` (pipeline/camera_rig.py) and none of what only some rigs do, so
it answers all of that as `RigBase` does: no occlusion maps (it cuts away from occlusion), no
deferred work, no player inputs, no delayed program. It has no part of its own in a frame's
state: all it answers is the core (pipeline/state.py).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose, Lens, level_look_rotation
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform, quat_rotate
from camdirector.infra.stage_clock import StageClock
from camdirector.pipeline.camera_rig import RigBase
from camdirector.pipeline.inputs import FrameInput, LoadedLevel
from camdirector.pipeline.stages import TracksStage
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style
from camdirector.pipeline.tracks.director import DirectorStyle, GraphDirector
from camdirector.pipeline.tracks.settings import DirectorSettings
from camdirector.pipeline.tracks.shot_sizes import framing_error

_LOCAL_FORWARD = np.array([0.0, 0.0, 1.0])
_WAIT_OFFSET_M = np.array([0.0, 2.0, 0.0])  # the waiting camera: this far up, and 6 m behind the actor


def director_style(style: Style) -> DirectorStyle:
    return DirectorStyle(shot_size=style.shot_size, movement=style.movement)


class TracksRig(RigBase):
    """The graph director of one session; implements `CameraRig` (module docstring)."""

    def __init__(
        self,
        level: LoadedLevel,
        lens: Lens,
        style: Style,
        ray_scene: RayScene,
        rng: np.random.Generator,
        clock: Callable[[], float] = time.perf_counter,
    ):
        self.level = level
        self.lens = lens
        self.ray_scene = ray_scene
        self.clock = clock
        self.settings = DirectorSettings(vertical_fov_deg=lens.vertical_fov_deg)
        self.director = GraphDirector(level.artifact, self.settings, rng, director_style(style), clock)

    def set_style(self, style: Style) -> None:
        """Shot size and movement from the next frame on; the current shot goes on (a changed shot
        size cuts once its framing has been off for the cutting strategy's 200 ms)."""
        self.director.set_style(director_style(style))

    def close(self) -> None:
        """Nothing to release: the level is the worker's (its LevelCache), the ray scene the session's."""

    def run(
        self, state: FrameState, update: FrameInput, target_transforms: list[RigidTransform], last: FrameState | None
    ) -> None:
        """MOTION and VISIBILITY: fills state.pose, cut, visibility, flags, scores and stage_ms."""
        actor, last_pose = target_transforms[0], None if last is None else last.pose
        forward = quat_rotate(actor.rotation_xyzw, _LOCAL_FORWARD)
        stages = StageClock(clock=self.clock, timings_ms=state.stage_ms)
        shot = self.director.step(state.time_s, actor.position_world, forward, self.ray_scene)
        if shot is None:
            stages.done(TracksStage.TARGET_UPDATE)
            state.pose = self._waiting_pose(actor.position_world, forward)
            state.visibility = 0.0
            state.flags.append("tracks_no_track_near_actor")
            return
        state.cut = shot.cut
        state.visibility = shot.visible_fraction
        state.scores = shot.scores
        if shot.cut_reason is not None:
            state.flags.append(f"tracks_cut_{shot.cut_reason.value}")
        state.stage_ms.update(shot.timings_ms)
        if np.linalg.norm(shot.look_at_world - shot.position_world) < 1e-6:  # on the look-at point: no direction
            held = last_pose if last_pose is not None else self._waiting_pose(actor.position_world, forward)
            rotation = held.rotation_xyzw
            state.flags.append("tracks_camera_on_actor")
        else:
            rotation = level_look_rotation(shot.position_world, shot.look_at_world, (0.0, 0.0), self.lens)
        state.pose = CameraPose(shot.position_world, rotation, self.lens.vertical_fov_deg)
        state.framing_error = framing_error(
            state.pose,
            self.lens,
            actor.position_world,
            self.level.artifact.agent_height_m,
            self.director.style.shot_size,
            self.director.screen_fraction(),
        )

    def _waiting_pose(self, actor_world: npt.NDArray[np.float64], forward: npt.NDArray[np.float64]) -> CameraPose:
        flat = np.array([forward[0], 0.0, forward[2]])
        norm = float(np.linalg.norm(flat))
        flat = flat / norm if norm > 1e-9 else _LOCAL_FORWARD
        look_at = actor_world + np.array([0.0, self.settings.look_at_fraction * self.level.artifact.agent_height_m, 0.0])
        position = actor_world - 6.0 * flat + _WAIT_OFFSET_M
        return CameraPose(position, level_look_rotation(position, look_at, (0.0, 0.0), self.lens), self.lens.vertical_fov_deg)
