"""A real QuakeWorld match from an MVD demo, as a match file (evaluation/match/match_file.py).

`import_mvd` reads the demo (matches/mvd_wire.py) and puts every playing slot onto a uniform time
grid at rate_hz from the demo's first player sample to its end (or `phase_rows` of a row after
it: a live feed samples the game at a phase nobody chooses, load_tests/program_phases.py):

- feet, facing and aim: quake_frame.feet_world(origin); the body upright, turned by the yaw alone
  (quake_frame.view_rotation at pitch 0); the aim's pitch, the view's (match_file.py: a player
  looking down does not lie down), in [-180, 180); all linearly
  interpolated between the demo's samples (yaw and pitch the short way round), EXCEPT into a
  sample that jumped: one the server marked (svc_setangle for a teleport or respawn, DF_DEAD
  cleared) or one reached faster than anything can move, STEP_SPEED_UNITS_S (QuakeWorld caps each
  velocity component at sv_maxvelocity = 2000 units/s, so 2000 * sqrt(3) is the fastest real
  motion); there the player holds its place and then steps, never sweeping through walls.
- stats (health, armor, items, frags): the last value the demo sent at or before each frame.
- alive: health > 0, the demo's DF_DEAD flag clear and not steered: a player the server turns
  every frame (svc_setangle on LIMBO_RUN samples in a row) is a dead one following a teammate's
  view (KTX's wipeout and clan arena; its stats are then the teammate's). And dead from a kill
  until the victim's next jump out of that (its respawn): a mode that respawns in the same server
  frame never shows health <= 0.
- events: one kill per obituary at its demo time: actor the killer, other the victim, label the
  weapon ("rl"); a suicide or a death to the world has the victim as both; a teamkill's unsaid side
  is the teammate whose health (victim) or frags (killer) fell within TEAMKILL_WINDOW_S of it, else
  the victim's nearest teammate (killer). Position: the victim's feet then.
- teams: with teamplay on and team names set, team names in slot order of first appearance -> 0,
  1, ..., each player keeping its team's name; otherwise (a duel, free for all) each player its
  own team, with no team name (a duel's userinfo "team" is a leftover, not a side).
"""

from __future__ import annotations

import gzip
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from camdirector.evaluation.match.match_file import MatchEvent, MatchPlayer, MatchRecording
from camdirector.geometry import quake_frame
from camdirector.matches.mvd_wire import MvdDemo, MvdError, MvdTrack, MvdUpdate, parse_mvd

__all__ = ["MvdError", "MvdImport", "import_mvd", "load_mvd_file", "match_from_mvd", "parse_mvd"]

STEP_SPEED_UNITS_S = 2000.0 * math.sqrt(3.0)  # sv_maxvelocity per axis, any direction
MIN_STEP_DT_S = 0.001  # two samples closer than this compare as this far apart
TEAMKILL_WINDOW_S = 0.5  # a teamkill's other side changes state within this
LIMBO_RUN = 3  # setangle on this many samples in a row: steered, not playing


@dataclass(frozen=True)
class MvdImport:
    """An imported match and steps (F - 1, P) bool: player p jumped (teleport, respawn) between
    frames f and f + 1, so its motion there is no running speed."""

    match: MatchRecording
    steps: np.ndarray


def import_mvd(
    data: bytes, *, level: str | None = None, rate_hz: float = 60.0, name: str = "", phase_rows: float = 0.0
) -> MatchRecording:
    """The match an MVD recorded (module docstring). level: the match file's level (default the
    demo's map, "dm2", else name, the demo's own name); phase_rows: the grid starts this share of a
    row after the demo's first player sample, [0, 1). MvdError (a ValueError) on a bad file."""
    return match_from_mvd(parse_mvd(data), level=level, rate_hz=rate_hz, name=name, phase_rows=phase_rows).match


def load_mvd_file(path: Path, *, level: str | None, rate_hz: float) -> MatchRecording:
    """The match in an .mvd file, or an .mvd.gz one (gunzipped): import-match's load function
    (matches/importers.py); the demo's own name is its file's."""
    data = path.read_bytes()
    if path.name.lower().endswith(".gz"):
        data = gzip.decompress(data)
    return import_mvd(data, level=level, rate_hz=rate_hz, name=path.name)


