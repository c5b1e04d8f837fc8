"""The situations of a moment, by interest: what our director chooses among between its planned
beats (planned.py), and what the rig offers a human director as candidates and falls back to
when a held player dies (rig.py, takes.py), whichever director runs.

Situations (interest.py): a DUEL per fighting pair, a FOLLOW per fighting player, a GROUP per
cluster of fighters, a FOLLOW of every other living player, and an OVERVIEW, below them all; with
a delay, fights are anticipated by reading the next 2 s of the buffer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.interest import fight_matrix, recent_event_boost
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.settings import MatchSettings

ANTICIPATION_STEPS_S = (0.5, 1.0, 1.5, 2.0)  # buffered future read for fights, s after the moment
ANTICIPATION_DISCOUNT = 0.9  # a future fight counts this much of a present one
FOLLOW_SHARE = 0.5  # one fighter alone is worth this share of its best fight
GROUP_SHARE = 0.6  # a group: this share of its best fight, plus GROUP_EXTRA per extra player
GROUP_EXTRA = 0.1
ROAM_FLOOR = 0.01  # a player in no fight: the overview's score plus this,
ROAM_BONUS = 0.1  # plus this times its nearness to an opponent


@dataclass
class Option:
    """A situation the director could show: kind, player indices, interest, why."""

    kind: ShotKind
    subjects: tuple[int, ...]
    score: float
    reason: str


class Situations:
    """The situations of the rig's players (target order), their teams (n,), judged with the
    session's settings and ray scene; the last answer kept (a plan asks twice: the decision and
    the rig's candidates)."""

    def __init__(self, players: list[str], teams: np.ndarray, settings: MatchSettings, ray_scene: RayScene):
        self.players, self.teams, self.settings, self.ray_scene = players, teams, settings, ray_scene
        self.index = {p: i for i, p in enumerate(players)}
        # the last options() answer, keyed by its moment's time and the buffer's horizon, s
        self._options: tuple[tuple[float, float], list[Option]] | None = None

    def options(self, moment: Moment, buffer: MomentBuffer) -> list[Option]:
        """Every situation worth showing at the moment, best first (module docstring)."""
        key = (moment.time_s, buffer.horizon_s)
        if self._options is None or self._options[0] != key:
            self._options = key, self._options_at(moment, buffer)
        return self._options[1]

    def _options_at(self, moment: Moment, buffer: MomentBuffer) -> list[Option]:
        s = self.settings
        now = moment.time_s
        ray_scene = self.ray_scene
        fights = fight_matrix(moment, self.teams, s, ray_scene)
        for step_s in ANTICIPATION_STEPS_S:
            if now + step_s > buffer.horizon_s:
                break
            ahead = (
                fight_matrix(buffer.at(now + step_s), self.teams, s, ray_scene) * moment.alive[:, None] * moment.alive[None, :]
            )
            fights = np.maximum(fights, ANTICIPATION_DISCOUNT * ahead)
        interest = (
            fights
            + recent_event_boost(buffer.events_between(now - s.recent_event_s, now), self.index, now, len(self.players), s)
            * moment.alive[:, None]
            * moment.alive[None, :]
        )
        options: list[Option] = []
        ii, jj = np.nonzero(np.triu(interest) > 0.0)
        for i, j in zip(ii.tolist(), jj.tolist()):
            options.append(Option(ShotKind.DUEL, (i, j), float(interest[i, j]), f"fight: {self.players[i]} vs {self.players[j]}"))
        best_fight = interest.max(axis=1)
        for i in np.flatnonzero(best_fight > 0.0).tolist():
            options.append(Option(ShotKind.FOLLOW, (i,), FOLLOW_SHARE * float(best_fight[i]), f"fighter: {self.players[i]}"))
        options += self._roaming(moment, best_fight)
        fighters = np.flatnonzero(best_fight > 0.0)
        if len(fighters) >= 3:
            feet = moment.feet_world[fighters]
            for k, i in enumerate(fighters.tolist()):
                near = fighters[np.linalg.norm(feet - feet[k], axis=1) <= s.group_radius_m]
                if len(near) >= 3 and near.min() == i:  # one group per leftmost member
                    members = tuple(int(m) for m in near[: s.max_group])
                    sub = interest[np.ix_(members, members)]
                    options.append(
                        Option(
                            ShotKind.GROUP,
                            members,
                            GROUP_SHARE * float(sub.max()) + GROUP_EXTRA * (len(members) - 2),
                            "group: " + ", ".join(self.players[m] for m in members),
                        )
                    )
        options.append(Option(ShotKind.OVERVIEW, (), s.overview_min_interest, "overview: no fight worth a closer shot"))
        options.sort(key=lambda o: -o.score)
        return options

    def _roaming(self, moment: Moment, best_fight: np.ndarray) -> list[Option]:
        """FOLLOW options of the living players in no fight, nearest an opponent first: on a real
        map most players most of the time see nobody (corridors, other floors), and one of them
        running toward the enemy shows more than an OVERVIEW, which in a closed level shows walls
        (on the real duel's first 3 minutes, overviews of nobody were 37% of the program, its
        players shown 0.30 of them). Each scores just above the overview (ROAM_FLOOR), more the
        nearer its nearest living opponent (ROAM_BONUS times engage_range / (engage_range + distance))."""
        s = self.settings
        alive = moment.alive
        distance = np.linalg.norm(moment.feet_world[None, :, :] - moment.feet_world[:, None, :], axis=2)
        opponents = (self.teams[:, None] != self.teams[None, :]) & alive[:, None] & alive[None, :]
        nearest = np.where(opponents, distance, np.inf).min(axis=1)
        proximity = s.engage_range_m / (s.engage_range_m + nearest)
        return [
            Option(
                ShotKind.FOLLOW,
                (i,),
                s.overview_min_interest + ROAM_FLOOR + ROAM_BONUS * float(proximity[i]),
                f"on the move: {self.players[i]}, an opponent {nearest[i]:.0f} m away",
            )
            for i in np.flatnonzero(alive & (best_fight <= 0.0)).tolist()
        ]
