"""Counter-Strike 2 demos (.dem, Source 2's "PBDEMS2") imported into a match file, with demoparser2.

demoparser2 (PyPI, LaihoE/demoparser, the optional extra `camdirector[cs2]`) reads the demo: each
player's props per tick (`parse_ticks`) and the game events (`parse_event(s)`). This module turns
its tables into a `MatchRecording` (evaluation/match/match_file.py); `match_from_tables` is that
conversion alone, over plain columns, so it runs without the package.

Units and axes. Source measures in units with +Z up and yaw turning +X toward +Y, as Quake does,
so quake_frame's axis map (x, y, z) -> (x, z, -y) and its view_rotation apply unchanged; only the
scale differs. A player's body stands, turned by its eye angles' yaw alone; their pitch is its aim
(evaluation/match/match_file.py: a player looking down does not lie down). The player's hull is
32 x 32 x 72 units standing (54 crouching) with the origin at
its feet (Valve Developer Community, "Counter-Strike: Global Offensive Mapper's Reference", Player
Dimensions; CS2 keeps CS:GO's movement hull). One unit = one inch (0.0254 m) makes that player
1.83 m tall and its 250 units/s knife run 6.35 m/s: a grown person at a sprint, so the player's
height sets the scale here as it does for Quake. (Hammer's "1 foot = 16 units" for architecture
would make the player 1.37 m.)

Frames: CS2 servers simulate 64 ticks per second; time_s = tick / 64. Frames are taken every
64 / rate_hz ticks from the first tick with a player on a team to the last, each at the first
recorded tick at or after its due tick (a demo may skip ticks); rate_hz is at most 64.

Players: everyone who was on T or CT at some frame, in order of first appearance; spectators and
the SourceTV bot are not players. Ids "p00", "p01", ...; a player is its Steam id, or its name for
a bot (bots have Steam id 0). Team: the side a player first played, T -> 0, CT -> 1: a team is a
roster, so it stays the same when the sides swap at half time. A player who joins late, leaves, or
goes to spectator is absent from those frames: alive False, its position and facing held from the
nearest frame it was present (the first such frame before it joins), its stats zero except frags
(held). Alive: present, is_alive and health > 0.

Stats (F, P, 4) int32, columns health, armor (armor_value), items and frags (kills_total, the
scoreboard's kills). items is a bit mask: 1 helmet, 2 defuse kit.

Events. Each player_death is one "kill": actor the attacker, other the victim, at the victim's
feet; label the weapon ("ak47"), with " headshot" after it for a headshot. A death to no player
(the world, the bomb, a fall) has actor = victim and label "world:<weapon>"; one to oneself
"suicide:<weapon>"; one to a teammate "teamkill:<weapon>" (the QuakeWorld importer's labels,
matches/quakeworld_obituaries.py). bomb_planted, bomb_defused and bomb_exploded are "objective"
events ("bomb planted", ...) at the bomb: the planter's feet when planted, that point again when
defused or exploded; actor the planter or defuser (the last planter for an explosion whose player
is unknown). Events outside the frames' times are moved to the nearest frame's time.

Errors: a file that is not a CS2 demo, is cut short, or that demoparser2 refuses raises
`Cs2DemoError` (a ValueError) naming the file; demoparser2's Rust panics are caught here too.
Without the package, `Cs2SupportMissing` says how to install it.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from camdirector.evaluation.match.match_file import MatchEvent, MatchPlayer, MatchRecording
from camdirector.geometry import quake_frame

TICK_RATE_HZ = 64.0  # CS2's server simulation rate
M_PER_UNIT = 0.0254  # one unit = one inch (module docstring)
PLAYER_HEIGHT_UNITS = 72.0  # standing hull height, origin at the feet
PLAYER_RADIUS_UNITS = 16.0  # hull half width
PLAYER_HEIGHT_M = PLAYER_HEIGHT_UNITS * M_PER_UNIT
PLAYER_RADIUS_M = PLAYER_RADIUS_UNITS * M_PER_UNIT
TEAMS = {2: 0, 3: 1}  # m_iTeamNum: 2 = T, 3 = CT -> the match file's team
ITEM_HELMET, ITEM_DEFUSER = 1, 2  # bits of the stats' items column
BOMB_EVENTS = {"bomb_planted": "bomb planted", "bomb_defused": "bomb defused", "bomb_exploded": "bomb exploded"}
INSTALL_HINT = "pip install 'camdirector[cs2]'"

# What parse_ticks is asked for: demoparser2's names (its README's list of player props).
TICK_PROPS = (
    "X",
    "Y",
    "Z",
    "pitch",
    "yaw",
    "team_num",
    "is_alive",
    "health",
    "armor_value",
    "kills_total",
    "has_helmet",
    "has_defuser",
)
EVENT_PROPS = ("X", "Y", "Z")  # the event's players' feet, as user_X, attacker_X, ...

_MAGIC_CS2 = b"PBDEMS2\x00"
_MAGIC_SOURCE1 = b"HL2DEMO\x00"
_HEADER_BYTES = 16  # magic, then the file info's offset and another, uint32 LE
_MIN_FRAME_BYTES = 3  # a frame's header: three varints of at least a byte each


class Cs2DemoError(ValueError):
    """A file that is not a readable CS2 demo: the message names the file and what is wrong."""

    def __init__(self, path: Path | str, problem: str):
        super().__init__(f"{path}: {problem}")
        self.path = str(path)


class Cs2SupportMissing(ImportError):
    """demoparser2 is not installed; the message says how to install it."""


def source_points_to_world(points_units: np.ndarray) -> np.ndarray:
    """Source points (..., 3) in units, Z up -> world points (..., 3) float64 in metres, Y up.

    quake_frame's axis map at this module's scale (one unit = one inch, module docstring)."""
    return quake_frame.points_to_world(points_units) * (M_PER_UNIT / quake_frame.M_PER_UNIT)


def view_rotation(pitch_deg: np.ndarray, yaw_deg: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) xyzw turning local +Z onto a player's view, local +Y up.

    Source's eye angles (m_angEyeAngles: pitch positive looking down, yaw about +Z from +X) give
    forward (cos p cos y, cos p sin y, -sin p) in ValveSoftware/source-sdk-2013 mathlib.cpp,
    AngleVectors, Quake's formula: so quake_frame.view_rotation, after the same axis map."""
    return quake_frame.view_rotation(pitch_deg, yaw_deg)


