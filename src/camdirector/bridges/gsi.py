"""Counter-Strike's Game State Integration payloads, parsed into our own types.

The game POSTs one JSON object per change (at most every `throttle` s, at least every `heartbeat`
s) to the uri of a gamestate_integration_*.cfg (Valve Developer Community, "Counter-Strike: Global
Offensive Game State Integration"; CS2 kept the format). An observer's client with the
`allplayers_*` blocks sends every player keyed by Steam id: "name", "team" ("T"/"CT"),
"observer_slot", "state" {"health", "armor", "helmet", "defusekit", ...}, "match_stats" {"kills",
"deaths", ...}, "position" and "forward" as "x, y, z" strings in Source units (Z up; position the
player's origin, at its feet). "provider" {"timestamp"} is the game's Unix time in whole seconds;
"auth" {"token"} the cfg's token; "previously" and "added" hold what changed since the last payload
(the old values), which this bridge does not need: every payload carries every player whole.

What GSI does not carry: who killed whom (no death event, no victim id: kills are derived from the
scoreboard, gsi_tracks.py), view pitch apart from `forward`, positions between two payloads.
Anything else in the payload is ignored. A payload that is not a JSON object, or whose players'
fields have the wrong types, raises GsiPayloadError; a player without a position is kept (its
position None) so that a payload of a playing client (no allplayers_position) is refused by the
caller, not here.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

TEAMS = {"T": 0, "CT": 1}  # the session's team of each side: T -> 0, CT -> 1, as the demo importer


class GsiPayloadError(ValueError):
    """A body that is not a GSI payload we can read; the message says where."""


@dataclass(frozen=True)
class GsiPlayer:
    """One player of a payload: steamid (the key), name, team ("T" or "CT"), observer_slot (the
    spectator's number key, -1 where absent), health, armor, helmet, defusekit, kills, deaths
    (scoreboard), position_units (3,) Source units at the feet or None, forward (3,) unit vector
    in Source axes or None."""

    steamid: str
    name: str
    team: str
    observer_slot: int
    health: int
    armor: int
    helmet: bool
    defusekit: bool
    kills: int
    deaths: int
    position_units: np.ndarray | None
    forward: np.ndarray | None


@dataclass(frozen=True)
class GsiPayload:
    """One payload: token ("" where it has no auth block), timestamp_s (the provider's Unix time,
    whole seconds; 0 where absent), map_name ("" where absent), round (-1 where absent), players
    in the payload's order, spectated (the observed player's Steam id, "" where none)."""

    token: str
    timestamp_s: int
    map_name: str
    round: int
    players: tuple[GsiPlayer, ...]
    spectated: str


def _vector(text: object, where: str) -> np.ndarray:
    """ "x, y, z" (the payload's form) or [x, y, z] -> (3,) float64; GsiPayloadError otherwise."""
    try:
        parts = text.split(",") if isinstance(text, str) else list(text)  # type: ignore[call-overload]
        v = np.array([float(p) for p in parts], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GsiPayloadError(f"{where}: {text!r} is not 'x, y, z'") from exc
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise GsiPayloadError(f"{where}: {text!r} is not three finite numbers")
    return v


def _int(block: dict, key: str, where: str, default: int = 0) -> int:
    value = block.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise GsiPayloadError(f"{where}.{key}: {value!r} is not a number")
    return int(value)


def _block(parent: dict, key: str, where: str) -> dict:
    value = parent.get(key, {})
    if not isinstance(value, dict):
        raise GsiPayloadError(f"{where}.{key} is not an object")
    return value


def _player(steamid: str, raw: object) -> GsiPlayer:
    where = f"allplayers.{steamid}"
    if not isinstance(raw, dict):
        raise GsiPayloadError(f"{where} is not an object")
    team = raw.get("team", "")
    if team not in TEAMS:
        raise GsiPayloadError(f"{where}.team: {team!r} is neither 'T' nor 'CT'")
    name = raw.get("name", steamid)
    if not isinstance(name, str):
        raise GsiPayloadError(f"{where}.name is not a string")
    state, stats = _block(raw, "state", where), _block(raw, "match_stats", where)
    return GsiPlayer(
        steamid=steamid,
        name=name,
        team=team,
        observer_slot=_int(raw, "observer_slot", where, -1),
        health=_int(state, "health", where + ".state"),
        armor=_int(state, "armor", where + ".state"),
        helmet=bool(state.get("helmet", False)),
        defusekit=bool(state.get("defusekit", False)),
        kills=_int(stats, "kills", where + ".match_stats"),
        deaths=_int(stats, "deaths", where + ".match_stats"),
        position_units=_vector(raw["position"], where + ".position") if "position" in raw else None,
        forward=_vector(raw["forward"], where + ".forward") if "forward" in raw else None,
    )


def parse_payload(body: bytes) -> GsiPayload:
    """The payload in `body` (UTF-8 JSON, module docstring); GsiPayloadError if it cannot be read."""
    try:
        raw = json.loads(body)
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise GsiPayloadError(f"not JSON: {exc}") from exc
    if not isinstance(raw, dict):
        raise GsiPayloadError("the payload is not a JSON object")
    auth, provider = _block(raw, "auth", "payload"), _block(raw, "provider", "payload")
    game_map, player = _block(raw, "map", "payload"), _block(raw, "player", "payload")
    token = auth.get("token", "")
    if not isinstance(token, str):
        raise GsiPayloadError("auth.token is not a string")
    spectated = player.get("spectarget", player.get("steamid", ""))
    return GsiPayload(
        token=token,
        timestamp_s=_int(provider, "timestamp", "provider"),
        map_name=str(game_map.get("name", "")),
        round=_int(game_map, "round", "map", -1),
        players=tuple(_player(str(k), v) for k, v in _block(raw, "allplayers", "payload").items()),
        spectated=spectated if isinstance(spectated, str) else "",
    )
