"""PLAN: our director (registry name "planned"). With a delay it plans the program over the buffered future; it always
chooses among the situations of the moment by interest.

Planned beats (delay > 0): the events of priority >= `beat_min_priority` (kills, objectives) in
the buffered future, in time order, each with the shot that shows it (a kill: DUEL of attacker and
victim). A beat is shown by cutting `lead_s` before it (never earlier than `max_lead_s`, never in
the last `min_lead_s`), held `event_hold_s` after it, and no shot under the style's `min_shot_s`;
within those bounds the cut moves off the players' jumps through walls, where a camera on them
cuts within its shot (`_around_jumps`).
An event whose players the previous beat's shot already shows extends that beat; one that cannot
get its own cut (too close after the previous) joins the previous beat as a GROUP when the players
fit in `max_group`, stand within `join_spread_max_m` of each other (a shot of players farther apart
shows them too small to read: on the open nav_test, joins of players 24 m apart made the median
shown height 0.066 of the frame, 0.18 without them, for kill coverage 0.885 -> 0.738), and
some place of the GROUP camera sees them all (`min_visible`) at the
events' moments (on open ground two nearby fights share a shot; in corridors a GROUP of players
far apart puts the camera so far back that walls hide them all), else as a high wide OVERVIEW
of them all when one of its cameras (above them, or a node of the level's graph) sees them all
(two fights in neighbouring corridors, seen from above or from the level's open spaces: on
nav_test at a 10 s delay, kill coverage 0.81 -> 0.86); the answers are cached per group and
events, so the re-plan at every tick does not cast again; else it takes the previous beat's
place when it has the higher priority (a kill over an objective) and that beat's cut is still to
come (or the current shot shows it: its hold gives way), else it is left out (flagged). A beat that could
have its own cut joins the previous one the same way when that cut would end the previous shot
short of `preferred_shot_s` (at a 10 s delay on zdm2, kills 2.7 s apart made the median shot 2.7 s; with
the joins it is 3.7 s, kill coverage 0.89 -> 0.87). The
current shot holds only its events that are past or within `min_lead_s`. Only the first beat acts
now; the plan is made again at every planning tick, so a late event changes it. The camera of a planned shot is
placed for the moments of its events (shots.py), and, with less weight, `PRE_EVENT_S` before
the first: the event is what must be seen.

Between beats the director may cut at its discretion, once the shot is `min_shot_s` old, when no
planned cut is nearer than `min_shot_s` (the new shot would be too short), and only when the shot
is `max_shot_s` old, or shows a subject dead for `dead_hold_s`, or a situation is better than the
shot's by `switch_margin` and the shot is `settle_s` old (hysteresis: without a delay, interest
flickers as players turn, and a cut at every flicker makes 2-s shots). Where the player whose jump
moves the shot's camera (its eyes, its Toric anchor) jumps through the level, the rig cuts within
the shot anyway and asks at once (rig.py `_mover_jumped`): then any situation at least as good as
the shot's is taken, however young the shot, unless it holds for its events
(`_camera_jumps_now`). Its situations: situations.py.

Its shots' cameras come from the shot builder (shot_builder.py); between cuts the rig re-places
an occluded camera of its shot (replacement.py, `replaces_occluded_places`), and its plan is drawn
at one tick and applied at the next, computed off the frame path (drawn_plan.py, `plans_ahead`).
`PlannedDirector` implements `MatchDirector` (director_contract.py) with every capability; it is
registered as "planned" (director_registry.py).

Instant replays: where the live decision keeps the shot a moment after a kill, or cuts at its
discretion (not for a planned beat), and the live timeline has room, the director shows the kill
again from another angle (a REPLAY, replays.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.pipeline.inputs import EventKind, GameEvent
from camdirector.pipeline.match.director_contract import DirectorBase, DirectorContext
from camdirector.pipeline.match.frame import PlannedCut, ShotChoice, ShotKind
from camdirector.pipeline.match.interest import event_priority
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import Shot, camera_jumps_at, camera_movers
from camdirector.pipeline.match.replays import DirectorReplays, Replays, is_replay
from camdirector.pipeline.match.shots import poses_seen
from camdirector.pipeline.style import Style

OPTION_COVER_S = (1.0, 2.0, 3.0)  # a discretionary shot is placed for now and these times ahead (as far
# as the buffer reaches: a shot lasts 2 s at least, 4 s before it may be bettered), s
MAX_UNSEEN_FIGHTS = 2  # fights a decision tries and passes over as unseen before it takes a player
MIN_SWITCH_GAIN = 0.05  # a better situation must gain at least this much (situations.py)
PRE_EVENT_S = 0.5  # a planned shot's camera is also scored this long before its event, s
PRE_EVENT_WEIGHT = 0.25  # with this weight against 1 for each event's own moment
POST_EVENT_S = 0.1  # and this long after it (the next frame, at 10 Hz and more), s
JUMP_TICKS = 3  # a cut in place of a shot's jump is planned this many planning ticks before it (_around_jumps: one
# for the tick it waits, two for a drawn plan applied a tick late, rig.py)


@dataclass
class Beat:
    """Planned: the events one shot shows, from the first event's time to the last's."""

    kind: ShotKind
    subjects: tuple[int, ...]
    time_s: float
    last_time_s: float
    priority: int
    reason: str
    cut_s: float | None = None  # None: the current shot already shows it
    times_s: list[float] = field(default_factory=list)  # every event it shows, s

    def add(self, event_s: float, priority: int) -> None:
        self.times_s.append(event_s)
        self.last_time_s, self.priority = event_s, max(self.priority, priority)


@dataclass(frozen=True)
class _OnAir:
    """The shot on air as a plan made at now_s sees it: from start_s, holding its events until
    free_s, showing `shows`; `movers`, the players whose jump moves its camera (camera_movers)."""

    buffer: MomentBuffer
    now_s: float
    start_s: float
    free_s: float
    shows: set[int]
    movers: tuple[int, ...]


def beat_movers(beat: Beat) -> tuple[int, ...]:
    """camera_movers of a planned beat's shot, whichever camera it gets: its kept player (a
    DUEL's killer, a FOLLOW's player) is the eyes or the anchor of either; a GROUP's or an
    OVERVIEW's camera is not known before it is built."""
    return beat.subjects[:1] if beat.kind in (ShotKind.DUEL, ShotKind.FOLLOW) else ()