def check_demo_file(path: Path) -> None:
    """Raises Cs2DemoError unless path starts as a CS2 demo and is as long as its header says.

    demoparser2 reads a demo cut short without complaint (LaihoE/demoparser
    src/parser/src/first_pass/parser.rs, handle_short_header, keeps this check commented out), so
    it is made here: the header's second field is the offset of the closing file-info frame, and
    a file that ends before that frame was cut. An offset of 0 (never written) is not checked."""
    try:
        with open(path, "rb") as f:
            head = f.read(_HEADER_BYTES)
            size = f.seek(0, 2)
    except OSError as exc:
        raise Cs2DemoError(path, f"cannot read the demo: {exc.strerror or exc}") from None
    if head[:8] == _MAGIC_SOURCE1:
        raise Cs2DemoError(path, "a Source 1 (CS:GO) demo; only CS2 (Source 2, PBDEMS2) demos are read")
    if head[:8] != _MAGIC_CS2:
        raise Cs2DemoError(path, f"not a CS2 demo: it starts with {head[:8]!r}, a CS2 demo with {_MAGIC_CS2!r}")
    if len(head) < _HEADER_BYTES:
        raise Cs2DemoError(path, f"truncated CS2 demo: {size} bytes, shorter than its {_HEADER_BYTES}-byte header")
    (file_info_at,) = struct.unpack_from("<I", head, 8)
    if file_info_at and size < file_info_at + _MIN_FRAME_BYTES:
        raise Cs2DemoError(
            path,
            f"truncated CS2 demo: it ends at byte {size}, but its header places the closing file info at byte {file_info_at}",
        )


def _demo_parser_class():
    try:
        from demoparser2 import DemoParser
    except ImportError:
        raise Cs2SupportMissing(f"reading CS2 demos needs the demoparser2 package: {INSTALL_HINT}") from None
    return DemoParser


def _guarded(path: Path, call: Callable):
    """call() with every failure of demoparser2 turned into Cs2DemoError naming path.

    demoparser2 raises DemoParser.Exception (an Exception) for what it detects, and its Rust
    panics arrive as pyo3's PanicException, which derives from BaseException only."""
    try:
        return call()
    except Exception as exc:
        raise Cs2DemoError(path, f"demoparser2 cannot read this demo: {exc}") from None
    except BaseException as exc:
        if type(exc).__name__ != "PanicException":
            raise
        raise Cs2DemoError(path, f"demoparser2 failed on this demo (panic: {exc})") from None


def _columns(table) -> dict[str, np.ndarray]:
    """A demoparser2 DataFrame as {column: array}; an empty result (it returns [] for an event the
    demo never had) as {}."""
    if not hasattr(table, "columns") or len(table) == 0:
        return {}
    return {str(c): table[c].to_numpy() for c in table.columns}


