"""The players as the newest GSI payloads saw them, sampled at any moment (gsi_cast.py's clock).

Payloads are offered as they arrive, stamped with the local monotonic clock: the game's own
timestamp counts whole seconds, too coarse to place a payload sent every 0.1 s. A payload whose
timestamp is older than the newest accepted one's came out of order and is dropped; one whose body
is byte for byte one of the last accepted (the game resending after its timeout) is dropped as a
duplicate; so time never runs backwards. Within one second the game's payloads are taken in their
arrival order (it posts one at a time, the next after the answer or its timeout).

Sampling at time t: each player's position and yaw are interpolated between the two newest
payloads that carried it, at t - interp_delay_s (entity interpolation: the frame shows the players
one payload period in the past, so that a payload lies on each side); beyond the newest, the
newest is held (no extrapolation: a player that stopped is not carried on). Without any payload
for hold_s, the sample says stale. Before the roster's payload is due (interp_delay_s after it came)
the sample says not started: the frames begin where the players begin to move, not holding the
first payload over the delay.

The roster is the first payload's players on T or CT, ordered by observer slot (then Steam id):
ids p00, p01, ... A player on T or CT with a position first seen later (one connecting in the
warm-up or mid-match) joins: he gets the next id, his samples are kept from then on and
`roster_changed` is set, but nothing of him is sampled (nor any event naming him) until
`reopen()` takes him into the roster for the next session (live_session.drive_sessions: a
session's players are fixed when it opens). One without a position, or on no team, is counted
in `unknown`.

Kills. GSI carries no death event and no victim's id: a kill is read off the scoreboard. A player
whose match_stats.kills rose killed someone; one whose deaths rose, or whose health fell to 0, died.
When one payload holds exactly one kill and one death on the other team, that is a KILL (attacker,
victim, at the victim's feet). Otherwise the pairing is unknown and each death is a CUSTOM event
"died" of the victim, each kill a CUSTOM event "kill, victim unknown" of the killer (a kill on the
wire must name its victim). A suicide or a death to the world shows as a death alone.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from camdirector.bridges.gsi import TEAMS, GsiPayload, GsiPlayer
from camdirector.evaluation.match.match_file import MatchPlayer
from camdirector.matches.cs2_demo import ITEM_DEFUSER, ITEM_HELMET, PLAYER_HEIGHT_M, PLAYER_RADIUS_M, source_points_to_world

RECENT_BODIES = 32  # digests of accepted bodies remembered to spot a resent payload


@dataclass(frozen=True)
class DerivedEvent:
    """A game event read off two payloads: kind "kill" (actor killed other), "death" (actor died,
    killer unknown) or "kill_unknown" (actor killed someone unknown); position_world (3,) m."""

    kind: str
    actor_id: str
    other_id: str
    position_world: np.ndarray

    def names_only(self, ids: set[str]) -> bool:
        """Whether every player it names is among ids (a session refuses an event naming another)."""
        return {self.actor_id, self.other_id} - {""} <= ids


@dataclass
class Sample:
    """The players at one moment: ids (n,), positions_world (n, 3) m at the feet, yaw_deg (n,)
    Source yaw; stats: (id, health, armor, items, frags) of the players whose values changed since
    the last sample; events since the last sample; stale: no payload for hold_s; source_time_s:
    the feed's own clock at the moment sampled, s, where it has one (QTV: the stream's demo time
    the players were sampled at; program_record.py places a program on the match by it); started:
    False before the feed's first sample is due (the playout delay after it came): nothing moves
    yet, so the driver sends no frame (live_session.py), and none of the rest is taken."""

    ids: list[str]
    positions_world: np.ndarray
    yaw_deg: np.ndarray
    stats: list[tuple[str, int, int, int, int]]
    events: list[DerivedEvent]
    stale: bool
    source_time_s: float | None = None
    started: bool = True

    @classmethod
    def not_started(cls, stale: bool) -> Sample:
        """A sample before the feed's first is due: no players, nothing else taken."""
        return cls([], np.zeros((0, 3)), np.zeros(0), [], [], stale, started=False)