class PlannedDirector(DirectorBase):
    """Our director (module docstring), made from the rig's context (director_contract.py)."""

    plans_ahead = True
    replaces_occluded_places = True

    def __init__(self, context: DirectorContext):
        self.players, self.teams, self.settings = context.players, context.teams, context.settings
        self.index = {p: i for i, p in enumerate(self.players)}
        self.builder, self.situations = context.builder, context.situations
        self.delay_s = context.delay_s
        self.dead_since: dict[int, float] = {}
        self.plan: list[Beat] = []  # the beats of the last decision (planned_cuts)
        self._seen: dict[tuple[ShotKind, tuple[int, ...], tuple[float, ...]], bool] = {}  # _shot_sees' answers
        self.replays = DirectorReplays(Replays(self.players, self.builder))

    @property
    def style(self) -> Style:
        return self.builder.style

    def planned_cuts(self) -> list[PlannedCut]:
        """The cuts of the last decision's beats (the current shot's own beat has none)."""
        return [
            PlannedCut(b.cut_s, ShotChoice(tuple(self.players[i] for i in b.subjects), b.kind, "planned " + b.reason))
            for b in self.plan
            if b.cut_s is not None
        ]

    def _overview_shows(self, moment: Moment, pose: CameraPose) -> float:
        """The share of its sample points the best-shown living player has in an overview's frame
        and seen from its pose now (framed_seen; 1 with nobody alive). An overview of nobody in
        particular on air is worth that share of its interest: one that shows nobody gives way to
        a roaming FOLLOW once it has settled (an overview framing a beat's players is the plan's).
        Issue 41: on the real duel's first 3 minutes its overviews showed their best player 0.43
        of their frames, two thirds of the program's lost visibility, and no FOLLOW's interest
        bettered an overview's by the switch margin, so each lasted max_shot_s."""
        living = tuple(int(i) for i in np.flatnonzero(moment.alive))
        if not living:
            return 1.0
        lens = Lens(pose.vertical_fov_deg, self.builder.lens.aspect)
        return float(poses_seen(self.builder.visibility, moment, living, [pose], lens).max())

    # -- planned beats ----------------------------------------------------------------------
    def _event_shot(self, event: GameEvent) -> tuple[ShotKind, tuple[int, ...]] | None:
        actor, other = self.index.get(event.actor_id), self.index.get(event.other_actor_id)
        if event.kind in (EventKind.KILL, EventKind.DAMAGE) and actor is not None and other is not None and actor != other:
            return ShotKind.DUEL, (actor, other)
        subject = actor if actor is not None else other
        return None if subject is None else (ShotKind.FOLLOW, (subject,))

    def beats(self, moment: Moment, buffer: MomentBuffer, current: Shot | None) -> tuple[list[Beat], int]:
        """The planned beats over the buffered future with their cut times, and how many events
        were left out (module docstring)."""
        s = self.settings
        now = moment.time_s
        horizon = min(buffer.horizon_s, now + s.lookahead_s)
        start = current.start_s if current is not None else -math.inf
        # The current shot's events that are past or within min_lead_s stay on screen their hold (a
        # cut at the very moment of a kill it was placed for lost that kill: the re-plan no longer
        # sees it ahead). Its later events hold nothing here: they are beats like any other, in
        # time order, so an earlier kill elsewhere still gets its cut.
        shown_soon = [t for t in (current.cover_times_s if current is not None else ()) if t <= now + s.min_lead_s]
        free = max(now, max(shown_soon) + s.event_hold_s) if shown_soon else now
        shows = set(current.subjects) if current is not None else set()
        on_air = _OnAir(buffer, now, start, free, shows, () if current is None else camera_movers(current.camera))
        beats: list[Beat] = []
        dropped = 0
        for event in buffer.events_between(now, horizon):
            priority = event_priority(event, s)
            shot = self._event_shot(event) if priority >= s.beat_min_priority else None
            if shot is None:
                continue
            kind, subjects = shot
            what = f"{event.kind.name.lower()} in {event.time_s - now:.1f} s: {' -> '.join(self.players[i] for i in subjects)}"
            if beats and set(subjects) <= set(beats[-1].subjects):
                beats[-1].add(event.time_s, priority)
                continue
            beat = Beat(kind, subjects, event.time_s, event.time_s, priority, what, times_s=[event.time_s])
            if not beats and set(subjects) <= shows and event.time_s - start <= s.max_held_shot_s:
                # the current shot shows it: no cut (up to max_held_shot_s: a duel's players are in every kill)
                beats.append(beat)
                continue
            last = beats[-1] if beats else None
            beat.cut_s = self._beat_cut(beat, last, on_air)
            if beat.cut_s is not None:
                # a cut that would end the shot before it short of preferred_shot_s: one shot of both, when one sees them all
                before_s = start if last is None or last.cut_s is None else last.cut_s
                if not (beat.cut_s - before_s < s.preferred_shot_s and self._join(last, beat, on_air)):
                    beats.append(beat)
                continue
            # no cut of its own: join the previous beat, take its place, or be left out
            if self._join(last, beat, on_air):
                continue
            if last is not None and priority > last.priority:
                if last.cut_s is not None:
                    beat.cut_s = self._beat_cut(beat, beats[-2] if len(beats) > 1 else None, on_air)
                else:  # the current shot shows the lesser event (the first beat): its hold gives way
                    beat.cut_s = self._cut_time(beat.time_s, start, now, on_air, on_air.movers, beat_movers(beat))
                if beat.cut_s is not None:
                    dropped += len(last.times_s)
                    beats[-1] = beat
                    continue
            dropped += 1
        return beats, dropped

    def _join(self, last: Beat | None, beat: Beat, on_air: _OnAir) -> bool:
        """Makes the previous beat show the new one's event too, as a GROUP or else an OVERVIEW of
        all their players, when they fit in max_group, stand within join_spread_max_m of each
        other at the events' moments, and one such shot sees them all then (_shot_sees); whether
        it did."""
        if last is None:
            return False
        buffer, now_s = on_air.buffer, on_air.now_s
        union = tuple(dict.fromkeys((*last.subjects, *beat.subjects)))
        times_s = [*last.times_s, beat.time_s]
        if self._spread_m(union, times_s, buffer) > self.settings.join_spread_max_m:
            return False
        joint = (
            None
            if len(union) > self.settings.max_group
            else next((k for k in (ShotKind.GROUP, ShotKind.OVERVIEW) if self._shot_sees(k, union, times_s, buffer, now_s)), None)
        )
        if joint is None:
            return False
        last.subjects, last.kind, last.reason = union, joint, last.reason + "; and " + beat.reason
        last.add(beat.time_s, beat.priority)
        if last.cut_s is None and not set(union) <= on_air.shows:  # the current shot no longer shows it all
            last.cut_s = self._cut_time(last.time_s, on_air.start_s, on_air.free_s, on_air, on_air.movers, beat_movers(last))
        return True

    @staticmethod
    def _spread_m(players: tuple[int, ...], times_s: list[float], buffer: MomentBuffer) -> float:
        """The greatest distance between two of the players' aim points at any of the moments, m."""
        aims = np.stack([buffer.at(t).aims_world[list(players)] for t in times_s])  # (t, p, 3)
        return float(np.linalg.norm(aims[:, :, None] - aims[:, None, :], axis=3).max())

    def _beat_cut(self, beat: Beat, previous: Beat | None, on_air: _OnAir) -> float | None:
        """The cut time of a beat after the previous planned one (None: after the current shot)."""
        previous_start = on_air.start_s if previous is None or previous.cut_s is None else previous.cut_s
        free = on_air.free_s if previous is None else previous.last_time_s + self.settings.event_hold_s
        leaving = on_air.movers if previous is None or previous.cut_s is None else beat_movers(previous)
        return self._cut_time(beat.time_s, previous_start, free, on_air, leaving, beat_movers(beat))

    def _shot_sees(
        self, kind: ShotKind, subjects: tuple[int, ...], times_s: list[float], buffer: MomentBuffer, now_s: float
    ) -> bool:
        """Whether a shot of the kind (GROUP or OVERVIEW) has a place that sees every subject (min_visible) at the events'
        moments, cached per subjects and times (module docstring)."""
        key = (kind, subjects, tuple(times_s))
        if key not in self._seen:
            cover, weights = self.event_cover(buffer, now_s, times_s)
            score = self.builder.place_score(kind, subjects, buffer.at(times_s[0]), cover, weights)
            self._seen[key] = score >= self.settings.min_visible
        return self._seen[key]

    @staticmethod
    def event_cover(buffer: MomentBuffer, now_s: float, times_s: list[float]) -> tuple[list[Moment], list[float]]:
        """The moments a shot planned for events at times_s is placed for, with their weights:
        PRE_EVENT_S before the first (not before now), and each event's own moment and
        POST_EVENT_S after it (buffer.at is the moment at or before a time; the kill is on screen
        at the next one, and a place seeing both at the one before alone was often at the edge
        of a wall: on the real 4on4, 5 of 73 kills placed for at 1.0 were hidden a frame later)."""
        cover = [buffer.at(max(now_s, times_s[0] - PRE_EVENT_S))]
        cover += [buffer.at(t + after_s) for t in times_s for after_s in (0.0, POST_EVENT_S)]
        return cover, [PRE_EVENT_WEIGHT] + [1.0] * (2 * len(times_s))

    def _cut_time(
        self,
        event_s: float,
        previous_start_s: float,
        free_s: float,
        on_air: _OnAir,
        leaving: tuple[int, ...],
        entering: tuple[int, ...],
    ) -> float | None:
        """When to cut for an event at event_s: lead_s before it, not before the previous shot is
        preferred_shot_s old (else min_shot_s: a shorter lead rather than a shorter shot; on the
        real 4on4, a kill every 2.5 s made the median shot 2.7 s), its hold is over, or max_lead_s
        before the event; None when that is within min_lead_s of the event. Moved within those
        bounds by the players' jumps (`_around_jumps`): `leaving` and `entering`, the players whose
        jump moves the camera of the shot it ends and of the new one (camera_movers)."""
        s = self.settings
        latest = event_s - s.min_lead_s
        for shot_s in dict.fromkeys((max(s.preferred_shot_s, self.style.min_shot_s), self.style.min_shot_s)):
            cut = max(on_air.now_s, previous_start_s + shot_s, free_s, event_s - s.max_lead_s, event_s - s.lead_s)
            if cut <= latest:
                earliest = max(on_air.now_s, previous_start_s + self.style.min_shot_s, free_s, event_s - s.max_lead_s)
                return self._around_jumps(cut, earliest, latest, on_air.buffer, leaving, entering)
        return None

    def _around_jumps(
        self,
        cut_s: float,
        earliest_s: float,
        latest_s: float,
        buffer: MomentBuffer,
        leaving: tuple[int, ...],
        entering: tuple[int, ...],
    ) -> float:
        """A cut at cut_s moved, within [earliest_s, latest_s] (the shot it ends min_shot_s long
        at least), off the players' jumps through walls (teleports and respawns,
        MomentBuffer.jumps_s), where a camera through their eyes or anchored on them cuts within
        its shot (rig.py), s: after the
        new shot's camera's last jump before latest_s (its first picture is where it will be;
        not after the victim's: a DUEL's camera is most often its killer's eyes, and on the real
        2on2 a cut moved after a victim's jump let a wide fight shot take the kill) unless the
        ending shot's camera jumps before that, else ahead of the first jump of the ending
        shot's camera after earliest_s (the planned cut in its place, JUMP_TICKS planning ticks
        early as the window allows: a planned cut is made at the first tick at or after its
        time, and the plan is made again at each tick). On the real
        4on4's first 3 minutes, 11 of the 27 shots under 2 s were eyes shots cut by their
        player's jump a moment after they began or a moment before the next cut."""
        early_s = JUMP_TICKS * self.settings.plan_interval_s
        crosses = self.builder.visibility.ray_scene.occluded
        entering_jumps = buffer.jumps_s(entering, cut_s, latest_s, crosses)
        if entering_jumps and not buffer.jumps_s(leaving, earliest_s, entering_jumps[-1] + early_s, crosses):
            return entering_jumps[-1]
        leaving_jumps = buffer.jumps_s(leaving, earliest_s, cut_s + early_s, crosses)
        return max(leaving_jumps[0] - early_s, earliest_s) if leaving_jumps else cut_s

    # -- the decision -----------------------------------------------------------------------
    def decide(
        self, moment: Moment, buffer: MomentBuffer, current: Shot | None, current_pose: CameraPose | None, flags: list[str]
    ) -> Shot | None:
        """The shot to cut to now, or None to keep the current one: the live decision, a REPLAY
        where it keeps the shot and the timeline has room, and a replay held to its end (replays.py)."""
        self.replays.saw(moment, current_pose, current)
        if is_replay(current):
            assert current is not None  # is_replay names a shot
            if not self.replays.ends(moment, buffer, current):
                self.plan = []  # the live plan is made again when the replay ends
                return None
            current = None  # the replay gives the program back: the live decision starts afresh
        shot = self.live_decision(moment, buffer, current, current_pose, flags)
        if shot is not None and shot.cover_times_s:
            return shot  # a planned beat's cut
        # where the live decision keeps the shot or cuts at its discretion, a replay may come first
        # (its discretionary shot waits: the live decision starts afresh after the replay)
        replay = self.replays.insert(moment, buffer, current, flags)
        return replay if replay is not None else shot

    def _camera_jumps_now(self, current: Shot, buffer: MomentBuffer, now_s: float) -> bool:
        """Whether the player whose jump moves the shot on air's camera (camera_movers: its eyes,
        its Toric anchor) jumps through the level at the moment now_s, s (a teleport, a respawn:
        MomentBuffer.jumps_s), where the rig cuts within the shot anyway (`cut_through_wall`)
        and asks for a decision at once (rig.py `_mover_jumped`): the cut goes to the best
        situation then, not on into the same shot from wherever the jump took its camera (on the
        real 4on4, a pair's DUEL that the match's start split 50 m apart went on into three cuts
        through walls in 2 s)."""
        crosses = self.builder.visibility.ray_scene.occluded
        return not is_replay(current) and camera_jumps_at(current.camera, buffer, now_s, crosses)

    def live_decision(
        self, moment: Moment, buffer: MomentBuffer, current: Shot | None, current_pose: CameraPose | None, flags: list[str]
    ) -> Shot | None:
        """The live shot to cut to now, or None to keep the current one."""
        s, style = self.settings, self.style
        now = moment.time_s
        for i in range(len(self.players)):
            if moment.alive[i]:
                self.dead_since.pop(i, None)
            else:
                self.dead_since.setdefault(i, now)
        self._seen = {k: v for k, v in self._seen.items() if k[2][0] >= now}  # past events: never asked again
        beats, dropped = self.beats(moment, buffer, current)
        self.plan = beats
        if dropped:
            flags.append(f"plan_events_left_out_{dropped}")
        first = beats[0] if beats else None
        if first is not None and first.cut_s is None:
            assert current is not None  # a beat without a cut is one the current shot shows
            current.hold_until_s = max(current.hold_until_s, first.last_time_s + s.event_hold_s)
            current.cover_times_s = sorted(set(current.cover_times_s) | set(first.times_s))
        elif first is not None and first.cut_s is not None and first.cut_s <= now + 1e-9:
            choice = ShotChoice(tuple(self.players[i] for i in first.subjects), first.kind, "planned " + first.reason)
            cover, weights = self.event_cover(buffer, now, first.times_s)
            shot, seen = self.builder.build(
                choice, first.subjects, moment, cover, current, current_pose, now, weights, tuple(first.times_s), buffer
            )
            if shot is not None:
                shot.hold_until_s, shot.cover_times_s = first.last_time_s + s.event_hold_s, list(first.times_s)
                shot.scores = {"priority": float(first.priority), "lead_s": first.time_s - now, "place_visibility": seen}
                return shot
            flags.append("plan_no_place_for_grammar")
        length_s = math.inf if current is None else now - current.start_s
        jumped = current is not None and self._camera_jumps_now(current, buffer, now)
        # a shot whose camera cuts now anyway is as short kept as left (but one holding for its events)
        if current is not None and ((length_s < style.min_shot_s and not jumped) or now < current.hold_until_s):
            return None
        next_cut = min((b.cut_s for b in beats if b.cut_s is not None), default=math.inf)
        if current is not None and next_cut - now < style.min_shot_s:
            flags.append("plan_holding_for_planned_cut")
            return None
        options = self.situations.options(moment, buffer)
        current_set = set(current.subjects) if current is not None else None
        current_kind = current.choice.kind if current is not None else None
        current_score = next((o.score for o in options if set(o.subjects) == current_set and o.kind == current_kind), 0.0)
        if current is not None and current_kind == ShotKind.OVERVIEW and not current.subjects and current_pose is not None:
            current_score *= self._overview_shows(moment, current_pose)  # an overview of nobody: of whom it shows
        dead_too_long = current is not None and any(
            now - self.dead_since.get(i, math.inf) >= s.dead_hold_s for i in current.subjects
        )
        skipped = 0
        for option in options:
            if current is not None and set(option.subjects) == current_set and option.kind == current_kind:
                continue
            better = option.score > current_score * (1.0 + s.switch_margin) + MIN_SWITCH_GAIN and length_s >= s.settle_s
            if jumped:  # its camera cuts now anyway: no hysteresis to pay for
                better = option.score >= current_score
            if not (current is None or length_s >= style.max_shot_s or dead_too_long or better):
                return None
            why = (
                "max shot length"
                if current is not None and length_s >= style.max_shot_s
                else "subject dead"
                if dead_too_long
                else "its camera's player jumped"
                if jumped
                else "better situation"
            )
            choice = ShotChoice(tuple(self.players[i] for i in option.subjects), option.kind, f"{option.reason} ({why})")
            if len(option.subjects) > 1 and skipped >= MAX_UNSEEN_FIGHTS:
                continue  # a plan's cost stays bounded: each try is a place search
            cover = [moment] + [buffer.at(now + ahead_s) for ahead_s in OPTION_COVER_S if now + ahead_s <= buffer.horizon_s]
            # the buffer: a FOLLOW's eyes give way to its Toric camera where that meets no wall (first_person.py)
            shot, seen = self.builder.build(choice, option.subjects, moment, cover, current, current_pose, now, buffer=buffer)
            if shot is not None and seen < s.min_visible and len(option.subjects) > 1:
                # a fight no place sees (no kill to wait for): one of its players, a later option, shows more
                # (on the real 4on4, such DUELs were 7% of the program, their players shown 0.54)
                flags.append("fight_unseen_skipped")
                skipped += 1
                continue
            if shot is not None:
                shot.scores = {"interest": option.score, "current_interest": current_score, "place_visibility": seen}
                return shot
        return None
