"""A recorded match: every player's transform per frame and the game events, in one .npz file.

The file is one compressed NumPy .npz archive. The member `metadata` holds UTF-8 JSON:
`format_version`, `level`, `seed`, `rate_hz`, `players` (id, team, height_m, radius_m, name) and
`events` (one object per MatchEvent, in time order). The other members are the arrays of
`MatchRecording`: `time_s` (F,) float64, `positions_world` (F, P, 3) float64, `rotations_xyzw`
(F, P, 4) float64, `alive` (F, P) bool and, when the source recorded them, `stats` (F, P, 4) int32
with the columns STAT_COLUMNS (a real match's health, armor, item bits and frags per frame).
`name` and `stats` came later without a new format version: a file without them loads with ""
and None. Conventions are the wire contract's
(docs/protocol.md): metres, seconds, +Y up; a player's position is its feet, its rotation turns
its local +Z onto its facing with local +Y up. `load` checks every shape and refuses anything
else with ValueError, so a reader never works on a half-valid match.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

FORMAT_VERSION = 1
EVENT_KINDS = ("kill", "damage", "objective", "custom")  # the wire contract's EventKind, in its order
STAT_COLUMNS = ("health", "armor", "items", "frags")  # MatchRecording.stats's last axis


@dataclass(frozen=True)
class MatchPlayer:
    """One player: id ("p00", ...), team (an index >= 0; players of one team share it), height_m
    and radius_m of its body, name (what the game called it; "" for simulated bots)."""

    id: str
    team: int
    height_m: float
    radius_m: float
    name: str = ""


@dataclass(frozen=True)
class MatchEvent:
    """One game event, as the wire contract's GameEvent.

    kind: one of EVENT_KINDS; for a kill actor_id is the attacker and other_actor_id the victim
    (for damage likewise; "" where there is no other); priority 0 means the kind's default;
    time_s: game time; label: free text; position_world (3,) float64 metres: where it happened
    (a kill's and a damage's at the victim's feet, an objective's at the point).
    """

    kind: str
    actor_id: str
    other_actor_id: str
    priority: int
    time_s: float
    label: str
    position_world: np.ndarray

    def as_json(self) -> dict:
        return {
            "kind": self.kind,
            "actor_id": self.actor_id,
            "other_actor_id": self.other_actor_id,
            "priority": self.priority,
            "time_s": self.time_s,
            "label": self.label,
            "position_world": [float(x) for x in self.position_world],
        }


@dataclass(frozen=True)
class MatchRecording:
    """A match (module docstring): F frames of P players and the events.

    time_s (F,) float64 increasing; positions_world (F, P, 3) float64 feet, metres;
    rotations_xyzw (F, P, 4) float64 unit facing; alive (F, P) bool; events in time order;
    stats (F, P, 4) int32 per STAT_COLUMNS, or None where the source has none.
    """

    level: str
    seed: int
    rate_hz: float
    players: list[MatchPlayer]
    time_s: np.ndarray
    positions_world: np.ndarray
    rotations_xyzw: np.ndarray
    alive: np.ndarray
    events: list[MatchEvent]
    stats: np.ndarray | None = None

    def __post_init__(self):
        validate(self)

    def until(self, end_s: float) -> MatchRecording:
        """The match's frames and events up to game time end_s (at least its first frame), every
        per-frame array cut alike."""
        keep = self.time_s <= max(end_s, self.time_s[0])
        last_s = self.time_s[keep][-1]
        return dataclasses.replace(
            self,
            time_s=self.time_s[keep],
            positions_world=self.positions_world[keep],
            rotations_xyzw=self.rotations_xyzw[keep],
            alive=self.alive[keep],
            stats=None if self.stats is None else self.stats[keep],
            events=[e for e in self.events if e.time_s <= last_s],
        )

    def player_index(self) -> dict[str, int]:
        """player id -> column in the per-player arrays."""
        return {p.id: i for i, p in enumerate(self.players)}

    def events_per_frame(self) -> list[list[MatchEvent]]:
        """F lists: the events of each frame, an event at time t going with the first frame whose
        time_s >= t (validate() keeps every event within the frames' times)."""
        frames: list[list[MatchEvent]] = [[] for _ in range(len(self.time_s))]
        if self.events:
            index = np.searchsorted(self.time_s, [e.time_s for e in self.events], side="left")
            for event, f in zip(self.events, index.tolist()):
                frames[f].append(event)
        return frames


def validate(match: MatchRecording) -> None:
    """Raises ValueError naming the first field that breaks the format (module docstring)."""
    n_frames, n_players = len(match.time_s), len(match.players)
    checks = [
        (
            match.time_s.dtype == np.float64 and match.time_s.ndim == 1 and n_frames >= 1,
            "time_s must be (F,) float64 with F >= 1",
        ),
        (
            bool(np.all(np.isfinite(match.time_s))) and bool(np.all(np.diff(match.time_s) > 0)),
            "time_s must be finite and strictly increasing",
        ),
        (n_players >= 1 and len({p.id for p in match.players}) == n_players, "players must have distinct ids"),
        (all(isinstance(p.team, int) and p.team >= 0 for p in match.players), "a player's team must be an int >= 0"),
        (
            match.positions_world.dtype == np.float64 and match.positions_world.shape == (n_frames, n_players, 3),
            f"positions_world must be (F, P, 3) = ({n_frames}, {n_players}, 3) float64",
        ),
        (
            match.rotations_xyzw.dtype == np.float64 and match.rotations_xyzw.shape == (n_frames, n_players, 4),
            f"rotations_xyzw must be (F, P, 4) = ({n_frames}, {n_players}, 4) float64",
        ),
        (
            match.alive.dtype == bool and match.alive.shape == (n_frames, n_players),
            f"alive must be (F, P) = ({n_frames}, {n_players}) bool",
        ),
        (match.rate_hz > 0, "rate_hz must be positive"),
        (
            match.stats is None
            or (match.stats.dtype == np.int32 and match.stats.shape == (n_frames, n_players, len(STAT_COLUMNS))),
            f"stats must be None or (F, P, {len(STAT_COLUMNS)}) = ({n_frames}, {n_players}, {len(STAT_COLUMNS)}) int32",
        ),
    ]
    for ok, message in checks:
        if not ok:
            raise ValueError(f"match file: {message}")
    ids = {p.id for p in match.players}
    for i, e in enumerate(match.events):
        if e.kind not in EVENT_KINDS:
            raise ValueError(f"match file: event {i}: kind {e.kind!r} is not one of {EVENT_KINDS}")
        if e.actor_id not in ids or (e.other_actor_id and e.other_actor_id not in ids):
            raise ValueError(f"match file: event {i} names an unknown player")
        if not match.time_s[0] <= e.time_s <= match.time_s[-1]:
            raise ValueError(f"match file: event {i} at {e.time_s} s is outside the frames' times")
        if i and e.time_s < match.events[i - 1].time_s:
            raise ValueError(f"match file: event {i} is earlier than the one before it")
        if np.shape(e.position_world) != (3,) or not 0 <= e.priority <= 15:
            raise ValueError(f"match file: event {i} needs a (3,) position and a priority in [0, 15]")


def save_match(match: MatchRecording, path: Path) -> None:
    """Write the match to path (.npz, module docstring)."""
    metadata = {
        "format_version": FORMAT_VERSION,
        "level": match.level,
        "seed": match.seed,
        "rate_hz": match.rate_hz,
        "players": [dataclasses.asdict(p) for p in match.players],
        "events": [e.as_json() for e in match.events],
    }
    optional: dict[str, Any] = {} if match.stats is None else {"stats": match.stats}
    with open(path, "wb") as f:
        np.savez_compressed(
            f,
            metadata=np.frombuffer(json.dumps(metadata).encode("utf-8"), dtype=np.uint8),
            time_s=match.time_s,
            positions_world=match.positions_world,
            rotations_xyzw=match.rotations_xyzw,
            alive=match.alive,
            **optional,
        )


def load_match(path: Path) -> MatchRecording:
    """Read and validate a match file; ValueError on anything else (module docstring)."""
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: cannot read match file: {exc}") from None
    with data:
        missing = {"metadata", "time_s", "positions_world", "rotations_xyzw", "alive"} - set(data.files)
        if missing:
            raise ValueError(f"{path}: not a match file (missing {sorted(missing)})")
        meta = json.loads(data["metadata"].tobytes().decode("utf-8"))
        arrays = {name: data[name] for name in ("time_s", "positions_world", "rotations_xyzw", "alive")}
        if "stats" in data.files:
            arrays["stats"] = data["stats"]
    if meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{path}: match file format version {meta.get('format_version')}, this build reads version {FORMAT_VERSION}"
        )
    try:
        players = [
            MatchPlayer(
                id=str(p["id"]),
                team=int(p["team"]),
                height_m=float(p["height_m"]),
                radius_m=float(p["radius_m"]),
                name=str(p.get("name", "")),
            )
            for p in meta["players"]
        ]
        events = [
            MatchEvent(
                kind=str(e["kind"]),
                actor_id=str(e["actor_id"]),
                other_actor_id=str(e["other_actor_id"]),
                priority=int(e["priority"]),
                time_s=float(e["time_s"]),
                label=str(e["label"]),
                position_world=np.asarray(e["position_world"], dtype=np.float64),
            )
            for e in meta["events"]
        ]
        return MatchRecording(
            level=str(meta["level"]),
            seed=int(meta["seed"]),
            rate_hz=float(meta["rate_hz"]),
            players=players,
            events=events,
            **arrays,
        )
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{path}: match file metadata lacks {exc}") from None