def match_from_mvd(
    demo: MvdDemo, *, level: str | None = None, rate_hz: float = 60.0, name: str = "", phase_rows: float = 0.0
) -> MvdImport:
    """A parsed demo on a uniform grid (module docstring), with where each player stepped."""
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    if not 0.0 <= phase_rows < 1.0:
        raise ValueError(f"phase_rows must be in [0, 1), got {phase_rows}")
    slots = [p.slot for p in demo.players]
    start_s = min(float(demo.tracks[s].time_s[0]) for s in slots) + phase_rows / rate_hz
    end_s = max(demo.duration_s, max(float(demo.tracks[s].time_s[-1]) for s in slots))
    n_frames = int(math.ceil((end_s - start_s) * rate_hz - 1e-9)) + 1
    time_s = start_s + np.arange(n_frames, dtype=np.float64) / rate_hz

    jumps = {s: _jumps(demo.tracks[s]) for s in slots}
    origin = np.stack([_interpolate(demo.tracks[s].time_s, demo.tracks[s].origin_units, jumps[s], time_s) for s in slots], axis=1)
    angles = np.stack(
        [
            _interpolate(
                demo.tracks[s].time_s, np.unwrap(demo.tracks[s].angles_deg[:, :2], period=360.0, axis=0), jumps[s], time_s
            )
            for s in slots
        ],
        axis=1,
    )
    stats = np.stack([_held(demo.stats[s].time_s, demo.stats[s].values, time_s) for s in slots], axis=1)
    dead_flag = np.stack([_held(demo.tracks[s].time_s, demo.tracks[s].dead, time_s) for s in slots], axis=1)
    limbo = {s: _limbo(demo.tracks[s].jump) for s in slots}
    steered = np.stack([_held(demo.tracks[s].time_s, limbo[s], time_s) for s in slots], axis=1)
    seen = np.stack([time_s >= demo.tracks[s].time_s[0] for s in slots], axis=1)
    alive = (stats[..., 0] > 0) & ~dead_flag & ~steered & seen
    steps = np.stack([_grid_steps(demo.tracks[s].time_s[jumps[s]], time_s) for s in slots], axis=1)

    ids = [f"p{i:02d}" for i in range(len(slots))]
    column = {s: i for i, s in enumerate(slots)}
    events = []
    for death in _resolved_deaths(demo, column, origin, time_s):
        killer, victim = column[death.killer], column[death.victim]
        t = min(max(death.time_s, time_s[0]), time_s[-1])
        track = demo.tracks[death.victim]
        at = _interpolate(track.time_s, track.origin_units, jumps[death.victim], np.array([t]))[0]
        events.append(
            MatchEvent(
                kind="kill",
                actor_id=ids[killer],
                other_actor_id=ids[victim],
                priority=0,
                time_s=float(t),
                label=death.label,
                position_world=quake_frame.feet_world(at),
            )
        )
        _dead_until_jump(alive[:, victim], time_s, t, track.time_s[jumps[death.victim] & ~limbo[death.victim]])

    players = [
        quake_player(pid, p.name, team, team_name) for pid, (team, team_name), p in zip(ids, player_teams(demo), demo.players)
    ]
    match = MatchRecording(
        level=level or demo.map_name or name,
        seed=0,
        rate_hz=float(rate_hz),
        players=players,
        time_s=time_s,
        positions_world=quake_frame.feet_world(origin),
        rotations_xyzw=quake_frame.view_rotation(0.0, angles[..., 1]),
        alive=alive,
        events=events,
        stats=stats.astype(np.int32),
        aim_pitch_deg=np.mod(angles[..., 0] + 180.0, 360.0) - 180.0,  # unwrapped, it may have gone round
    )
    return MvdImport(match=match, steps=steps)


def quake_player(pid: str, name: str, team: int, team_name: str) -> MatchPlayer:
    """A QuakeWorld player of a match: Quake's body (quake_frame's height and radius)."""
    return MatchPlayer(
        id=pid,
        team=team,
        height_m=quake_frame.PLAYER_HEIGHT_M,
        radius_m=quake_frame.PLAYER_RADIUS_M,
        name=name,
        team_name=team_name,
    )


def _jumps(track: MvdTrack) -> np.ndarray:
    """(n,) bool: sample k jumped from sample k - 1 (module docstring)."""
    dt = np.maximum(np.diff(track.time_s), MIN_STEP_DT_S)
    too_fast = np.linalg.norm(np.diff(track.origin_units, axis=0), axis=1) > STEP_SPEED_UNITS_S * dt
    return track.jump | np.concatenate([[False], too_fast])


