"""AUTOTRACK: the baseline QuakeWorld casters use, ezQuake's mvd_autotrack, rebuilt from its source
(github.com/QW-Group/ezquake-source: src/mvd_autotrack.c, src/mvd_utils.c, src/cl_cam.c,
src/cl_view.c; settings with their cvar names and defaults in `AutotrackSettings`).

- Players are ranked from their scoreboard stats (FrameInput.player_stats; the rig keeps each
  player's latest values at the program moment): every player's value is the mode's expression
  (default "%a * %A + 50 * %W + %p + %f") over its variables (MVD_Var_Vals): %a armor points,
  %A the value of its armor type (green, yellow, red: IT_ARMOR1..3, the first held), %W the value
  of its best weapon (MVD_AutoTrackBW: the first weapon held in tp_weapon_order, then "78654321",
  truncated to an integer as the C function returns int), %p the sum of its powerups' values
  (quad, pentagram, ring), %f frags, %h health, %u its number. The values come from the mode's
  list of 14 (axe sg ssg ng sng gl rl lg ga ya ra ring quad pent); the mode is chosen once by the
  player count (MVD_GetValuesAndEquation with mvd_autotrack 1 and MVD_Init_Info's gametype: 2
  players 1on1, 4 players 2on2, any other count 4on4) or is the custom one (mvd_autotrack 2).
- Re-ranking happens every 0.5 s of program time (MVD_AutoTrack returns until 0.5 s of
  cls.realtime have passed since its last update), and only at a switch moment (MVD_SwitchMoment,
  mvd_autotrack_instant 0): the tracked player has neither a rocket launcher nor a lightning gun
  while someone has one, or neither quad nor pentagram while someone has one, or someone has a
  pentagram with a rocket launcher. The best player (MVD_GetBestPlayer) is then the one of
  strictly highest value, starting from the tracked one: the tracked player keeps a tie, and
  among the others the first in target order wins. A different best player is tracked at once.
  With mvd_autotrack_lockteam 1 (teamplay: some players share a team) only the tracked player's
  team is considered (MVD_LockTeamIgnore). mvd_autotrack 3 (multiview) and 4 (the "simple" rule)
  are not offered; nor is the client's pause while the match is in standby or countdown (the
  wire says neither).
- The camera is what a spectator in track mode sees (cl_cam.c Cam_Track with cl_chasecam 1:
  the tracked player's origin and view angles): the player's first-person view, the eye
  DEFAULT_VIEWHEIGHT (22 units) above its origin, 16 below it for a corpse (cl_view.c
  V_CalcRefdef), looking along the player's facing (the wire carries the body's yaw; the view's
  pitch stays in the match file), through the level camera of look_along.py (as HLTV's views;
  the corpse's 80-degree roll is left out: the MATCH rig keeps the horizon level):
  first_person.py's `FirstPersonCamera`, which our director's first-person shots use too. A cut
  is instant, as the client's `track`. Players' transforms are their feet (the wire's contract):
  the origin is 24 units above them (geometry/quake_frame.py), so the eye stands 46 units
  (1.44 m) above the feet of any game.
- It reads no future: it needs no broadcast delay (with one it runs at the program moment as
  live), plans nothing and offers the rig's usual candidates.

Without stats (a game that sends none), the items are unknown, so no switch moment can come: it
ranks by frags counted from kill events (+1 for killing another player, -1 for a suicide) at every
0.5-s rank instead, switching to a player with strictly more, and flags every planning tick
`autotrack_no_stats`.
"""

from __future__ import annotations

import math
import operator
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.pipeline.inputs import EventKind, PlayerStats
from camdirector.pipeline.match.director_contract import DirectorBase
from camdirector.pipeline.match.first_person import FirstPersonCamera
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import Shot

