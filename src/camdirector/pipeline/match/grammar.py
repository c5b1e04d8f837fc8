"""Film grammar at cuts: the 30-degree rule (no jump cut) and the line of action between duelists.

- 30-degree rule: a cut between two shots that share subjects must turn the view of the shared
  subjects (the angle at their centroid between the two camera centres) by at least
  `jump_cut_deg`; a cut that does not, between two views of the same subjects, is a jump cut.
- Line of action: the first time a pair duels, the director chooses which of the two is on the
  left of the screen (the side of the line between them the camera is on); every later DUEL of
  that pair keeps it, so the duelists never swap sides across cuts.
"""

from __future__ import annotations

import math

import numpy as np


def view_turn_deg(camera_a_world: np.ndarray, camera_b_world: np.ndarray, point_world: np.ndarray) -> np.ndarray:
    """Angle, deg, at point (3,) between the directions to camera_a (3,) and each of camera_b (m, 3) or (3,)."""
    u = camera_a_world - point_world
    v = np.atleast_2d(camera_b_world) - point_world
    cos = (v @ u) / np.maximum(np.linalg.norm(v, axis=1) * np.linalg.norm(u), 1e-9)
    angle_deg: np.ndarray = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return angle_deg


class Grammar:
    def __init__(self, jump_cut_deg: float):
        self.jump_cut_deg = jump_cut_deg
        self._left_of: dict[frozenset[str], str] = {}

    def duel_left(self, first: str, second: str) -> str | None:
        """The player kept on the screen's left for this pair, None if the pair has not duelled."""
        return self._left_of.get(frozenset((first, second)))

    def remember_duel(self, left: str, right: str) -> None:
        self._left_of.setdefault(frozenset((left, right)), left)

    def allows_cut(
        self, previous_camera_world: np.ndarray | None, shared_points_world: np.ndarray, new_cameras_world: np.ndarray
    ) -> np.ndarray:
        """(m,) bool: which of (m, 3) new camera centres respect the 30-degree rule against the
        previous centre (3,) for shared subjects at (s, 3) points (no shared subject: all allowed)."""
        new = np.atleast_2d(new_cameras_world)
        if previous_camera_world is None or len(shared_points_world) == 0:
            return np.ones(len(new), dtype=bool)
        centroid = np.mean(shared_points_world, axis=0)
        return view_turn_deg(previous_camera_world, new, centroid) >= self.jump_cut_deg


def is_jump_cut(
    subjects_a: tuple[str, ...],
    camera_a_world: np.ndarray,
    subjects_b: tuple[str, ...],
    camera_b_world: np.ndarray,
    subject_points_world: np.ndarray,
    jump_cut_deg: float,
) -> bool:
    """Whether a cut from view A to view B of the same subjects, at (s, 3) points, turns less than
    jump_cut_deg (what evaluation counts as a jump cut)."""
    if set(subjects_a) != set(subjects_b) or not subjects_a:
        return False
    turn = view_turn_deg(camera_a_world, camera_b_world, np.mean(subject_points_world, axis=0))[0]
    return bool(turn < jump_cut_deg) and math.isfinite(turn)
