"""PLAN: our director. With a delay it plans the program over the buffered future; it always
chooses among the situations of the moment by interest.

Planned beats (delay > 0): the events of priority >= `beat_min_priority` (kills, objectives) in
the buffered future, in time order, each with the shot that shows it (a kill: DUEL of attacker and
victim). A beat is shown by cutting `lead_s` before it (never earlier than `max_lead_s`, never in
the last `min_lead_s`), held `event_hold_s` after it, and no shot under the style's `min_shot_s`.
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
flickers as players turn, and a cut at every flicker makes 2-s shots). Situations (interest.py):
a DUEL per fighting pair, a FOLLOW per fighting player, a GROUP per cluster of fighters, a FOLLOW
of every other living player, and an OVERVIEW, below them all; with a delay, fights are
anticipated by reading the next 2 s of the buffer.

The shot's camera comes from shots.py with the grammar of grammar.py: the line of action of a
pair is kept, and a cut that shares subjects with the previous shot must turn 30 degrees. A DUEL
or GROUP (not a human's take) whose best place sees its subjects under `min_visible` over the
moments it must cover is shot as a level OVERVIEW of exactly those subjects when one of its
cameras (above them, or a node of the level's graph), allowed by the 30-degree rule, sees them
better; its reason says so ("wide: no level duel place sees both"). The level Toric pictures
cannot show a pair far apart along a corridor, seen only from above it over a shoulder, one
above the other (shots.py).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.pipeline.inputs import EventKind, GameEvent
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.grammar import Grammar
from camdirector.pipeline.match.interest import event_priority, fight_matrix, recent_event_boost
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import (
    PairWindow,
    Place,
    StaticCamera,
    ToricCamera,
    best_place,
    overview_pose,
    place_grid,
)
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.pipeline.style import Style

ANTICIPATION_STEPS_S = (0.5, 1.0, 1.5, 2.0)  # buffered future read for fights, s after the moment
ANTICIPATION_DISCOUNT = 0.9                  # a future fight counts this much of a present one
FOLLOW_SHARE = 0.5                           # one fighter alone is worth this share of its best fight
GROUP_SHARE = 0.6                            # a group: this share of its best fight, plus GROUP_EXTRA per extra player
GROUP_EXTRA = 0.1
OPTION_COVER_S = (1.0, 2.0, 3.0)             # a discretionary shot is placed for now and these times ahead (as far
                                             # as the buffer reaches: a shot lasts 2 s at least, 4 s before it may be bettered), s
MAX_UNSEEN_FIGHTS = 2                        # fights a decision tries and passes over as unseen before it takes a player
ROAM_FLOOR = 0.01                            # a player in no fight: the overview's score plus this,
ROAM_BONUS = 0.1                             # plus this times its nearness to an opponent
MIN_SWITCH_GAIN = 0.05                       # and a better situation must gain at least this much
PRE_EVENT_S = 0.5                            # a planned shot's camera is also scored this long before its event, s
PRE_EVENT_WEIGHT = 0.25                      # with this weight against 1 for each event's own moment
POST_EVENT_S = 0.1                           # and this long after it (the next frame, at 10 Hz and more), s
ALONE_GAP_S = 0.6                            # a killer alone this long before its pair's window is also placed for halfway, s
ALONE_AFTER_S = 0.5                          # and for this long after the window closes, s


@dataclass
class Shot:
    """The program's shot: whom and how (choice), the player indices, its camera, when it started
    (program time, s), until when it must hold for an event it shows, and its sub-scores."""

    choice: ShotChoice
    subjects: tuple[int, ...]
    camera: ToricCamera | StaticCamera
    start_s: float
    hold_until_s: float = -math.inf
    cover_times_s: list[float] = field(default_factory=list)  # the events it is planned to show (its camera is placed for them)
    scores: dict[str, float] = field(default_factory=dict)
    held: bool = False  # a human's take

    def framed(self, time_s: float) -> tuple[int, ...]:
        """The players its picture frames at time_s, s: its subjects, or the one its pair window keeps (shots.py)."""
        framed = self.camera.framed(time_s) if isinstance(self.camera, ToricCamera) else None
        return self.subjects if framed is None else framed


@dataclass
class Option:
    """A situation the director could show: kind, player indices, interest, why."""

    kind: ShotKind
    subjects: tuple[int, ...]
    score: float
    reason: str


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


class ShotBuilder:
    """Makes a shot's camera for a kind and subjects, placed by ray casts and the grammar."""

    def __init__(self, players: list[str], style: Style, lens: Lens, settings: MatchSettings,
                 visibility: SubjectVisibility, grammar: Grammar, extra_overview_cameras: np.ndarray):
        self.players, self.style, self.lens = players, style, lens
        self.settings, self.visibility, self.grammar = settings, visibility, grammar
        self.extra_overview_cameras = extra_overview_cameras

    @property
    def upright(self) -> float:
        """The sign of phi where the style's composition is upright (geometry/toric.py: seen from
        phi = +pi/2, A is on the left)."""
        return 1.0 if self.style.screen_a[0] <= self.style.screen_b[0] else -1.0

    def default_place(self) -> Place:
        return Place(self.style.preferred_theta_ratio, self.upright * math.radians(self.style.preferred_phi_deg))

    def cameras(self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment,
                default: bool) -> list[tuple[ToricCamera, list[Place]]]:
        """The Toric cameras a shot may use, each with the places to try (default: the style's only)."""
        if kind == ShotKind.FOLLOW:
            return [(ToricCamera(kind, subjects[0], None, self.style, self.lens, self.default_place()),
                     [self.default_place()] if default else place_grid(None))]
        if kind == ShotKind.DUEL:
            i, j = subjects
            left = self.grammar.duel_left(self.players[i], self.players[j])
            orders = [(i, j), (j, i)] if left is None else [(i, j) if self.players[i] == left else (j, i)]
        else:  # GROUP: the two players farthest apart frame the rest
            aims = moment.aims_world[list(subjects)]
            d = np.linalg.norm(aims[:, None] - aims[None], axis=2)
            a, b = np.unravel_index(int(np.argmax(d)), d.shape)
            orders = [(subjects[a], subjects[b]), (subjects[b], subjects[a])]
        grid = [self.default_place()] if default else place_grid(self.upright)
        return [(ToricCamera(kind, a, b, self.style, self.lens, self.default_place()), grid)
                for a, b in (orders[:1] if default else orders)]

    def _best(self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment, cover: list[Moment],
              weights: list[float] | None, allowed: Callable[[np.ndarray], np.ndarray] | None,
              pair: PairWindow | None = None) -> tuple[ToricCamera, Place, float]:
        """The camera (of those cameras() offers at the moment, with the pair window of a planned
        DUEL) and place that best see the subjects over cover, and its score (-1: the grammar
        refuses every place)."""
        best: tuple[ToricCamera, Place, float] | None = None
        for camera, places in self.cameras(kind, subjects, moment, default=False):
            camera.pair = pair
            place, score = best_place(camera, places, cover, subjects, self.visibility, allowed, moment, weights)
            if best is None or score > best[2]:
                best = (camera, place, score)
        return best

    def place_score(self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment, cover: list[Moment],
                    weights: list[float]) -> float:
        """How well the best place of a shot from the moment on sees the subjects over cover, [0, 1]."""
        if kind == ShotKind.OVERVIEW:
            return self._overview(subjects, cover, weights)[1]
        return self._best(kind, subjects, moment, cover, weights, None)[2]

    def _overview(self, subjects: tuple[int, ...], cover: list[Moment], weights: list[float],
                  allowed: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[CameraPose, float]:
        return overview_pose(cover, weights, subjects, self.lens, self.visibility, self.settings.overview_height_m,
                             self.extra_overview_cameras, allowed)

    def build(self, choice: ShotChoice, subjects: tuple[int, ...], moment: Moment, cover: list[Moment],
              previous: Shot | None, previous_pose: CameraPose | None, start_s: float,
              weights: list[float] | None = None, events_s: tuple[float, ...] = (),
              buffer: MomentBuffer | None = None) -> tuple[Shot | None, float]:
        """A shot showing `subjects` from `moment` on, placed for the moments in `cover` (with
        `weights`, default equal), respecting the 30-degree rule against the previous picture at
        `moment`; and its place's score. None (and -1) when no place respects the rule. A DUEL or
        GROUP whose best place scores under min_visible is a wide OVERVIEW of its subjects when
        one sees them better (module docstring).

        A DUEL planned for events at events_s, s, frames its pair around them only, its first
        subject (the killer) alone elsewhere (shots.py `PairWindow`). When the cut itself shows the
        killer alone, the pair's place is chosen for the events as before, without the 30-degree
        rule (the pair is not on screen at the cut), and the killer's own place from all of the
        grid for the moments it is alone (`_alone_cover`, read from `buffer`), with the rule."""
        if choice.kind == ShotKind.OVERVIEW:
            # everybody when nobody is named and nobody alive (all dead between rounds): a view of the map, not an error
            shown = subjects or tuple(int(i) for i in np.flatnonzero(moment.alive)) or tuple(range(len(moment.alive)))
            pose, seen = self._overview(shown, cover, [1.0] * len(cover) if weights is None else weights)
            return Shot(choice, subjects, StaticCamera(pose), start_s), seen
        previous_framed = set() if previous is None else set(previous.framed(moment.time_s))
        previous_world = None if previous_pose is None else previous_pose.position_world

        def allowed_after(framed: tuple[int, ...]) -> Callable[[np.ndarray], np.ndarray]:
            """The 30-degree rule for a cut from the previous picture to one framing `framed`."""
            shared = list(previous_framed & set(framed))
            return lambda positions: self.grammar.allows_cut(previous_world, moment.aims_world[shared], positions)

        s = self.settings
        pair = PairWindow(subjects[0], events_s, s.pair_before_s, s.pair_after_s, s.reframe_s) \
            if events_s and choice.kind == ShotKind.DUEL else None
        alone = pair is not None and buffer is not None and pair.weight(moment.time_s) <= 0.0
        allowed = allowed_after(subjects)
        camera, place, score = self._best(choice.kind, subjects, moment, cover, weights, None if alone else allowed,
                                          pair)
        if score < s.min_visible and not choice.held:  # a wide view of them may see them better
            pose, seen = self._overview(subjects, cover, [1.0] * len(cover) if weights is None else weights, allowed)
            # a killer shown alone until its kill sees more than a static view seeing the pair under min_visible
            if seen > max(score, 0.0) and (seen >= s.min_visible or not alone):
                what = "both" if choice.kind == ShotKind.DUEL else "them all"
                wide = replace(choice, kind=ShotKind.OVERVIEW,
                               reason=f"{choice.reason}; wide: no level {choice.kind.name.lower()} place sees {what}")
                return Shot(wide, subjects, StaticCamera(pose), start_s), seen
        if alone and score >= 0.0:
            keep = (pair.keep_index,)
            camera.pair = replace(pair, place=place)
            place, alone_score = best_place(camera, place_grid(None), self._alone_cover(pair, moment, buffer),
                                            keep, self.visibility, allowed_after(keep), moment)
            score = score if alone_score >= 0.0 else -1.0
        if score < 0.0:
            return None, -1.0
        camera.place = camera.goal = place
        if choice.kind == ShotKind.DUEL:
            self.grammar.remember_duel(self.players[camera.a_index], self.players[camera.b_index])
        return Shot(choice, subjects, camera, start_s), score

    @staticmethod
    def _alone_cover(pair: PairWindow, moment: Moment, buffer: MomentBuffer) -> list[Moment]:
        """The moments a planned DUEL's killer is framed alone, its own place is chosen for: the
        cut, halfway to the pair's window when that is over ALONE_GAP_S away, and ALONE_AFTER_S
        after the window closes when the buffer reaches it."""
        now = moment.time_s
        opens = pair.times_s[0] - pair.before_s - pair.ramp_s
        closed = pair.times_s[-1] + pair.after_s + pair.ramp_s + ALONE_AFTER_S
        times = [now] + ([0.5 * (now + opens)] if opens - now > ALONE_GAP_S else []) \
            + ([closed] if closed <= buffer.horizon_s else [])
        return [buffer.at(t) for t in times]


class PlannedDirector:
    """Our director (module docstring)."""

    def __init__(self, players: list[str], teams: np.ndarray, settings: MatchSettings, builder: ShotBuilder,
                 delay_s: float):
        self.players, self.teams, self.settings = players, teams, settings
        self.index = {p: i for i, p in enumerate(players)}
        self.builder = builder
        self.delay_s = delay_s
        self.dead_since: dict[int, float] = {}
        self.plan: list[Beat] = []  # the beats of the last decision (read for the dashboard, MatchRig.planned_cut)
        self._seen: dict[tuple[ShotKind, tuple[int, ...], tuple[float, ...]], bool] = {}  # _shot_sees' answers
        # the last options() answer, keyed by its moment's time and the buffer's horizon, s (a plan asks
        # twice: decide and the rig's candidates)
        self._options: tuple[tuple[float, float], list[Option]] | None = None

    @property
    def style(self) -> Style:
        return self.builder.style

    # -- situations -------------------------------------------------------------------------
    def options(self, moment: Moment, buffer: MomentBuffer) -> list[Option]:
        """Every situation worth showing at the moment, best first (module docstring)."""
        key = (moment.time_s, buffer.horizon_s)
        if self._options is None or self._options[0] != key:
            self._options = key, self._options_at(moment, buffer)
        return self._options[1]

    def _options_at(self, moment: Moment, buffer: MomentBuffer) -> list[Option]:
        s = self.settings
        now = moment.time_s
        ray_scene = self.builder.visibility.ray_scene
        fights = fight_matrix(moment, self.teams, s, ray_scene)
        for step_s in ANTICIPATION_STEPS_S:
            if now + step_s > buffer.horizon_s:
                break
            ahead = fight_matrix(buffer.at(now + step_s), self.teams, s, ray_scene) \
                * moment.alive[:, None] * moment.alive[None, :]
            fights = np.maximum(fights, ANTICIPATION_DISCOUNT * ahead)
        interest = fights + recent_event_boost(buffer.events_between(now - s.recent_event_s, now), self.index, now,
                                               len(self.players), s) * moment.alive[:, None] * moment.alive[None, :]
        options: list[Option] = []
        ii, jj = np.nonzero(np.triu(interest) > 0.0)
        for i, j in zip(ii.tolist(), jj.tolist()):
            options.append(Option(ShotKind.DUEL, (i, j), float(interest[i, j]),
                                  f"fight: {self.players[i]} vs {self.players[j]}"))
        best_fight = interest.max(axis=1)
        for i in np.flatnonzero(best_fight > 0.0).tolist():
            options.append(Option(ShotKind.FOLLOW, (i,), FOLLOW_SHARE * float(best_fight[i]),
                                  f"fighter: {self.players[i]}"))
        options += self._roaming(moment, best_fight)
        fighters = np.flatnonzero(best_fight > 0.0)
        if len(fighters) >= 3:
            feet = moment.feet_world[fighters]
            for k, i in enumerate(fighters.tolist()):
                near = fighters[np.linalg.norm(feet - feet[k], axis=1) <= s.group_radius_m]
                if len(near) >= 3 and near.min() == i:  # one group per leftmost member
                    members = tuple(int(m) for m in near[: s.max_group])
                    sub = interest[np.ix_(members, members)]
                    options.append(Option(ShotKind.GROUP, members,
                                          GROUP_SHARE * float(sub.max()) + GROUP_EXTRA * (len(members) - 2),
                                          "group: " + ", ".join(self.players[m] for m in members)))
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
        return [Option(ShotKind.FOLLOW, (i,), s.overview_min_interest + ROAM_FLOOR + ROAM_BONUS * float(proximity[i]),
                       f"on the move: {self.players[i]}, an opponent {nearest[i]:.0f} m away")
                for i in np.flatnonzero(alive & (best_fight <= 0.0)).tolist()]

    # -- planned beats ----------------------------------------------------------------------
    def _event_shot(self, event: GameEvent) -> tuple[ShotKind, tuple[int, ...]] | None:
        actor, other = self.index.get(event.actor_id), self.index.get(event.other_actor_id)
        if event.kind in (EventKind.KILL, EventKind.DAMAGE) and actor is not None and other is not None \
                and actor != other:
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
        beats: list[Beat] = []
        dropped = 0
        for event in buffer.events_between(now, horizon):
            priority = event_priority(event, s)
            shot = self._event_shot(event) if priority >= s.beat_min_priority else None
            if shot is None:
                continue
            kind, subjects = shot
            what = (f"{event.kind.name.lower()} in {event.time_s - now:.1f} s: "
                    f"{' -> '.join(self.players[i] for i in subjects)}")
            if beats and set(subjects) <= set(beats[-1].subjects):
                beats[-1].add(event.time_s, priority)
                continue
            beat = Beat(kind, subjects, event.time_s, event.time_s, priority, what, times_s=[event.time_s])
            if not beats and set(subjects) <= shows and event.time_s - start <= s.max_held_shot_s:
                # the current shot shows it: no cut (up to max_held_shot_s: a duel's players are in every kill)
                beats.append(beat)
                continue
            last = beats[-1] if beats else None
            beat.cut_s = self._beat_cut(beat, last, start, free, now)
            if beat.cut_s is not None:
                # a cut that would end the shot before it short of preferred_shot_s: one shot of both, when one sees them all
                before_s = start if last is None or last.cut_s is None else last.cut_s
                if not (beat.cut_s - before_s < s.preferred_shot_s and self._join(last, beat, buffer, now, start, free, shows)):
                    beats.append(beat)
                continue
            # no cut of its own: join the previous beat, take its place, or be left out
            if self._join(last, beat, buffer, now, start, free, shows):
                continue
            if last is not None and priority > last.priority:
                if last.cut_s is not None:
                    beat.cut_s = self._beat_cut(beat, beats[-2] if len(beats) > 1 else None, start, free, now)
                else:  # the current shot shows the lesser event (the first beat): its hold gives way
                    beat.cut_s = self._cut_time(beat.time_s, start, now, now)
                if beat.cut_s is not None:
                    dropped += len(last.times_s)
                    beats[-1] = beat
                    continue
            dropped += 1
        return beats, dropped

    def _join(self, last: Beat | None, beat: Beat, buffer: MomentBuffer, now_s: float, start_s: float, free_s: float,
              shows: set[int]) -> bool:
        """Makes the previous beat show the new one's event too, as a GROUP or else an OVERVIEW of
        all their players, when they fit in max_group, stand within join_spread_max_m of each
        other at the events' moments, and one such shot sees them all then (_shot_sees); whether
        it did."""
        if last is None:
            return False
        union = tuple(dict.fromkeys((*last.subjects, *beat.subjects)))
        times_s = [*last.times_s, beat.time_s]
        if self._spread_m(union, times_s, buffer) > self.settings.join_spread_max_m:
            return False
        joint = None if len(union) > self.settings.max_group else next(
            (k for k in (ShotKind.GROUP, ShotKind.OVERVIEW) if self._shot_sees(k, union, times_s, buffer, now_s)), None)
        if joint is None:
            return False
        last.subjects, last.kind, last.reason = union, joint, last.reason + "; and " + beat.reason
        last.add(beat.time_s, beat.priority)
        if last.cut_s is None and not set(union) <= shows:  # the current shot no longer shows it all
            last.cut_s = self._cut_time(last.time_s, start_s, free_s, now_s)
        return True

    @staticmethod
    def _spread_m(players: tuple[int, ...], times_s: list[float], buffer: MomentBuffer) -> float:
        """The greatest distance between two of the players' aim points at any of the moments, m."""
        aims = np.stack([buffer.at(t).aims_world[list(players)] for t in times_s])           # (t, p, 3)
        return float(np.linalg.norm(aims[:, :, None] - aims[:, None, :], axis=3).max())

    def _beat_cut(self, beat: Beat, previous: Beat | None, start_s: float, free_s: float,
                  now_s: float) -> float | None:
        """The cut time of a beat after the previous planned one (None: after the current shot
        that started at start_s and holds its events until free_s)."""
        previous_start = start_s if previous is None or previous.cut_s is None else previous.cut_s
        free = free_s if previous is None else previous.last_time_s + self.settings.event_hold_s
        return self._cut_time(beat.time_s, previous_start, free, now_s)

    def _shot_sees(self, kind: ShotKind, subjects: tuple[int, ...], times_s: list[float], buffer: MomentBuffer,
                   now_s: float) -> bool:
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

    def _cut_time(self, event_s: float, previous_start_s: float, free_s: float, now_s: float) -> float | None:
        """When to cut for an event at event_s: lead_s before it, not before the previous shot is
        preferred_shot_s old (else min_shot_s: a shorter lead rather than a shorter shot; on the
        real 4on4, a kill every 2.5 s made the median shot 2.7 s), its hold is over, or max_lead_s
        before the event; None when that is within min_lead_s of the event."""
        s = self.settings
        for shot_s in dict.fromkeys((max(s.preferred_shot_s, self.style.min_shot_s), self.style.min_shot_s)):
            earliest = max(now_s, previous_start_s + shot_s, free_s, event_s - s.max_lead_s)
            cut = max(earliest, event_s - s.lead_s)
            if cut <= event_s - s.min_lead_s:
                return cut
        return None

    # -- the decision -----------------------------------------------------------------------
    def decide(self, moment: Moment, buffer: MomentBuffer, current: Shot | None,
               current_pose: CameraPose | None, flags: list[str]) -> Shot | None:
        """The shot to cut to now, or None to keep the current one."""
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
            current.hold_until_s = max(current.hold_until_s, first.last_time_s + s.event_hold_s)
            current.cover_times_s = sorted(set(current.cover_times_s) | set(first.times_s))
        elif first is not None and first.cut_s <= now + 1e-9:
            choice = ShotChoice(tuple(self.players[i] for i in first.subjects), first.kind, "planned " + first.reason)
            cover, weights = self.event_cover(buffer, now, first.times_s)
            shot, seen = self.builder.build(choice, first.subjects, moment, cover, current, current_pose, now, weights,
                                            tuple(first.times_s), buffer)
            if shot is not None:
                shot.hold_until_s, shot.cover_times_s = first.last_time_s + s.event_hold_s, list(first.times_s)
                shot.scores = {"priority": float(first.priority), "lead_s": first.time_s - now, "place_visibility": seen}
                return shot
            flags.append("plan_no_place_for_grammar")
        length_s = math.inf if current is None else now - current.start_s
        if current is not None and (length_s < style.min_shot_s or now < current.hold_until_s):
            return None
        next_cut = min((b.cut_s for b in beats if b.cut_s is not None), default=math.inf)
        if current is not None and next_cut - now < style.min_shot_s:
            flags.append("plan_holding_for_planned_cut")
            return None
        options = self.options(moment, buffer)
        current_set = set(current.subjects) if current is not None else None
        current_kind = current.choice.kind if current is not None else None
        current_score = next((o.score for o in options if set(o.subjects) == current_set and o.kind == current_kind),
                             0.0)
        dead_too_long = current is not None and any(
            now - self.dead_since.get(i, math.inf) >= s.dead_hold_s for i in current.subjects)
        skipped = 0
        for option in options:
            if current is not None and set(option.subjects) == current_set and option.kind == current_kind:
                continue
            better = (option.score > current_score * (1.0 + s.switch_margin) + MIN_SWITCH_GAIN
                      and length_s >= s.settle_s)
            if not (current is None or length_s >= style.max_shot_s or dead_too_long or better):
                return None
            why = ("max shot length" if current is not None and length_s >= style.max_shot_s
                   else "subject dead" if dead_too_long else "better situation")
            choice = ShotChoice(tuple(self.players[i] for i in option.subjects), option.kind,
                                f"{option.reason} ({why})")
            if len(option.subjects) > 1 and skipped >= MAX_UNSEEN_FIGHTS:
                continue  # a plan's cost stays bounded: each try is a place search
            cover = [moment] + [buffer.at(now + ahead_s) for ahead_s in OPTION_COVER_S if now + ahead_s <= buffer.horizon_s]
            shot, seen = self.builder.build(choice, option.subjects, moment, cover, current, current_pose, now)
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