def parse_demo_tables(path: Path) -> tuple[dict, dict[str, np.ndarray], dict[str, np.ndarray], dict]:
    """demoparser2's reading of path: (header, ticks, deaths, bombs).

    header: parse_header's strings (map_name, ...); ticks: parse_ticks(TICK_PROPS) as columns,
    with tick, steamid and name; deaths: player_death's columns with the victim's and attacker's
    feet (user_X, attacker_X, ...); bombs: {event name: columns} for BOMB_EVENTS. Any failure of
    the package -> Cs2DemoError; the package missing -> Cs2SupportMissing."""
    parser_class = _demo_parser_class()
    parser = _guarded(path, lambda: parser_class(str(path)))
    header = _guarded(path, parser.parse_header)
    ticks = _guarded(path, lambda: _columns(parser.parse_ticks(list(TICK_PROPS))))
    deaths = _guarded(path, lambda: _columns(parser.parse_event("player_death", player=list(EVENT_PROPS))))
    bombs = _guarded(
        path, lambda: {name: _columns(table) for name, table in parser.parse_events(list(BOMB_EVENTS), player=list(EVENT_PROPS))}
    )
    return dict(header), ticks, deaths, bombs


def import_cs2_demo(path: Path, *, level: str | None = None, rate_hz: float = 64.0) -> MatchRecording:
    """The CS2 demo at path as a match (module docstring), rate_hz frames per second (at most 64).

    level: the level's name in camdirector's level registry (its geometry is the user's OBJ, added
    with `camdirector level add`); None takes the demo's map name (de_dust2, ...)."""
    path = Path(path)
    check_demo_file(path)
    header, ticks, deaths, bombs = parse_demo_tables(path)
    try:
        return match_from_tables(ticks, deaths, bombs, level=level or header.get("map_name") or "unknown", rate_hz=rate_hz)
    except ValueError as exc:
        raise Cs2DemoError(path, str(exc)) from None


def load_cs2_demo_file(path: Path, *, level: str | None, rate_hz: float) -> MatchRecording:
    """import-match's load function (matches/importers.py): the demo's frames at CS2's own tick
    rate, TICK_RATE_HZ, whatever `rate_hz` (import-match's --rate-hz, whose default is the MVD's
    60 Hz grid) asks."""
    return import_cs2_demo(path, level=level)


def _text(value) -> str:
    """A table cell as text, "" where demoparser2 left it empty (None, NaN, pandas' NA)."""
    text = "" if value is None else str(value).strip()
    return "" if text in ("nan", "<NA>", "None") else text


def _player_key(steamid, name) -> str | None:
    """Who a row is: its Steam id, or "bot:<name>" where the id is 0 (a bot); None for no one."""
    steamid, name = _text(steamid), _text(name)
    if steamid not in ("", "0"):
        return steamid
    return f"bot:{name}" if name else None


def _held(values: np.ndarray, present: np.ndarray) -> np.ndarray:
    """values (F, P, ...) with each absent [f, p] replaced by the nearest present frame's: the
    last one before f, or the first one after for frames before the player's first."""
    n_frames = len(present)
    frame = np.arange(n_frames)[:, None]
    last = np.maximum.accumulate(np.where(present, frame, -1), axis=0)
    first = np.minimum.accumulate(np.where(present, frame, n_frames)[::-1], axis=0)[::-1]
    source = np.where(last >= 0, last, np.minimum(first, n_frames - 1))
    return np.take_along_axis(values, source.reshape(source.shape + (1,) * (values.ndim - 2)), axis=0)


def _frame_ticks(all_ticks: np.ndarray, first: int, last: int, rate_hz: float) -> np.ndarray:
    """The ticks that become frames: every 64 / rate_hz ticks from first to last, each moved to the
    first recorded tick at or after it."""
    recorded = np.unique(all_ticks[(all_ticks >= first) & (all_ticks <= last)])
    due = first + np.arange(int(np.floor((last - first) * rate_hz / TICK_RATE_HZ)) + 1) * (TICK_RATE_HZ / rate_hz)
    index = np.minimum(np.searchsorted(recorded, np.ceil(due - 1e-9).astype(np.int64)), len(recorded) - 1)
    return np.unique(recorded[index])


