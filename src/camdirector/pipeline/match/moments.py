"""The buffered game moments of a match: every frame's players, who is alive, and the events.

With a broadcast delay D the program shows the game moment t - D while frames up to t have
arrived, so the moments in between are the known future the director plans over (issue 12,
"Delay semantics"). Each moment keeps the players' transforms, aim points, feet and horizontal
facing as arrays in target order.

Who is alive: a player is dead from the time of a KILL event naming it as victim until it
respawns. A respawn is a teleport: between two frames its feet move at least `respawn_min_jump_m`
and faster than `respawn_speed_m_s`, however near the spawn point is to where it fell (a jump
threshold in metres alone missed spawns 2 m away and kept those players dead for the rest of the
match). A player respawned at the very spot it fell shows no teleport; once it stands
`respawn_walk_m` from there across the ground it has walked away, which a body does not. A body
that lies still, falls or is dragged a little stays dead. Events are applied to the first moment
whose time reaches theirs; an event announced late (its time before the newest moment) is applied
to the newest moment, the earliest the director can know it.
"""

from __future__ import annotations

import bisect
import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.inputs import EventKind, GameEvent
from camdirector.pipeline.match.settings import MatchSettings


@dataclass
class Moment:
    """One buffered frame. Arrays are in target order, n players."""

    frame: int
    time_s: float
    transforms: list[RigidTransform]
    aims_world: np.ndarray  # (n, 3) framed points (the target's aim offset), metres
    feet_world: np.ndarray  # (n, 3) transform positions, metres
    forward_world: np.ndarray  # (n, 3) horizontal unit facing (local +Z), metres/metre
    alive: np.ndarray  # (n,) bool
    events: list[GameEvent] = field(default_factory=list)  # applied at this moment
    # (n,) int64: each dead player's killer (its last KILL event's attacker), -1 where alive, killed by
    # itself or the world; None: nobody's known (a moment made without a buffer)
    killers: np.ndarray | None = None
    # its floats packed for pickling, once: a moment never changes once pushed (MomentBuffer.push)
    _floats: bytes | None = field(default=None, init=False, repr=False, compare=False)

    def __reduce__(self) -> tuple[Callable[..., Moment], tuple[object, ...]]:
        """Pickled as two byte strings: a session's snapshot holds every buffered moment (over a
        thousand at 60 Hz and a 10 s delay); as 29 numpy arrays each (8 players) 700 KB took
        60-190 ms to pickle, as three arrays each 55 us a moment (100 ms a snapshot of the 4on4 at
        60 Hz, the worker stalled that long every second); packed once, as every snapshot holds
        it again. The floats in order: each transform's position, rotation and scale (n, 10),
        then aims, feet and facing (3, n, 3)."""
        if self._floats is None:
            floats = np.concatenate(
                [a for t in self.transforms for a in (t.position_world, t.rotation_xyzw, t.scale)]
                + [self.aims_world.ravel(), self.feet_world.ravel(), self.forward_world.ravel()]
            )
            self._floats = floats.astype(np.float64, copy=False).tobytes()
        return _moment_of_bytes, (
            self.frame,
            self.time_s,
            len(self.transforms),
            self._floats,
            self.alive.tobytes(),
            self.events,
            None if self.killers is None else self.killers.astype(np.int64, copy=False).tobytes(),
        )


def _moment_of_bytes(
    frame: int, time_s: float, n: int, floats: bytes, alive: bytes, events: list[GameEvent], killers: bytes | None = None
) -> Moment:
    """Moment.__reduce__'s moment again, n players: its arrays are copies (writable, their own).
    A snapshot written before 2026-12-06 has no killers: none known."""
    values = np.frombuffer(floats, dtype=np.float64)
    rows, points = values[: n * 10].reshape(n, 10), values[n * 10 :].reshape(3, n, 3)
    moment = _unpacked_moment(frame, time_s, rows, points, np.frombuffer(alive, dtype=bool).copy(), events)
    moment.killers = None if killers is None else np.frombuffer(killers, dtype=np.int64).copy()
    moment._floats = floats  # packed already: the next snapshot writes these bytes again
    return moment


def _unpacked_moment(
    frame: int, time_s: float, transforms: np.ndarray, points: np.ndarray, alive: np.ndarray, events: list[GameEvent]
) -> Moment:
    """A moment of its arrays: transforms (n, 10) position, rotation, scale; points (3, n, 3) aims,
    feet, facing. Also how a snapshot written before 2026-12-02 gives each moment (a node of the
    new version restores sessions whose checkpoints the old one wrote)."""
    return Moment(
        frame,
        time_s,
        [RigidTransform(row[0:3].copy(), row[3:7].copy(), row[7:10].copy()) for row in transforms],
        points[0].copy(),
        points[1].copy(),
        points[2].copy(),
        alive,
        events,
    )


