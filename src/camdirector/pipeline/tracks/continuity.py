"""Continuity rules on cuts (Section 5.3): the 30-degree rule and the line of action.

30-degree rule [Arijon 1991]: the angle at the actor between the pre-cut camera and the post-cut
camera must be at least `min_cut_angle_deg`, or the cut is a jump cut.

Line of action ("optical flow" in the paper): the actor's motion must keep its on-screen
direction across the cut. We project the actor's motion direction into each camera's image
(right and up axes of a level camera looking at the actor) and compare: the paper's sub-score is
the cosine of the angle between the two projections; the rule holds when the horizontal screen
components do not have opposite signs, which is the camera staying on its side of the line
through the actor along its motion (a camera on the line itself sees the actor come or go
straight and may cut to either side). Below `min_actor_speed_m_s` the actor's facing stands
in for its motion.

The director treats both rules as hard constraints (a cut that breaks one is not taken) and uses
the two sub-scores to rank the cuts that keep them.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from camdirector.geometry.transforms import UP_WORLD


def cut_angle_deg(
    previous_camera_world: npt.NDArray[np.float64], cameras_world: npt.NDArray[np.float64], actor_world: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """(k,) angle at actor_world (3,) between the previous camera (3,) and each camera (k, 3), deg."""
    a = previous_camera_world - actor_world
    b = np.atleast_2d(cameras_world) - actor_world
    cos = (b @ a) / np.maximum(np.linalg.norm(b, axis=1) * np.linalg.norm(a), 1e-12)
    angle_deg: npt.NDArray[np.float64] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return angle_deg


def action_direction(
    velocity_world: npt.NDArray[np.float64], forward_world: npt.NDArray[np.float64], min_speed_m_s: float
) -> npt.NDArray[np.float64]:
    """Unit horizontal direction of the line of action (3,): the motion, or the facing when slow
    (zero vector when neither has a horizontal part)."""
    v = np.array([velocity_world[0], 0.0, velocity_world[2]])
    if np.linalg.norm(v) < max(min_speed_m_s, 1e-9):
        v = np.array([forward_world[0], 0.0, forward_world[2]])
    norm = np.linalg.norm(v)
    return v / norm if norm > 1e-9 else np.zeros(3)


def screen_motion(
    cameras_world: npt.NDArray[np.float64], actor_world: npt.NDArray[np.float64], direction_world: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """(k, 2) the motion direction (3,) as seen on screen (right, up) from each level camera
    (k, 3) looking at actor_world (3,)."""
    forward = actor_world - np.atleast_2d(cameras_world)
    forward /= np.maximum(np.linalg.norm(forward, axis=1, keepdims=True), 1e-12)
    right = np.cross(forward, UP_WORLD)
    norm = np.linalg.norm(right, axis=1, keepdims=True)
    right = np.where(norm > 1e-9, right / np.maximum(norm, 1e-12), np.array([1.0, 0.0, 0.0]))
    up = np.cross(right, forward)
    motion: npt.NDArray[np.float64] = np.stack([right @ direction_world, up @ direction_world], axis=1)
    return motion


def thirty_degree_score(angle_deg: npt.NDArray[np.float64], min_angle_deg: float) -> npt.NDArray[np.float64]:
    """(k,) in [0, 1]: 1 - cos of the cut angle, relative to that of the minimum angle, capped at 1."""
    denominator = max(1.0 - np.cos(np.radians(min_angle_deg)), 1e-9)
    score: npt.NDArray[np.float64] = np.clip((1.0 - np.cos(np.radians(angle_deg))) / denominator, 0.0, 1.0)
    return score


def line_of_action_score(before: npt.NDArray[np.float64], after: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(k,) in [0, 1]: (1 + cos of the angle between the screen motions (2,) before and (k, 2) after) / 2."""
    nb = np.linalg.norm(before)
    na = np.linalg.norm(after, axis=1)
    cos = (after @ before) / np.maximum(na * nb, 1e-12)
    score: npt.NDArray[np.float64] = np.where((na > 1e-9) & (nb > 1e-9), 0.5 * (1.0 + cos), 1.0)
    return score


def keeps_line_of_action(before: npt.NDArray[np.float64], after: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """(k,) bool: the horizontal screen motion does not change sign (module docstring)."""
    keeps: npt.NDArray[np.bool_] = before[0] * after[:, 0] >= -1e-9
    return keeps
