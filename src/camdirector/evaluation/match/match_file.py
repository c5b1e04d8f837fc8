"""A recorded match: every player's transform per frame and the game events, in one .npz file.

The file is one compressed NumPy .npz archive. The member `metadata` holds UTF-8 JSON:
`format_version`, `level`, `seed`, `rate_hz`, `players` (id, team, height_m, radius_m, name, team_name) and
`events` (one object per MatchEvent, in time order). The other members are the arrays of
`MatchRecording`: `time_s` (F,) float64, `positions_world` (F, P, 3) float64, `rotations_xyzw`
(F, P, 4) float64, `alive` (F, P) bool and, when the source recorded them, `stats` (F, P, 4) int32
with the columns STAT_COLUMNS (a real match's health, armor, item bits and frags per frame), and
`aim_pitch_deg` (F, P) float64 where the source recorded where players looked.
`name`, `team_name`, `stats` and `aim_pitch_deg` came later without a new format version: a file
without them loads with "", "", None and None. Conventions are the wire contract's (docs/protocol.md): metres,
seconds, +Y up; a player's position is its feet, its rotation turns its local +Z onto its facing
with local +Y up.

Bodies stand: a player's rotation turns about world up only (its yaw), whatever the player looks
at, because the rotation is its body's (the capsule the server frames, the measures sample and the
video draws) and a person looking down does not lie down. Where it looks is the aim: the body's
rotation, then `aim_pitch_deg` about the body's local +X, positive looking down as Quake and
Source count pitch (`aim_rotations_xyzw`). Files written before this held the view (pitch and
yaw) as the rotation and no aim: `load_match` reads such a file's rotations as the view, split
into the body's yaw and the aim's pitch (`split_view`).

`load_match` checks every shape and refuses anything else with ValueError naming the file, so a
reader never works on a half-valid match.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from camdirector.geometry.transforms import quat_to_matrix

FORMAT_VERSION = 1
EVENT_KINDS = ("kill", "damage", "objective", "custom")  # the wire contract's EventKind, in its order
STAT_COLUMNS = ("health", "armor", "items", "frags")  # MatchRecording.stats's last axis
UPRIGHT_TOLERANCE = 1e-9  # largest x or z component of a body's unit quaternion: a turn about world up has none
_ZIP_MAGIC = b"PK\x03\x04"  # an .npz is a zip archive (numpy.lib.format, np.load reads the same bytes)


@dataclass(frozen=True)
class MatchPlayer:
    """One player: id ("p00", ...), team (an index >= 0; players of one team share it), height_m
    and radius_m of its body, name (what the game called it; "" for simulated bots) and team_name
    (what the game called its team; "" where it has none, a duel's or a free-for-all's player)."""

    id: str
    team: int
    height_m: float
    radius_m: float
    name: str = ""
    team_name: str = ""


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
    rotations_xyzw (F, P, 4) float64 unit facing of the upright body; alive (F, P) bool; events in
    time order; stats (F, P, 4) int32 per STAT_COLUMNS, or None where the source has none;
    aim_pitch_deg (F, P) float64, the view's pitch about the body's facing, degrees, positive
    looking down, or None where the source has none (players look where they face).
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
    aim_pitch_deg: np.ndarray | None = None

    def __post_init__(self):
        validate(self)

    def aim_rotations_xyzw(self) -> np.ndarray:
        """(F, P, 4) xyzw: where each player looks, its body's rotation then its aim's pitch about
        the body's local +X (module docstring); the body's own where the match has no aim."""
        if self.aim_pitch_deg is None:
            return self.rotations_xyzw.copy()
        half = np.radians(self.aim_pitch_deg) / 2.0
        s, c = np.sin(half), np.cos(half)
        y, w = self.rotations_xyzw[..., 1], self.rotations_xyzw[..., 3]
        # (0, y, 0, w) times (s, 0, 0, c), Hamilton product: the body's x and z are 0 (validate).
        return np.stack([w * s, y * c, -y * s, w * c], axis=-1)

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
            aim_pitch_deg=None if self.aim_pitch_deg is None else self.aim_pitch_deg[keep],
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
            match.rotations_xyzw.shape != (n_frames, n_players, 4)  # said by the check above
            or bool(np.all(np.abs(match.rotations_xyzw[..., [0, 2]]) <= UPRIGHT_TOLERANCE)),
            "rotations_xyzw must keep every body upright: a turn about world up (+Y) only, the view's pitch is the aim",
        ),
        (
            match.aim_pitch_deg is None
            or (
                match.aim_pitch_deg.dtype == np.float64
                and match.aim_pitch_deg.shape == (n_frames, n_players)
                and bool(np.all(np.isfinite(match.aim_pitch_deg)))
            ),
            f"aim_pitch_deg must be None or (F, P) = ({n_frames}, {n_players}) finite float64",
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
    optional: dict[str, Any] = {
        name: array for name, array in (("stats", match.stats), ("aim_pitch_deg", match.aim_pitch_deg)) if array is not None
    }
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


def split_view(rotations_xyzw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Views (..., 4) xyzw, each a turn about world up (yaw) after one about local +X (pitch), as
    the upright body's rotations (..., 4) (the turn about world up alone: the quaternion's twist
    about +Y) and the aim's pitch (...,) degrees, positive looking down, so that the body then the
    pitch is the view again (module docstring). A view with no twist (upside down) stands facing +Z."""
    views = np.asarray(rotations_xyzw, dtype=np.float64)
    twist = np.zeros_like(views)
    twist[..., 1], twist[..., 3] = views[..., 1], views[..., 3]
    norm = np.linalg.norm(twist, axis=-1, keepdims=True)
    body = np.where(norm > 0.0, twist / np.where(norm > 0.0, norm, 1.0), [0.0, 0.0, 0.0, 1.0])
    body = np.where(body[..., 3:4] < 0.0, -body, body)
    # the view's forward in the body's frame: its pitch is the angle below the body's +Z in the y-z plane
    forward = np.einsum("...ji,...j->...i", quat_to_matrix(body), quat_to_matrix(views)[..., 2])
    return body, np.degrees(np.arctan2(-forward[..., 1], forward[..., 2]))