# QuakeWorld's item bits (ezQuake src/common.h, IT_*)
IT_SHOTGUN, IT_SUPER_SHOTGUN, IT_NAILGUN, IT_SUPER_NAILGUN = 1, 2, 4, 8
IT_GRENADE_LAUNCHER, IT_ROCKET_LAUNCHER, IT_LIGHTNING, IT_AXE = 16, 32, 64, 4096
IT_ARMOR1, IT_ARMOR2, IT_ARMOR3 = 8192, 16384, 32768
IT_INVISIBILITY, IT_INVULNERABILITY, IT_QUAD = 524288, 1048576, 4194304

DEFAULT_EXPRESSION = "%a * %A + 50 * %W + %p + %f"
VALUE_NAMES = ("axe", "sg", "ssg", "ng", "sng", "gl", "rl", "lg", "ga", "ya", "ra", "ring", "quad", "pent")
# tp_weapon_order's digits: the weapon's item bit and its index in a value list
WEAPONS = {
    "1": (IT_AXE, 0),
    "2": (IT_SHOTGUN, 1),
    "3": (IT_SUPER_SHOTGUN, 2),
    "4": (IT_NAILGUN, 3),
    "5": (IT_SUPER_NAILGUN, 4),
    "6": (IT_GRENADE_LAUNCHER, 5),
    "7": (IT_ROCKET_LAUNCHER, 6),
    "8": (IT_LIGHTNING, 7),
}
FALLBACK_WEAPON_ORDER = "78654321"  # MVD_AutoTrackBW tries it after tp_weapon_order
VARIABLES = {
    "a": "armor points",
    "A": "armor type value",
    "W": "best weapon value",
    "p": "powerups value",
    "f": "frags",
    "h": "health",
    "u": "player number",
}  # of MVD_Var_Vals, those the wire carries
NO_STATS_FLAG = "autotrack_no_stats"
EXPRESSION_ERROR_FLAG = "autotrack_expression_error"  # a value divided by zero: that player ranks last


class RankExpression:
    """An mvd_autotrack expression, parsed once: numbers, the %-variables of VARIABLES, + - * /,
    unary minus and parentheses, evaluated in double precision as ezQuake's parser.c does
    (its division is always in doubles). ValueError naming `what` for anything else."""

    _TOKEN = re.compile(r"\s*(?:(\d+\.?\d*|\.\d+)|%([A-Za-z])|([-+*/()]))")

    def __init__(self, text: str, what: str):
        self.text, self.what = text, what
        self._tokens: list[tuple[str, str]] = []
        position, text = 0, text.rstrip()
        while position < len(text):
            match = self._TOKEN.match(text, position)
            if match is None:
                raise ValueError(f"{what}: unexpected {text[position:].lstrip()[:1]!r} in {self.text!r}")
            number, variable, operator = match.groups()
            if variable is not None and variable not in VARIABLES:
                raise ValueError(
                    f"{what}: %{variable} is not a variable the wire carries; use "
                    + ", ".join(f"%{v} ({meaning})" for v, meaning in VARIABLES.items())
                )
            self._tokens.append(
                ("n", number) if number is not None else ("v", variable) if variable is not None else ("o", operator)
            )
            position = match.end()
        self._next = 0
        self._evaluate = self._sum()
        if self._next != len(self._tokens):
            raise ValueError(f"{what}: unexpected {self._tokens[self._next][1]!r} in {self.text!r}")

    def __reduce__(self) -> tuple[type[RankExpression], tuple[str, str]]:
        """Pickled as its text (a session's checkpoint): the parsed closures do not pickle."""
        return RankExpression, (self.text, self.what)

    def __call__(self, values: Mapping[str, float]) -> float:
        """The expression's value with the variables' values (keys of VARIABLES); ZeroDivisionError
        for a division by zero."""
        return self._evaluate(values)

    def _peek(self) -> tuple[str, str] | None:
        return self._tokens[self._next] if self._next < len(self._tokens) else None

    def _sum(self) -> Callable[[Mapping[str, float]], float]:
        return self._chain(self._product, {"+": operator.add, "-": operator.sub})

    def _product(self) -> Callable[[Mapping[str, float]], float]:
        return self._chain(self._unary, {"*": operator.mul, "/": operator.truediv})

    def _chain(
        self, operand: Callable[[], Callable[[Mapping[str, float]], float]], operators: dict[str, Callable[[float, float], float]]
    ) -> Callable[[Mapping[str, float]], float]:
        """operand (op operand)*, left to right, for one precedence level's operators."""
        left = operand()
        while (token := self._peek()) is not None and token[0] == "o" and token[1] in operators:
            self._next += 1
            left = (lambda a, b, f: lambda v: f(a(v), b(v)))(left, operand(), operators[token[1]])
        return left

    def _unary(self) -> Callable[[Mapping[str, float]], float]:
        token = self._peek()
        if token is None:
            raise ValueError(f"{self.what}: {self.text!r} ends too early")
        self._next += 1
        kind, text = token
        if token == ("o", "-"):
            inner = self._unary()
            return lambda v: -inner(v)
        if token == ("o", "("):
            inner = self._sum()
            if self._peek() != ("o", ")"):
                raise ValueError(f"{self.what}: a '(' is not closed in {self.text!r}")
            self._next += 1
            return inner
        if kind == "n":
            number = float(text)
            return lambda v: number
        if kind == "v":
            return lambda v: float(v[text])
        raise ValueError(f"{self.what}: unexpected {text!r} in {self.text!r}")