def match_from_tables(
    ticks: Mapping[str, np.ndarray],
    deaths: Mapping[str, np.ndarray],
    bombs: Mapping[str, Mapping[str, np.ndarray]],
    *,
    level: str,
    rate_hz: float = 64.0,
) -> MatchRecording:
    """demoparser2's tables (parse_demo_tables) as a match (module docstring).

    ticks: one row per player and tick, columns "tick", "steamid", "name" and TICK_PROPS (X, Y, Z
    units; pitch, yaw degrees); deaths: player_death's columns ("tick", "user_steamid",
    "user_name", "attacker_steamid", "attacker_name", "weapon", "headshot", "user_X", ...), {} for
    none; bombs: BOMB_EVENTS' names -> columns ("tick", "user_steamid", "user_name", "user_X",
    ...). Raises ValueError when no player was on a team or rate_hz is outside (0, 64]."""
    if not 0.0 < rate_hz <= TICK_RATE_HZ:
        raise ValueError(f"rate_hz {rate_hz} is outside (0, {TICK_RATE_HZ:g}]: frames come from the demo's ticks")
    missing = {"tick", "steamid", "name", *TICK_PROPS} - set(ticks)
    if ticks and missing:
        raise ValueError(f"demoparser2's ticks lack {sorted(missing)}")
    tick = np.asarray(ticks.get("tick", []), dtype=np.int64)
    on_team = np.isin(np.asarray(ticks.get("team_num", []), dtype=np.int64), list(TEAMS))
    if not on_team.any():
        raise ValueError("no player is on T or CT at any tick: nothing to import")
    keys = np.asarray([_player_key(steamid, name) or "" for steamid, name in zip(ticks["steamid"], ticks["name"])])
    on_team &= keys != ""
    team_num = np.asarray(ticks["team_num"], dtype=np.int64)

    frame_ticks = _frame_ticks(tick, int(tick[on_team].min()), int(tick[on_team].max()), rate_hz)
    rows = np.flatnonzero(on_team & np.isin(tick, frame_ticks))
    rows = rows[np.lexsort((keys[rows], tick[rows]))]  # by tick, then player
    unique_keys, first_at, inverse = np.unique(keys[rows], return_index=True, return_inverse=True)
    appearance = np.argsort(first_at, kind="stable")  # the players' order: who showed up first
    column_of_unique = np.empty(len(unique_keys), dtype=np.int64)
    column_of_unique[appearance] = np.arange(len(unique_keys))
    first_rows = rows[first_at[appearance]]
    players = [
        MatchPlayer(
            id=f"p{i:02d}",
            team=TEAMS[int(team_num[r])],
            height_m=PLAYER_HEIGHT_M,
            radius_m=PLAYER_RADIUS_M,
            name=_text(ticks["name"][r]),
        )
        for i, r in enumerate(first_rows)
    ]

    n_frames, n_players = len(frame_ticks), len(players)
    f_index = np.searchsorted(frame_ticks, tick[rows])
    p_index = column_of_unique[inverse]
    present = np.zeros((n_frames, n_players), dtype=bool)
    present[f_index, p_index] = True

    def column(name: str, dtype) -> np.ndarray:
        return np.asarray(ticks[name], dtype=dtype)[rows]

    origin = np.zeros((n_frames, n_players, 3))
    origin[f_index, p_index] = np.stack([column("X", np.float64), column("Y", np.float64), column("Z", np.float64)], axis=-1)
    angles = np.zeros((n_frames, n_players, 2))
    angles[f_index, p_index] = np.stack([column("pitch", np.float64), column("yaw", np.float64)], axis=-1)
    origin, angles = _held(origin, present), _held(angles, present)
    alive = np.zeros((n_frames, n_players), dtype=bool)
    alive[f_index, p_index] = column("is_alive", bool) & (column("health", np.int32) > 0)
    stats = np.zeros((n_frames, n_players, 4), dtype=np.int32)
    stats[f_index, p_index, 0] = column("health", np.int32)
    stats[f_index, p_index, 1] = column("armor_value", np.int32)
    stats[f_index, p_index, 2] = (column("has_helmet", bool) * ITEM_HELMET) | (column("has_defuser", bool) * ITEM_DEFUSER)
    frags = np.zeros((n_frames, n_players, 1), dtype=np.int32)
    frags[f_index, p_index, 0] = column("kills_total", np.int32)
    stats[..., 3] = np.where(np.maximum.accumulate(present, axis=0), _held(frags, present)[..., 0], 0)

    time_s = frame_ticks.astype(np.float64) / TICK_RATE_HZ
    positions = source_points_to_world(origin)
    by_key = dict(zip(unique_keys[appearance].tolist(), players))
    events = _kill_events(deaths, by_key, time_s, positions) + _bomb_events(bombs, by_key, time_s)
    events.sort(key=lambda e: e.time_s)
    return MatchRecording(
        level=level,
        seed=0,
        rate_hz=float(rate_hz),
        players=players,
        time_s=time_s,
        positions_world=positions,
        rotations_xyzw=view_rotation(np.zeros_like(angles[..., 1]), angles[..., 1]),
        alive=alive,
        events=events,
        stats=stats,
        aim_pitch_deg=angles[..., 0].copy(),
    )