def load_match(path: Path) -> MatchRecording:
    """Read and validate a match file; ValueError naming the file on anything else (module docstring)."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(_ZIP_MAGIC))
        data = np.load(path, allow_pickle=False) if head == _ZIP_MAGIC else None
    except (OSError, ValueError) as exc:
        problem = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise ValueError(f"{path}: cannot read match file: {problem}") from None
    if data is None:  # np.load would try it as a pickle, and advise loading it unsafely
        raise ValueError(
            f"{path}: not a match file: expected the .npz archive that camdirector import-match (from a demo) or "
            f"match-sim writes, this starts {head!r}"
        )
    with data:
        missing = {"metadata", "time_s", "positions_world", "rotations_xyzw", "alive"} - set(data.files)
        if missing:
            raise ValueError(f"{path}: not a match file (missing {sorted(missing)})")
        meta = json.loads(data["metadata"].tobytes().decode("utf-8"))
        arrays = {name: data[name] for name in ("time_s", "positions_world", "rotations_xyzw", "alive")}
        arrays.update({name: data[name] for name in ("stats", "aim_pitch_deg") if name in data.files})
    rotations = arrays["rotations_xyzw"]
    if (
        "aim_pitch_deg" not in arrays
        and rotations.shape[-1:] == (4,)
        and np.any(np.abs(rotations[..., [0, 2]]) > UPRIGHT_TOLERANCE)
    ):
        arrays["rotations_xyzw"], arrays["aim_pitch_deg"] = split_view(rotations)  # an older file: the view as the body
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
                team_name=str(p.get("team_name", "")),  # absent from files written before team names
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