@dataclass(frozen=True)
class AutotrackSettings:
    """ezQuake's mvd_autotrack cvars (src/mvd_autotrack.c, src/teamplay.c), their defaults but the first."""

    mvd_autotrack: int = 1  # the mode: 1 expression and values by player count, 2 the custom ones
    # (ezQuake's default 0 is off; this director is on). {1, 2}
    mvd_autotrack_instant: bool = False  # re-rank at every update, not only at a switch moment
    mvd_autotrack_lockteam: bool = False  # teamplay: consider only the tracked player's team
    mvd_autotrack_1on1: str = DEFAULT_EXPRESSION  # the ranking expression of 2 players (RankExpression)
    mvd_autotrack_1on1_values: tuple[float, ...] = (1, 2, 3, 2, 3, 5, 8, 8, 1, 2, 3, 0, 0, 0)  # 14, VALUE_NAMES order
    mvd_autotrack_2on2: str = DEFAULT_EXPRESSION  # of 4 players
    mvd_autotrack_2on2_values: tuple[float, ...] = (1, 2, 3, 2, 3, 5, 8, 8, 1, 2, 3, 500, 900, 1000)
    mvd_autotrack_4on4: str = DEFAULT_EXPRESSION  # of any other count
    mvd_autotrack_4on4_values: tuple[float, ...] = (1, 2, 4, 2, 4, 6, 10, 10, 1, 2, 3, 500, 900, 1000)
    mvd_autotrack_custom: str = DEFAULT_EXPRESSION  # with mvd_autotrack 2
    mvd_autotrack_custom_values: tuple[float, ...] = (1, 2, 3, 2, 3, 4, 6, 6, 1, 2, 3, 500, 900, 1000)
    tp_weapon_order: str = "78654321"  # %W: the best weapon is the first held in this order, digits 1-8
    update_interval_s: float = 0.5  # MVD_AutoTrack's hard-coded 0.5 s between updates, s. (0, 10]

    def __post_init__(self) -> None:
        if self.mvd_autotrack not in (1, 2):
            raise ValueError(f"AutotrackSettings: mvd_autotrack must be 1 or 2, got {self.mvd_autotrack}")
        for mode in ("1on1", "2on2", "4on4", "custom"):
            RankExpression(getattr(self, f"mvd_autotrack_{mode}"), f"AutotrackSettings.mvd_autotrack_{mode}")
            values = getattr(self, f"mvd_autotrack_{mode}_values")
            if len(values) != len(VALUE_NAMES) or not all(math.isfinite(v) for v in values):
                raise ValueError(
                    f"AutotrackSettings: mvd_autotrack_{mode}_values must be {len(VALUE_NAMES)} finite "
                    f"numbers ({' '.join(VALUE_NAMES)}), got {values}"
                )
        if not self.tp_weapon_order or set(self.tp_weapon_order) - set(WEAPONS):
            raise ValueError(f"AutotrackSettings: tp_weapon_order must be digits 1-8, got {self.tp_weapon_order!r}")
        if not (math.isfinite(self.update_interval_s) and 0.0 < self.update_interval_s <= 10.0):
            raise ValueError(f"AutotrackSettings: update_interval_s must be in (0, 10], got {self.update_interval_s}")

    def mode(self, players: int) -> tuple[str, RankExpression, tuple[float, ...]]:
        """(name, expression, values) of a match of `players` (MVD_GetValuesAndEquation)."""
        name = "custom" if self.mvd_autotrack == 2 else {2: "1on1", 4: "2on2"}.get(players, "4on4")
        expression = getattr(self, f"mvd_autotrack_{name}")
        return name, RankExpression(expression, f"mvd_autotrack_{name}"), getattr(self, f"mvd_autotrack_{name}_values")


