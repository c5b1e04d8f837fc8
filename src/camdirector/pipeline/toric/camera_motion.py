"""MOTION stage: where on the torus the camera goes this frame (the FRAMING_ONLY rig).

The camera always sits on the current torus, so the composition is exact every frame (with one
target, A is exact and the horizon level; the gaze-room point lands near screen_b). Its place
(theta, phi) has inertia: the previous camera position is projected onto the new torus (the
camera stays where it was as far as the new composition allows), then a critically damped spring
pulls it toward the style's preferred (theta, phi). The spring's acceleration and the resulting
speed are limited in world units through the torus's tangent frame, because equal steps in
(theta, phi) are not equal steps in metres (toric-space-primer.md, "Distortion"; the
occlusion-anticipation paper, section 5, plans motion the same way).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose, Lens, level_look_rotation
from camdirector.geometry.toric import Torus, compose_pose, tangent_frame, theta_max, torus_angles, torus_position
from camdirector.geometry.transforms import UP_WORLD, quat_rotate
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style
from camdirector.pipeline.toric.frame import ToricFrame


@dataclass(frozen=True)
class MotionSettings:
    max_substep_s: float = 1.0 / 60.0  # integration step, s; longer frame gaps are subdivided. (0, 0.1]
    max_substeps: int = 30  # at most this many per frame; the rest of a long gap is dropped. [1, 1000]
    theta_margin_rad: float = 0.02  # keep theta this far inside its open range, rad. (0, 0.5]
    side_hysteresis: float = 0.2  # the upright side changes only when the other is better by this (up-vector dot). [0, 2]
    side_recheck_axis_dot: float = 0.02  # re-choose the side when the A-B axis elevation (dot with up) moves this much. [0, 1]
    # Sides whose up-vector dots are closer than this are a tie, which +1 takes: where the two halves
    # are mirror images (B straight above A) rounding must not choose, or no two libms agree. [0, 0.1]
    side_tie: float = 1e-9


class ToricMotion:
    """Camera place (theta, phi) and its rates; one instance per session."""

    def __init__(self, style: Style, lens: Lens, settings: MotionSettings = MotionSettings()):
        self.settings = settings
        self.lens = lens
        self.style = style
        self.theta: float | None = None  # None until the first torus
        self.phi = 0.0
        self.rate = np.zeros(2)  # (dtheta/dt, dphi/dt), rad/s
        self.position_world: npt.NDArray[np.float64] | None = None
        self.side = 0.0  # +1 or -1: which half of the torus is upright
        self._side_key: float | None = None  # axis elevation (A-B . up) the side was chosen at

    def set_style(self, style: Style) -> None:
        self.style = style
        self._side_key = None

    def _upright_side(self, torus: Torus, theta: float) -> float:
        """+1 or -1: the side (sign of phi) where the composed camera's up is nearest world up.

        One side of the torus sees A and B in the asked left/right order with the camera upright;
        the other side would need the camera rolled over. Uprightness does not change when the
        whole configuration turns about world up, so the choice only depends on the style and on
        the elevation of the A-B axis: it is re-evaluated when that elevation changes.
        """
        key = float(torus.axis_world @ UP_WORLD)
        if self._side_key is not None and abs(key - self._side_key) < self.settings.side_recheck_axis_dot:
            return self.side
        self._side_key = key
        phi = math.radians(self.style.preferred_phi_deg)
        ups = []
        for sign in (1.0, -1.0):
            pose = compose_pose(torus, theta, sign * phi, self.style.screen_a, self.style.screen_b, self.lens)
            ups.append(float(quat_rotate(pose.rotation_xyzw, UP_WORLD) @ UP_WORLD))
        best = 1.0 if ups[0] >= ups[1] - self.settings.side_tie else -1.0
        if self.side == 0.0 or ups[0 if best > 0 else 1] > ups[0 if self.side > 0 else 1] + self.settings.side_hysteresis:
            self.side = best
        return self.side

    def preferred_place(self, torus: Torus) -> tuple[float, float, float, float]:
        """(theta, phi, theta_lo, theta_hi) radians: the style's preferred place on the upright side."""
        lo = self.settings.theta_margin_rad
        hi = theta_max(torus.alpha) - self.settings.theta_margin_rad
        goal_theta = lo + self.style.preferred_theta_ratio * (hi - lo)
        return goal_theta, self._upright_side(torus, goal_theta) * math.radians(self.style.preferred_phi_deg), lo, hi

    def run(self, state: FrameState, toric: ToricFrame) -> None:
        """The camera's place on the frame's torus (`toric`, filled by FRAMING) and its pose."""
        torus = toric.torus
        if torus is None:  # degenerate framing: hold the last pose
            state.flags.append("pose_held")
            toric.theta, toric.phi = self.theta or 0.0, self.phi
            return
        goal_theta, goal_phi, lo, hi = self.preferred_place(torus)
        if self.theta is None or self.position_world is None:
            self.theta, self.phi = goal_theta, goal_phi
        else:
            self.theta, self.phi = torus_angles(torus, self.position_world)
            self._integrate(torus, goal_theta, goal_phi, lo, hi, state.dt_s)
        toric.theta, toric.phi = self.theta, self.phi
        state.pose = pose_on_torus(torus, self.theta, self.phi, self.style, self.lens, toric.b_is_gaze_point)
        self.position_world = state.pose.position_world

    def _integrate(self, torus: Torus, goal_theta: float, goal_phi: float, lo: float, hi: float, dt_s: float) -> None:
        if dt_s <= 0.0:
            return
        steps = min(self.settings.max_substeps, max(1, math.ceil(dt_s / self.settings.max_substep_s)))
        h = min(dt_s / steps, self.settings.max_substep_s)
        omega = 1.0 / self.style.response_time_s
        assert self.theta is not None  # run() places the camera before it integrates
        for _ in range(steps):
            t_theta, t_phi, _ = tangent_frame(torus, self.theta, self.phi)
            jacobian = np.stack([t_theta, t_phi], axis=1)  # (3, 2): world metres per radian
            error = np.array([goal_theta - self.theta, math.remainder(goal_phi - self.phi, math.tau)])
            accel = omega * omega * error - 2.0 * omega * self.rate
            accel *= _limit_scale(float(np.linalg.norm(jacobian @ accel)), self.style.max_accel_m_s2)
            self.rate = self.rate + h * accel
            self.rate *= _limit_scale(float(np.linalg.norm(jacobian @ self.rate)), self.style.max_speed_m_s)
            self.theta += h * self.rate[0]
            self.phi = math.remainder(self.phi + h * self.rate[1], math.tau)
            if not lo <= self.theta <= hi:
                self.theta = min(max(self.theta, lo), hi)
                self.rate[0] = 0.0


def _limit_scale(norm: float, limit: float) -> float:
    return limit / norm if norm > limit else 1.0


def pose_on_torus(torus: Torus, theta: float, phi: float, style: Style, lens: Lens, level: bool) -> CameraPose:
    """The camera at (theta, phi) radians composing A and B. With `level` (B is only a gaze-room
    point), A is placed exactly and the horizon kept level, where the full composition would roll
    the camera whenever it is not square to A-B."""
    if not level:
        return compose_pose(torus, theta, phi, style.screen_a, style.screen_b, lens)
    position = torus_position(torus, theta, phi)
    return CameraPose(position, level_look_rotation(position, torus.a_world, style.screen_a, lens), lens.vertical_fov_deg)