def _limbo(jump: np.ndarray) -> np.ndarray:
    """(n,) bool: sample k is in a run of at least LIMBO_RUN server-flagged jumps (module docstring)."""
    limbo = np.zeros(len(jump), dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], jump.astype(np.int8), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        if stop - start >= LIMBO_RUN:
            limbo[start:stop] = True
    return limbo


def _interpolate(times: np.ndarray, values: np.ndarray, jump: np.ndarray, at: np.ndarray) -> np.ndarray:
    """values (n, k) at the times `at` (m,): linear between samples, held into a jumped sample,
    held at the ends; (m, k)."""
    last = len(times) - 1
    i = np.clip(np.searchsorted(times, at, side="right") - 1, 0, last)
    j = np.minimum(i + 1, last)
    span = times[j] - times[i]
    w = np.clip((at - times[i]) / np.where(span > 0, span, 1.0), 0.0, 1.0)
    w[(span <= 0) | jump[j]] = 0.0
    return values[i] + w[:, None] * (values[j] - values[i])


def _held(times: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The last of values (n, ...) at or before each of `at` (m,), the first before the first."""
    return values[np.clip(np.searchsorted(times, at, side="right") - 1, 0, len(times) - 1)]


def _grid_steps(jump_times: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """(F - 1,) bool: a jump at a time in (time_s[f], time_s[f + 1]]."""
    steps = np.zeros(max(len(time_s) - 1, 0), dtype=bool)
    f = np.searchsorted(time_s, jump_times, side="left") - 1
    steps[f[(f >= 0) & (f < len(steps))]] = True
    return steps


def _dead_until_jump(alive: np.ndarray, time_s: np.ndarray, kill_s: float, jump_times: np.ndarray) -> None:
    """Marks the victim dead from the kill until its next jump (its respawn), in place."""
    after = jump_times[jump_times > kill_s]
    until = after[0] if len(after) else time_s[-1] + 1.0
    alive[(time_s >= kill_s) & (time_s < until)] = False


def player_teams(demo: MvdDemo | MvdUpdate) -> list[tuple[int, str]]:
    """Team index and team name per player (module docstring), of a demo or of a live stream's
    players so far (bridges/qtv.py)."""
    names = [p.team for p in demo.players]
    if demo.teamplay == 0 or not all(names):
        return [(k, "") for k in range(len(names))]
    order = list(dict.fromkeys(names))
    return [(order.index(t), t) for t in names]


def _resolved_deaths(demo: MvdDemo, column: dict[int, int], origin: np.ndarray, time_s: np.ndarray):
    """The demo's deaths with both slots known (module docstring); a teamkill whose other side
    cannot be found is left out."""
    team = {p.slot: p.team for p in demo.players}
    for death in demo.deaths:
        if death.killer >= 0 and death.victim >= 0:
            yield death
            continue
        known = death.killer if death.killer >= 0 else death.victim
        mates = [s for s in column if s != known and team[s] and team[s] == team[known]]
        if death.victim < 0:
            found = _changed_near(demo, mates, death.time_s, column=0, dropped_to_dead=True)
            if found is not None:
                yield type(death)(death.time_s, death.killer, found, death.label)
            continue
        found = _changed_near(demo, mates, death.time_s, column=3, dropped_to_dead=False)
        if found is None and mates:
            f = min(int(np.searchsorted(time_s, death.time_s)), len(time_s) - 1)
            found = min(mates, key=lambda s: np.linalg.norm(origin[f, column[s]] - origin[f, column[death.victim]]))
        yield type(death)(death.time_s, death.victim if found is None else found, death.victim, death.label)


def _changed_near(demo: MvdDemo, slots: list[int], t: float, column: int, dropped_to_dead: bool) -> int | None:
    """The slot among `slots` whose stat `column` fell (to <= 0 if dropped_to_dead) closest to t,
    within TEAMKILL_WINDOW_S; None if none did."""
    best, best_dt = None, TEAMKILL_WINDOW_S
    for s in slots:
        stats = demo.stats[s]
        before, after = stats.values[:-1, column], stats.values[1:, column]
        fell = (after < before) & ((after <= 0) & (before > 0) if dropped_to_dead else True)
        for when in stats.time_s[1:][fell]:
            if abs(when - t) <= best_dt:
                best, best_dt = s, abs(when - t)
    return best