def best_weapon_value(items: int, values: tuple[float, ...], weapon_order: str) -> int:
    """%W (MVD_AutoTrackBW): the value of the first weapon held in weapon_order, then "78654321"; 0 for none."""
    for digit in weapon_order + FALLBACK_WEAPON_ORDER:
        bit, index = WEAPONS[digit]
        if items & bit:
            return int(values[index])
    return 0


def stats_variables(stats: PlayerStats, number: int, values: tuple[float, ...], weapon_order: str) -> dict[str, float]:
    """One player's %-variables (MVD_Var_Vals) from its stats; `number` is %u."""
    items = stats.items
    armor_type = values[8] if items & IT_ARMOR1 else values[9] if items & IT_ARMOR2 else values[10] if items & IT_ARMOR3 else 0.0
    powerups = (
        (values[12] if items & IT_QUAD else 0.0)
        + (values[13] if items & IT_INVULNERABILITY else 0.0)
        + (values[11] if items & IT_INVISIBILITY else 0.0)
    )
    return {
        "a": stats.armor,
        "A": armor_type,
        "W": best_weapon_value(items, values, weapon_order),
        "p": powerups,
        "f": stats.frags,
        "h": stats.health,
        "u": number,
    }


class AutotrackDirector(DirectorBase):
    """ezQuake's mvd_autotrack (module docstring) over the rig's players (target order), their
    teams (n,) and the read-only view of their latest stats by id."""

    def __init__(
        self,
        players: list[str],
        teams: np.ndarray,
        lens: Lens,
        stats: Mapping[str, PlayerStats],
        settings: AutotrackSettings = AutotrackSettings(),
    ):
        self.players, self.teams, self.lens, self.stats, self.settings = players, np.asarray(teams), lens, stats, settings
        self.mode_name, self.expression, self.values_list = settings.mode(len(players))
        self.teamplay = len(set(self.teams.tolist())) < len(players)
        self.tracked: int | None = None
        self.next_rank_s = -math.inf
        self.frags_from_kills = np.zeros(len(players), dtype=np.int64)  # without stats: kills minus suicides
        self._counted_s = -math.inf
        self._index = {p: i for i, p in enumerate(players)}

    def values(self, flags: list[str]) -> np.ndarray:
        """(n,) every player's value of the mode's expression (a player never sent: all zero);
        -inf, flagged, where it divides by zero (ezQuake gives up autotracking then)."""
        out = np.empty(len(self.players))
        for i, player in enumerate(self.players):
            stats = self.stats.get(player) or PlayerStats(player, 0, 0, 0, 0)
            try:
                out[i] = self.expression(stats_variables(stats, i, self.values_list, self.settings.tp_weapon_order))
            except ZeroDivisionError:
                out[i] = -math.inf
                if EXPRESSION_ERROR_FLAG not in flags:
                    flags.append(EXPRESSION_ERROR_FLAG)
        return out

    def _eligible(self, tracked: int | None) -> np.ndarray:
        """(n,) bool: the players MVD_LockTeamIgnore keeps."""
        if tracked is None or not (self.settings.mvd_autotrack_lockteam and self.teamplay):
            return np.ones(len(self.players), dtype=bool)
        same_team: np.ndarray = self.teams == self.teams[tracked]
        return same_team

    def switch_moment(self, tracked: int, eligible: np.ndarray) -> str | None:
        """MVD_SwitchMoment: why to re-rank now, or None."""
        if self.settings.mvd_autotrack_instant:
            return "instant"
        items = np.array([s.items if (s := self.stats.get(p)) is not None else 0 for p in self.players], dtype=np.int64)
        weapon = (items & (IT_ROCKET_LAUNCHER | IT_LIGHTNING)) != 0
        powerup = (items & (IT_QUAD | IT_INVULNERABILITY)) != 0
        pent_rl = ((items & IT_ROCKET_LAUNCHER) != 0) & ((items & IT_INVULNERABILITY) != 0)
        name = self.players[tracked]
        if not weapon[tracked] and (weapon & eligible).any():
            return f"{name} has no rocket launcher or lightning gun, another player has"
        if not powerup[tracked] and (powerup & eligible).any():
            return f"{name} has no quad or pentagram, another player has"
        if (pent_rl & eligible).any():
            return "a player has a pentagram and a rocket launcher"
        return None

    @staticmethod
    def best(values: np.ndarray, start: int, eligible: np.ndarray) -> int:
        """MVD_GetBestPlayer: from `start` (the tracked player), the first of strictly higher value."""
        best, best_value = start, (values[start] if eligible[start] else None)
        for i, value in enumerate(values):
            if eligible[i] and (best_value is None or value > best_value):
                best, best_value = i, value
        return best

    def _count_kills(self, buffer: MomentBuffer, now_s: float) -> None:
        for event in buffer.events_between(self._counted_s, now_s):
            if event.kind != EventKind.KILL or event.other_actor_id not in self._index:
                continue
            if event.actor_id == event.other_actor_id:
                self.frags_from_kills[self._index[event.actor_id]] -= 1
            elif event.actor_id in self._index:
                self.frags_from_kills[self._index[event.actor_id]] += 1
        self._counted_s = max(self._counted_s, now_s)

    def decide(
        self, moment: Moment, buffer: MomentBuffer, current: Shot | None, current_pose: CameraPose | None, flags: list[str]
    ) -> Shot | None:
        """The rig's plan tick: a new first-person shot when the tracked player changes (or there
        is no current shot of ours), else None."""
        now = moment.time_s
        self._count_kills(buffer, now)
        has_stats = bool(self.stats)
        if not has_stats:
            flags.append(NO_STATS_FLAG)
        must_track = current is None or self.tracked is None
        if not must_track and now < self.next_rank_s:
            return None
        self.next_rank_s = now + self.settings.update_interval_s
        eligible = self._eligible(self.tracked)
        if has_stats:
            why = "start" if must_track or self.tracked is None else self.switch_moment(self.tracked, eligible)
            if why is None:
                return None
            values = self.values(flags)
        else:
            why, values = "no stats", self.frags_from_kills.astype(np.float64)
        best = self.best(values, 0 if self.tracked is None else self.tracked, eligible)
        if best == self.tracked and not must_track:
            return None
        self.tracked = best
        name = self.players[best]
        if has_stats:
            reason = f"autotrack ({self.mode_name}, {why}): {name} ranks best, {values[best]:g}"
        else:
            reason = f"autotrack (no stats): {name} has the most frags from kill events, {int(values[best])}"
        shot = Shot(ShotChoice((name,), ShotKind.FOLLOW, reason, eyes_id=name), (best,), FirstPersonCamera(best, self.lens), now)
        shot.scores = {"autotrack_value": float(values[best])}
        return shot