def horizontal_forward(rotations_xyzw: np.ndarray) -> np.ndarray:
    """(n, 3) unit horizontal local +Z of (n, 4) xyzw quaternions; +Z where the facing is vertical."""
    x, y, z, w = rotations_xyzw.T
    forward = np.stack([2.0 * (x * z + w * y), np.zeros_like(x), 1.0 - 2.0 * (x * x + y * y)], axis=1)
    norm = np.linalg.norm(forward, axis=1)
    flat = norm < 1e-6
    forward[flat] = (0.0, 0.0, 1.0)
    norm[flat] = 1.0
    unit: np.ndarray = forward / norm[:, None]
    return unit


COMPACT_AFTER = 32  # moments gone (before the program's) that the buffer drops at once
TIME_EPSILON_S = 1e-6  # frame times this close are the same instant (floating-point rounding of t - D), s


def _jumped(step_world: np.ndarray, dt_s: float | np.ndarray, settings: MatchSettings) -> np.ndarray:
    """(..., 3) feet steps over dt_s, s -> (...) bool: moved at least respawn_min_jump_m and
    faster than respawn_speed_m_s (a teleport, not a run: module docstring)."""
    step_m = np.linalg.norm(step_world, axis=-1)
    jumped: np.ndarray = (step_m >= settings.respawn_min_jump_m) & (step_m > settings.respawn_speed_m_s * dt_s)
    return jumped


