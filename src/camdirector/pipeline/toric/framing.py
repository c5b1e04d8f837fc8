"""FRAMING stage: the two framed points A and B, and the torus of cameras that frames them.

Two targets: A and B are their aim points. One target: B is the gaze-room point, placed
`gaze_room_m` ahead of A along its smoothed horizontal heading (toric-space-primer.md, "One
target"), so the composition leaves space in front of the character. The heading follows the
target's horizontal velocity with a time constant; below a walking-pace threshold it keeps its
last value; before any motion it is the target's facing (its local +Z, the glTF forward axis).

`Framing.error` measures, once the frame's pose is final (the rig calls it in VISIBILITY), how far
the framed points land from the style's screen points: the frame's `framing_error`. The points and
the torus are the rig's part of the frame's state (`ToricFrame`, frame.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.toric import DegenerateTorus, composition_angle, make_torus
from camdirector.geometry.transforms import UP_WORLD, quat_rotate
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style
from camdirector.pipeline.toric.frame import ToricFrame


@dataclass(frozen=True)
class FramingSettings:
    heading_time_constant_s: float = 0.6  # smoothing of the one-target heading, s. [0.01, 10]
    heading_min_speed_m_s: float = 0.2  # slower than this the heading holds, m/s. [0, 10]
    min_ab_distance_m: float = 1e-3  # two targets closer than this frame as one, m. (0, 1]


class Framing:
    """Keeps the one-target heading between frames and fills A, B and the torus of a frame."""

    def __init__(
        self,
        lens: Lens,
        style: Style,
        initial_rotation_xyzw: npt.NDArray[np.float64],
        settings: FramingSettings = FramingSettings(),
    ):
        self.settings = settings
        self.lens = lens
        self.set_style(style)
        forward = quat_rotate(initial_rotation_xyzw, np.array([0.0, 0.0, 1.0]))
        self.heading_rad = math.atan2(forward[0], forward[2]) if math.hypot(forward[0], forward[2]) > 1e-6 else 0.0
        self._last_aim: npt.NDArray[np.float64] | None = None

    def set_style(self, style: Style) -> None:
        self.style = style
        self.alpha = composition_angle(style.screen_a, style.screen_b, self.lens)
        self._screen_a = np.array([style.screen_a])  # (1, 2): `error`'s goals, made once
        self._screen_ab = np.array([style.screen_a, style.screen_b])  # (2, 2)

    def _gaze_point(self, aim_world: npt.NDArray[np.float64], dt_s: float) -> npt.NDArray[np.float64]:
        if self._last_aim is not None and dt_s > 0.0:
            vx, vz = (aim_world[0] - self._last_aim[0]) / dt_s, (aim_world[2] - self._last_aim[2]) / dt_s
            if math.hypot(vx, vz) > self.settings.heading_min_speed_m_s:
                error = math.remainder(math.atan2(vx, vz) - self.heading_rad, math.tau)
                self.heading_rad += error * (1.0 - math.exp(-dt_s / self.settings.heading_time_constant_s))
        self._last_aim = aim_world
        g = self.style.gaze_room_m
        gaze_point: npt.NDArray[np.float64] = aim_world + np.array(
            [g * math.sin(self.heading_rad), 0.0, g * math.cos(self.heading_rad)]
        )
        return gaze_point

    def run(self, state: FrameState, toric: ToricFrame) -> None:
        """A, B and the torus of the frame's aim points into `toric` (the frame's part); what
        degrades goes to state.flags."""
        a = state.aim_points_world[0]
        if len(state.aim_points_world) == 2:
            b = state.aim_points_world[1]
            if np.linalg.norm(b - a) < self.settings.min_ab_distance_m:
                state.flags.append("targets_coincide")
                b = self._gaze_point(a, state.dt_s)
                toric.b_is_gaze_point = True
        else:
            b = self._gaze_point(a, state.dt_s)
            toric.b_is_gaze_point = True
        toric.a_world, toric.b_world = a, b
        try:
            toric.torus = make_torus(a, b, self.alpha, UP_WORLD)
        except DegenerateTorus:
            state.flags.append("degenerate_torus")
            toric.torus = None

    def error(self, pose: CameraPose, toric: ToricFrame) -> float:
        """How far the framed points of `toric` land from the style's screen points in `pose` (the
        frame's final pose), in normalised screen units (the frame is [-1, 1] on both axes; the TRACKS
        rig's framing error is in the same units): the larger of the points' largest-axis errors.
        A always counts, B only when it is the second target: the gaze-room point is no subject,
        and the level camera of one target (camera_motion.pose_on_torus) puts only A exactly.
        NaN when a point is behind the camera."""
        assert toric.a_world is not None and toric.b_world is not None  # FRAMING placed them
        if toric.b_is_gaze_point:
            points, goals = toric.a_world, self._screen_a
        else:
            points, goals = np.array((toric.a_world, toric.b_world)), self._screen_ab
        return float(np.abs(project_to_screen(pose, self.lens, points) - goals).max())
