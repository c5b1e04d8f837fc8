"""CAMERA and VISIBILITY of the MATCH rig: every frame, the program shot's camera stepped to the
program moment, a Toric camera whose first subject walls hide pulled in front of the wall
(shots.py `pulled_in`, flagged `pulled_in_front_of_wall`), any director's pose that would lie
outside the level or inside solid moved inside toward the player the shot keeps in view
(in_level.py, flagged `moved_inside_level`), one that would move through a wall kept on that
player's side of it (flagged `kept_this_side_of_wall`) or, for a short move, held where it was
(`held_before_wall`), its lens widened where a player would stand taller than the framing band
(lens_width.py, flagged `lens_widened`; every director's shots, the baselines' too), and the share
of the framed subjects' sample points seen from the pose
(visibility.py). In the frame (rig.py) or ahead of it, on a copy of the camera (camera_ahead.py):
the same computation either way.
"""

from __future__ import annotations

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import quat_to_matrix
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.lens_width import widened_fov_deg
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.match.program_shot import Shot, ShotCamera
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import ToricCamera, framed_seen
from camdirector.pipeline.match.visibility import SubjectVisibility


class ProgramCamera:
    """The CAMERA and VISIBILITY stages of one session (module docstring)."""

    def __init__(
        self, settings: MatchSettings, visibility: SubjectVisibility, ray_scene: RayScene, lens: Lens, in_level: InLevel
    ):
        self.settings, self.subject_visibility, self.ray_scene, self.lens = settings, visibility, ray_scene, lens
        self.in_level = in_level

    def step(
        self, moment: Moment, dt_s: float, camera: ShotCamera, shot: Shot, response_time_s: float, last_pose: CameraPose | None
    ) -> tuple[CameraPose, list[str]] | None:
        """CAMERA of `shot` by `camera` (its own, or a copy ahead) stepped dt_s to the moment: the
        pose and its flags; the last pose shown held when the camera has none. None when it has
        no pose and none was shown before (a degenerate first shot)."""
        camera.advance(moment, dt_s, response_time_s)
        flags: list[str] = []
        pose = camera.pose(moment)
        if pose is not None and isinstance(camera, ToricCamera):
            pose, pulled = self._pulled_in(moment, pose, dt_s, camera, shot)
            if pulled:
                flags.append("pulled_in_front_of_wall")
        if pose is not None:
            anchor = self._anchor(moment, camera, shot)
            pose, moved = self.in_level.contained(pose, anchor)
            if moved:
                flags.append("moved_inside_level")
            if dt_s > 0.0 and last_pose is not None:  # a move, not a cut's first frame
                pose, kept = self.in_level.kept_this_side(last_pose.position_world, pose, anchor)
                if kept:
                    flags.append("kept_this_side_of_wall")
                else:
                    pose, held = self.in_level.held(
                        last_pose.position_world, pose, anchor, self.lens, self.settings.wall_hold_max_m
                    )
                    if held:
                        flags.append("held_before_wall")
        if pose is None:
            if last_pose is None:
                return None
            pose = last_pose
            flags.append("pose_held")
            return pose, flags
        last_fov_deg = last_pose.vertical_fov_deg if dt_s > 0.0 and last_pose is not None else None  # None: a cut
        fov_deg = widened_fov_deg(pose, moment, self.subject_visibility, self.lens, self.settings, last_fov_deg, dt_s)
        if fov_deg != pose.vertical_fov_deg:
            pose = CameraPose(pose.position_world, pose.rotation_xyzw, fov_deg)
            if fov_deg > self.lens.vertical_fov_deg:
                flags.append("lens_widened")
        return pose, flags

    @staticmethod
    def _anchor(moment: Moment, camera: ShotCamera, shot: Shot) -> np.ndarray | None:
        """(3,) m: the aim point of the player the shot keeps in view (a Toric camera's anchor,
        else its first framed subject); None for a shot of nobody."""
        framed = shot.framed(moment.time_s)
        anchor = camera.anchor_index if isinstance(camera, ToricCamera) else framed[0] if framed else None
        return None if anchor is None else np.asarray(moment.aims_world[anchor], dtype=np.float64)

    def visibility(self, moment: Moment, pose: CameraPose, shot: Shot) -> float:
        """VISIBILITY: the mean share of the shot's framed subjects seen from the pose (1 for none)."""
        subjects = shot.framed(moment.time_s)
        return float(self.subject_visibility.visible_share(pose.position_world, moment, subjects).mean()) if subjects else 1.0

    def _pulled_in(
        self, moment: Moment, pose: CameraPose, dt_s: float, camera: ToricCamera, shot: Shot
    ) -> tuple[CameraPose, bool]:
        """The Toric shot's pose pulled in front of a wall (shots.py `pulled_in`) when walls hide
        most of its first subject, kept only if it frames the shot's subjects better (their mean
        seen share, framed_seen): close to A, a pair far apart may no longer fit. On 90 s of the
        4on4 on dm2 this kept program visibility 0.58 and kill coverage 0.60 (0.38 and 0.53 with no
        pull; 0.52 and 0.63 judging by the worst-seen subject; 0.56 and 0.57 pulling always)."""
        s, subjects = self.settings, shot.framed(moment.time_s)
        hidden = self.subject_visibility.visible_share(pose.position_world, moment, (camera.anchor_index,))[0, 0] < s.pull_below
        reach_before = camera.reach_m
        pulled, moved = camera.pulled_in(moment, pose, bool(hidden), self.ray_scene, dt_s, s.pull_margin_m, s.pull_regrow_m_s)
        if not moved or not subjects:
            return pulled, moved
        both = [pose, pulled]
        seen = framed_seen(
            self.subject_visibility,
            moment,
            subjects,
            np.array([p.position_world for p in both]),
            quat_to_matrix(np.array([p.rotation_xyzw for p in both])),
            self.lens,
        ).mean(axis=1)
        if seen[1] > seen[0] or (reach_before is not None and not hidden):  # going back out: at its pace
            return pulled, True
        camera.reach_m = None
        return pose, False