@dataclass
class OfferCounts:
    """What became of the payloads offered: accepted, duplicate, out_of_order, unknown (players
    outside the roster, summed over payloads)."""

    accepted: int = 0
    duplicate: int = 0
    out_of_order: int = 0
    unknown: int = 0


def _yaw_deg(forward: np.ndarray | None) -> float:
    return 0.0 if forward is None else float(np.degrees(np.arctan2(forward[1], forward[0])))


def _items(p: GsiPlayer) -> int:
    return (ITEM_HELMET if p.helmet else 0) | (ITEM_DEFUSER if p.defusekit else 0)


@dataclass
class GsiTracks:
    """The store (module docstring); thread-safe: the HTTP endpoint offers, the driver samples."""

    interp_delay_s: float
    hold_s: float
    counts: OfferCounts = field(default_factory=OfferCounts)
    roster: list[MatchPlayer] = field(default_factory=list)
    _steamids: dict[str, int] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _has_roster: threading.Event = field(default_factory=threading.Event)
    roster_changed: threading.Event = field(default_factory=threading.Event)  # a player joined: reopen() takes him in
    _joined: list[MatchPlayer] = field(default_factory=list)  # after the roster, in the order they joined
    _recent: deque[bytes] = field(default_factory=lambda: deque(maxlen=RECENT_BODIES))
    _newest_stamp_s: int = -1
    _last_accept_s: float = float("-inf")
    _first_s: float = float("inf")  # arrival of the roster's payload (the first sampled), monotonic s
    _t: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (n, 2) s: older, newer sample
    _p: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))  # (n, 2, 3) m
    _yaw: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (n, 2) deg
    _last: dict[str, GsiPlayer] = field(default_factory=dict)
    _stats_sent: dict[str, tuple[int, int, int, int]] = field(default_factory=dict)
    _events: list[DerivedEvent] = field(default_factory=list)

    def offer(self, payload: GsiPayload, digest: bytes, arrival_s: float) -> str:
        """Takes a payload that arrived at arrival_s (monotonic s) with the body's digest; returns
        "accepted", "duplicate" or "out_of_order" (module docstring)."""
        with self._lock:
            if digest in self._recent:
                self.counts.duplicate += 1
                return "duplicate"
            if payload.timestamp_s < self._newest_stamp_s:
                self.counts.out_of_order += 1
                return "out_of_order"
            self._recent.append(digest)
            self._newest_stamp_s = payload.timestamp_s
            self._last_accept_s = arrival_s
            self.counts.accepted += 1
            if not self.roster:
                self._start_roster(payload, arrival_s)
            self._take(payload, arrival_s)
            return "accepted"

    def wait_roster(self, timeout_s: float | None = None) -> bool:
        """Whether a payload with players came (waiting up to timeout_s)."""
        return self._has_roster.wait(timeout_s)

    def _start_roster(self, payload: GsiPayload, arrival_s: float) -> None:
        placed = sorted(
            (p for p in payload.players if p.position_units is not None),
            key=lambda p: (p.observer_slot, p.steamid),
        )
        if not placed:
            return
        self.roster = [self._track(p, arrival_s) for p in placed]
        self._first_s = arrival_s
        self._has_roster.set()

    def _take(self, payload: GsiPayload, arrival_s: float) -> None:
        killers, victims = [], []
        for p in payload.players:
            i = self._steamids.get(p.steamid)
            if i is None and p.position_units is not None and p.team in TEAMS:
                i = self._join(p, arrival_s)
            if i is None:
                self.counts.unknown += 1
                continue
            if p.position_units is not None and arrival_s > self._t[i, 1]:
                self._t[i] = (self._t[i, 1], arrival_s)
                self._p[i] = (self._p[i, 1], source_points_to_world(p.position_units))
                self._yaw[i] = (self._yaw[i, 1], _yaw_deg(p.forward))
            before = self._last.get(p.steamid)
            if before is not None:
                killers += [i] * max(0, p.kills - before.kills)
                if p.deaths > before.deaths or (before.health > 0 and p.health <= 0):
                    victims.append(i)
            self._last[p.steamid] = p
        self._events += self._kills(killers, victims)

    def _track(self, p: GsiPlayer, arrival_s: float) -> MatchPlayer:
        """Tracks p from arrival_s on as the next id (his first sample twice: held until the next
        comes); his player."""
        i = len(self._steamids)
        self._steamids[p.steamid] = i
        feet = source_points_to_world(np.asarray(p.position_units, dtype=np.float64))
        self._t = np.vstack([self._t, [arrival_s, arrival_s]])
        self._p = np.concatenate([self._p, np.repeat(feet[None, None, :], 2, axis=1)])
        self._yaw = np.vstack([self._yaw, [_yaw_deg(p.forward)] * 2])
        return MatchPlayer(f"p{i:02d}", TEAMS[p.team], PLAYER_HEIGHT_M, PLAYER_RADIUS_M, p.name, p.team)

    def _join(self, p: GsiPlayer, arrival_s: float) -> int:
        """Takes p in as a joiner (module docstring); his index in the tracks."""
        self._joined.append(self._track(p, arrival_s))
        self.roster_changed.set()
        return len(self._steamids) - 1

    def reopen(self) -> list[MatchPlayer]:
        """The players who joined since (module docstring), now in the roster; clears roster_changed."""
        with self._lock:
            joined, self._joined = self._joined, []
            self.roster = [*self.roster, *joined]
            self.roster_changed.clear()
            return joined

    def _kills(self, killers: list[int], victims: list[int]) -> list[DerivedEvent]:
        players = [*self.roster, *self._joined]  # the tracks' order
        ids = [m.id for m in players]
        if len(killers) == 1 and len(victims) == 1 and players[killers[0]].team != players[victims[0]].team:
            return [DerivedEvent("kill", ids[killers[0]], ids[victims[0]], self._p[victims[0], 1].copy())]
        return [DerivedEvent("death", ids[v], "", self._p[v, 1].copy()) for v in victims] + [
            DerivedEvent("kill_unknown", ids[k], "", self._p[k, 1].copy()) for k in killers
        ]

    def sample(self, now_s: float) -> Sample:
        """The players at now_s (monotonic s), module docstring; the events and changed stats since
        the last sample go with it, once."""
        with self._lock:
            at_s = now_s - self.interp_delay_s
            stale = now_s - self._last_accept_s > self.hold_s
            if at_s < self._first_s:  # the first payload's own moment not yet due
                return Sample.not_started(stale)
            span = self._t[:, 1] - self._t[:, 0]
            alpha = np.clip((at_s - self._t[:, 0]) / np.where(span > 0, span, 1.0), 0.0, 1.0)
            alpha = np.where(span > 0, alpha, 1.0)
            positions = self._p[:, 0] + alpha[:, None] * (self._p[:, 1] - self._p[:, 0])
            turn = (self._yaw[:, 1] - self._yaw[:, 0] + 180.0) % 360.0 - 180.0  # the short way round
            yaw = self._yaw[:, 0] + alpha * turn
            stats = []
            for m, steamid in zip(self.roster, self._steamids):  # dicts keep the roster's order
                p = self._last.get(steamid)
                if p is None:
                    continue
                values = (p.health, p.armor, _items(p), p.kills)
                if self._stats_sent.get(m.id) != values:
                    self._stats_sent[m.id] = values
                    stats.append((m.id, *values))
            in_session = {m.id for m in self.roster}
            events = [e for e in self._events if e.names_only(in_session)]  # a joiner's wait out, as he does
            self._events = []
            n = len(self.roster)
            return Sample([m.id for m in self.roster], positions[:n], yaw[:n], stats, events, stale)