def _event_time(tick: int, time_s: np.ndarray) -> float:
    return float(np.clip(tick / TICK_RATE_HZ, time_s[0], time_s[-1]))


def _event_feet(columns: Mapping[str, np.ndarray], side: str, i: int) -> np.ndarray | None:
    """The world feet (3,) metres of the event's `side` player ("user", "attacker") at row i, or
    None where demoparser2 gave none."""
    try:
        point = np.array([float(columns[f"{side}_{axis}"][i]) for axis in "XYZ"])
    except (KeyError, TypeError, ValueError):
        return None
    return source_points_to_world(point) if np.all(np.isfinite(point)) else None


def _key_at(columns: Mapping[str, np.ndarray], side: str, i: int) -> str | None:
    """The player key of an event's `side` ("user", "attacker") at row i, None where it has none."""
    steamid, name = columns.get(f"{side}_steamid"), columns.get(f"{side}_name")
    return _player_key(None if steamid is None else steamid[i], None if name is None else name[i])


def _player_at(by_key: Mapping[str, MatchPlayer], columns: Mapping[str, np.ndarray], side: str, i: int) -> MatchPlayer | None:
    """The player on an event's `side` at row i (_key_at), None where it has none or is no player."""
    key = _key_at(columns, side, i)
    return None if key is None else by_key.get(key)


def _kill_events(
    deaths: Mapping[str, np.ndarray], by_key: dict[str, MatchPlayer], time_s: np.ndarray, positions: np.ndarray
) -> list[MatchEvent]:
    """player_death's rows as kill events (module docstring); by_key: player key -> player, in
    the players' order; positions (F, P, 3) world feet, for a death whose row has no position."""
    column_of = {player.id: i for i, player in enumerate(by_key.values())}
    events = []
    for i in range(len(deaths.get("tick", []))):
        victim = _player_at(by_key, deaths, "user", i)
        if victim is None:  # a death of no one on a team (cannot happen in a normal match)
            continue
        attacker = _player_at(by_key, deaths, "attacker", i)
        weapon = str(deaths["weapon"][i]) if "weapon" in deaths else ""
        if attacker is None:
            label, attacker = f"world:{weapon}", victim
        elif attacker is victim:
            label = f"suicide:{weapon}"
        elif attacker.team == victim.team:
            label = f"teamkill:{weapon}"
        else:
            label = weapon
        if "headshot" in deaths and bool(deaths["headshot"][i]):
            label += " headshot"
        t = _event_time(int(deaths["tick"][i]), time_s)
        feet = _event_feet(deaths, "user", i)
        if feet is None:
            frame = min(int(np.searchsorted(time_s, t)), len(time_s) - 1)
            feet = positions[frame, column_of[victim.id]]
        events.append(
            MatchEvent(
                kind="kill",
                actor_id=attacker.id,
                other_actor_id=victim.id,
                priority=0,
                time_s=t,
                label=label,
                position_world=np.asarray(feet, dtype=np.float64),
            )
        )
    return events


def _bomb_events(
    bombs: Mapping[str, Mapping[str, np.ndarray]], by_key: dict[str, MatchPlayer], time_s: np.ndarray
) -> list[MatchEvent]:
    """BOMB_EVENTS' rows, in tick order, as objective events at the bomb (module docstring)."""
    rows = sorted(
        (int(columns["tick"][i]), name, i)
        for name, columns in bombs.items()
        if name in BOMB_EVENTS
        for i in range(len(columns.get("tick", [])))
    )
    events, planter, bomb_at = [], None, None
    for tick, name, i in rows:
        columns = bombs[name]
        player = _player_at(by_key, columns, "user", i)
        feet = _event_feet(columns, "user", i)
        if name == "bomb_planted":
            planter, bomb_at = player, feet
            where = feet
        else:
            where = bomb_at if bomb_at is not None else feet
            if name == "bomb_exploded" and player is None:
                player = planter
        if player is None or where is None:
            continue
        events.append(
            MatchEvent(
                kind="objective",
                actor_id=player.id,
                other_actor_id="",
                priority=0,
                time_s=_event_time(tick, time_s),
                label=BOMB_EVENTS[name],
                position_world=np.asarray(where, dtype=np.float64),
            )
        )
    return events
