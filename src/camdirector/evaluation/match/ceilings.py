"""Ceilings for the kill coverage of a match (issue 29, item 4): what cameras placed for each kill
could show, ignoring and then obeying the film rules' shot length.

- Reference cameras, placed for each kill at its moment and for it alone (a broadcast that knew
  every kill and could cut anywhere, with shots of any length):
  - a chase camera `CHASE_BACK_M` behind the attacker on the victim-to-attacker line and
    `CHASE_UP_M` above its aim point, looking at the middle of the two aim points;
  - a side camera on either side of the line of action, square to it, as far from its middle as
    the lens needs to hold both aim points with `SIDE_MARGIN_M` to spare (at least `SIDE_MIN_M`),
    `SIDE_UP_M` above the middle, looking at the middle.
  A kill is *reachable* when one of the three shows both players (measure.py's shown rule).
- The greedy bound for 2-s shots: the most reachable kills a program can cover when every shot
  lasts at least `min_shot_s`, each covered kill needing a shot of its own that starts at or
  before the kill and ends after it (a cut between two kills' moments). Taking the kills in time
  order, each at the earliest start its predecessor allows, is optimal for this schedule (the
  exchange argument of interval scheduling): the count is an upper bound for any director that
  cuts to a new view for each kill, and the bound the issue's "0.85 of the greedy 2-s bound" means.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from camdirector.evaluation.match.match_file import MatchRecording
from camdirector.evaluation.match.measure import SHOWN_FRACTION, BodySampler, shown_fractions
from camdirector.geometry.camera import CameraPose, Lens, level_look_rotation
from camdirector.geometry.raycast import RayScene

CHASE_BACK_M = 2.0  # the chase camera this far behind the attacker, m
CHASE_UP_M = 0.6  # and this far above its aim point, m
SIDE_MARGIN_M = 1.0  # the side camera frames the aim points with this much room each side, m
SIDE_MIN_M = 3.0  # and stands at least this far from their middle, m
SIDE_UP_M = 1.0  # this far above the middle, m


@dataclass(frozen=True)
class Ceilings:
    """kill_times_s (k,) s of the kills with an attacker (suicides left out); reachable (k,) bool;
    greedy (k,) bool: the kills the greedy 2-s schedule covers."""

    kill_times_s: np.ndarray
    reachable: np.ndarray
    greedy: np.ndarray

    def as_json(self) -> dict:
        k = len(self.kill_times_s)
        return {
            "kills": k,
            "reference_kill_coverage": round(float(self.reachable.mean()), 3) if k else None,
            "greedy_2s_kill_coverage": round(float(self.greedy.mean()), 3) if k else None,
        }


def reference_poses(attacker_aim: np.ndarray, victim_aim: np.ndarray, lens: Lens) -> list[CameraPose]:
    """The chase camera and the two side cameras (module docstring) of aim points (3,) m."""
    middle = (attacker_aim + victim_aim) / 2.0
    line = victim_aim - attacker_aim
    flat = np.array([line[0], 0.0, line[2]])
    length = float(np.linalg.norm(flat))
    along = flat / length if length > 1e-6 else np.array([0.0, 0.0, 1.0])
    across = np.array([-along[2], 0.0, along[0]])
    places = [attacker_aim - CHASE_BACK_M * along + [0.0, CHASE_UP_M, 0.0]]
    half_width_m = float(np.linalg.norm(line)) / 2.0 + SIDE_MARGIN_M
    distance_m = max(SIDE_MIN_M, half_width_m / lens.tan_half_fov_x)
    places += [middle + sign * distance_m * across + [0.0, SIDE_UP_M, 0.0] for sign in (1.0, -1.0)]
    return [CameraPose(p, level_look_rotation(p, middle, (0.0, 0.0), lens), lens.vertical_fov_deg) for p in places]


def greedy_schedule(kill_times_s: np.ndarray, reachable: np.ndarray, min_shot_s: float, start_s: float) -> np.ndarray:
    """(k,) bool: the kills (times in increasing order) that the greedy schedule, whose first shot
    may start at the program's start start_s, covers (module docstring)."""
    covered = np.zeros(len(kill_times_s), dtype=bool)
    last_start_s, last_kill_s = start_s - min_shot_s, -math.inf
    for i, t in enumerate(kill_times_s):
        if not reachable[i]:
            continue
        start_s = max(last_start_s + min_shot_s, math.nextafter(last_kill_s, math.inf))
        if start_s <= t:
            covered[i] = True
            last_start_s, last_kill_s = start_s, t
    return covered


def match_ceilings(match: MatchRecording, bodies: BodySampler, lens: Lens, level: RayScene, min_shot_s: float = 2.0) -> Ceilings:
    """The reference cameras' reach and the greedy bound of the match's kills (module docstring)."""
    column = match.player_index()
    times, reachable = [], []
    for event in match.events:
        if event.kind != "kill" or event.actor_id == event.other_actor_id:
            continue
        row = min(int(np.searchsorted(match.time_s, event.time_s)), len(match.time_s) - 1)
        pair = [column[event.actor_id], column[event.other_actor_id]]
        aims = bodies.aims_world(row, pair)
        points = bodies.points_world(row)[pair]
        reachable.append(
            any(
                shown_fractions(pose, lens, points, level).min() >= SHOWN_FRACTION
                for pose in reference_poses(aims[0], aims[1], lens)
            )
        )
        times.append(float(match.time_s[row]))
    times_s, reach = np.array(times), np.array(reachable, dtype=bool)
    return Ceilings(times_s, reach, greedy_schedule(times_s, reach, min_shot_s, float(match.time_s[0])))