class MomentBuffer:
    """The moments from `kept_past_s` before the program's moment (what a replay shows again,
    replays.py, and a replay the edit window starts early before it) to the newest frame, and the
    match's events."""

    def __init__(self, player_ids: list[str], settings: MatchSettings):
        self.player_ids = player_ids
        self.index = {p: i for i, p in enumerate(player_ids)}
        self.settings = settings
        self._fell_world = np.full((len(player_ids), 3), np.nan)  # (n, 3) feet at each dead player's death
        self.moments: list[Moment] = []
        self.times: list[float] = []
        self.events: list[GameEvent] = []  # every event, in time order (the planner reads ahead)
        self._event_times: list[float] = []
        self._pending: list[GameEvent] = []  # announced before their time, not yet applied
        self.killed_by: dict[str, str] = {}  # victim -> attacker of its last death
        self._start = 0  # the program moment's index: moments before it are past, kept for replays

    @property
    def newest(self) -> Moment | None:
        return self.moments[-1] if len(self.moments) > self._start else None

    def push(
        self, frame: int, time_s: float, transforms: list[RigidTransform], aims_world: list[np.ndarray], events: list[GameEvent]
    ) -> bool:
        """Adds the newest frame; False (nothing added) when it is not newer than the last one."""
        last = self.newest
        if last is not None and (frame <= last.frame or time_s < last.time_s):
            return False
        feet = np.array([t.position_world for t in transforms], dtype=np.float64)
        alive = np.ones(len(transforms), dtype=bool) if last is None else last.alive.copy()
        killers = np.full(len(transforms), -1, dtype=np.int64) if last is None or last.killers is None else last.killers.copy()
        if last is not None and not alive.all():
            s = self.settings
            teleported = _jumped(feet - last.feet_world, time_s - last.time_s, s)
            # across the ground: a body that falls off a ledge has not walked
            walked_away = np.linalg.norm((feet - self._fell_world)[:, [0, 2]], axis=1) >= s.respawn_walk_m  # NaN: False
            alive |= teleported | walked_away
            killers[alive] = -1
        for event in sorted(events, key=lambda e: e.time_s):
            position = bisect.bisect_right(self._event_times, event.time_s)
            self._event_times.insert(position, event.time_s)
            self.events.insert(position, event)
            self._pending.append(event)
        due = [e for e in self._pending if e.time_s <= time_s]
        self._pending = [e for e in self._pending if e.time_s > time_s]
        for event in due:
            if event.kind == EventKind.KILL and event.other_actor_id in self.index:
                victim = self.index[event.other_actor_id]
                self._fell_world[victim] = feet[victim]
                alive[victim] = False
                killers[victim] = -1
                if event.actor_id in self.index and event.actor_id != event.other_actor_id:
                    self.killed_by[event.other_actor_id] = event.actor_id
                    killers[victim] = self.index[event.actor_id]
        rotations = np.array([t.rotation_xyzw for t in transforms], dtype=np.float64)
        self.moments.append(
            Moment(
                frame,
                time_s,
                list(transforms),
                np.array(aims_world, dtype=np.float64),
                feet,
                horizontal_forward(rotations),
                alive,
                due,
                killers,
            )
        )
        self.times.append(time_s)
        return True

    def view(self) -> MomentBuffer:
        """What the buffer holds now, as a buffer that later frames leave as it is, for a plan
        drawn now and computed in slices later (rig.py): the lists and the killers copied, the
        moments themselves shared (a moment never changes once pushed). Read it only (at,
        horizon_s, program_s, events_between, killed_by)."""
        view = copy.copy(self)
        view.moments, view.times = list(self.moments), list(self.times)
        view.events, view._event_times = list(self.events), list(self._event_times)
        view.killed_by, view._pending = dict(self.killed_by), []
        return view

    def program_moment(self, time_s: float) -> Moment | None:
        """The moment nearest time_s (the program's moment, frame time minus the delay), dropping
        older ones; None while no moment is that old (the delay is still filling).

        Nearest, not newest at or before: t - D computed in floating point lands a hair before the
        frame it names about half the time, and "at or before" then showed the previous moment
        again and skipped one later (5-12% of moments repeated at delays of 10 and 30 s)."""
        i = bisect.bisect_right(self.times, time_s, lo=self._start) - 1
        if i < self._start:  # before the oldest moment: only a rounding hair before counts
            if self._start >= len(self.times) or self.times[self._start] - time_s > TIME_EPSILON_S:
                return None
            i = self._start
        elif i + 1 < len(self.times) and self.times[i + 1] - time_s < time_s - self.times[i]:
            i += 1
        self._start = i
        # compact now and then, not every frame: moments more than kept_past_s before the
        # program's are never read again, but a session's snapshot pickles what the buffer holds
        # (at 4096, up to 9 MB that took 1.5 s every 60 frames) and the garbage collector walks it
        gone = bisect.bisect_left(self.times, self.times[i] - self.settings.kept_past_s, hi=i)
        if gone > COMPACT_AFTER:
            del self.moments[:gone], self.times[:gone]
            self._start -= gone
        return self.moments[self._start]

    def nearest(self, time_s: float) -> Moment | None:
        """The moment nearest time_s among those kept (program_moment's rule, moving nothing);
        None while none is that old."""
        if not self.times or self.times[0] - time_s > TIME_EPSILON_S:
            return None
        i = max(bisect.bisect_right(self.times, time_s) - 1, 0)
        if i + 1 < len(self.times) and self.times[i + 1] - time_s < time_s - self.times[i]:
            i += 1
        return self.moments[i]

    def rewind(self, moment: Moment) -> None:
        """The program moment back to `moment`, a kept one (the edit window's, rig.py)."""
        i = bisect.bisect_left(self.times, moment.time_s)
        assert self.moments[i] is moment  # kept: the window is shorter than the past kept for replays
        self._start = i

    def at(self, time_s: float) -> Moment:
        """The buffered moment nearest at or before time_s, clamped to the buffer's ends (the
        past kept for replays included)."""
        i = bisect.bisect_right(self.times, time_s) - 1
        return self.moments[min(max(i, 0), len(self.moments) - 1)]

    def at_or_after(self, time_s: float) -> Moment:
        """The buffered moment nearest at or after time_s (within TIME_EPSILON_S), clamped to the
        buffer's ends: the program moment eval-match judges an event of time_s at, its first at
        or after it (one program moment a buffered one)."""
        i = bisect.bisect_left(self.times, time_s - TIME_EPSILON_S)
        return self.moments[min(i, len(self.moments) - 1)]

    @property
    def oldest_s(self) -> float:
        """Time of the oldest moment kept (the past a replay can show), s."""
        return self.times[0]

    def following(self, moment: Moment) -> Moment | None:
        """The moment buffered after `moment`, the program's (program_moment), None when it is the
        newest or not the program's."""
        i = self._start
        if i + 1 >= len(self.moments) or self.moments[i] is not moment:
            return None
        return self.moments[i + 1]

    @property
    def horizon_s(self) -> float:
        """Time of the newest moment (the end of the known future)."""
        return self.times[-1]

    def jumps_s(
        self,
        players: Sequence[int],
        start_s: float,
        end_s: float,
        crosses: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    ) -> list[float]:
        """Times of the moments in (start_s, end_s], s, at which one of the players jumped from
        the moment before: a teleport or a respawn (module docstring). With `crosses` ((n, 3)
        from, (n, 3) to, m -> (n,) bool: the level between them), only a jump whose aim points
        have level geometry between them: where a camera through that player's eyes or anchored
        on it passes through a wall, a cut within its shot (rig.py); a jump pad's is none."""
        lo = max(bisect.bisect_right(self.times, start_s), 1)
        hi = bisect.bisect_right(self.times, end_s)
        if hi <= lo or not players:
            return []
        columns = list(players)
        feet = np.array([m.feet_world[columns] for m in self.moments[lo - 1 : hi]])  # (k + 1, p, 3)
        dt_s = np.diff(self.times[lo - 1 : hi])[:, None]  # (k, 1)
        steps, movers = np.nonzero(_jumped(np.diff(feet, axis=0), dt_s, self.settings))
        if crosses is not None and len(steps):
            before = np.array([self.moments[lo - 1 + k].aims_world[columns[p]] for k, p in zip(steps, movers)])
            after = np.array([self.moments[lo + k].aims_world[columns[p]] for k, p in zip(steps, movers)])
            steps = steps[crosses(before, after)]
        return [self.times[lo + k] for k in sorted(set(steps.tolist()))]

    def events_between(self, start_s: float, end_s: float) -> list[GameEvent]:
        """Events with start_s < time_s <= end_s, in time order."""
        lo = bisect.bisect_right(self._event_times, start_s)
        hi = bisect.bisect_right(self._event_times, end_s)
        return self.events[lo:hi]

    def forget_events_before(self, time_s: float) -> None:
        """Drops events older than time_s (the planner never looks back further)."""
        n = bisect.bisect_left(self._event_times, time_s)
        if n > 1024:
            del self.events[:n], self._event_times[:n]
