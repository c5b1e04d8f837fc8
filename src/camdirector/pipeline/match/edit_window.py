"""EDIT WINDOW of the MATCH rig (issue 41, item 3; docs/casting.md, "The edit window"): the rig
works the program `window_s` (2.5 s: the style's `min_shot_s` and half a second more) ahead of the
moment it answers, on the broadcast delay's own buffer, and keeps the frames it has worked out and
not yet answered.
A cut within a shot (a camera met a wall, its player teleported: rig.py) is found the frame it
happens; here the frames before it are still the rig's to change. Where a cut comes under
`min_shot_s` after the one before, the short shot between is given to a neighbour:

- to the shot before, carried on: a copy of the camera that went off air at a cut is stepped on
  for `window_s` after it (the `Shadow`, as camera_ahead.py steps one for a frame), and holds its
  poses where it met no wall, lost its subjects nowhere (a copy is never re-placed) and jumped
  nowhere over the short shot's frames;
- or to the shot after, started earlier: through the same eyes where it is a first-person shot
  whose player does not jump there, a copy of its camera stepped from the short shot's first frame
  where it moves (a Toric camera) and meets no wall on the way, else standing at its first place
  and turning to keep its subjects where its first pose shows them (`_turned_toward`; a player's
  eyes held still there, their subjects counted seen only in their frame);

whichever shows its subjects more over those frames (the share of their points seen, visibility.py;
ties to the shot before), among the neighbours that
- may take it (`_may_take`): a replay's piece goes to the same replay, or to a live shot where the
  replay goes on on its other side and the piece does not show its kill (never left out); a live
  shot's to a live one, or to a replay starting earlier where no kill happens in its frames;
- show each kill the short shot showed (killer and victim each with KILL_SEEN of their points in
  the frame and seen at the kill's frame, or the victim so through the killer's eyes, as
  eval-match counts a kill covered: `_shows_kill`);
- show their subjects at least SEEN_FLOOR on every frame the short shot showed its own so (no
  picture of nobody where there was one of somebody);
- and show the players in their frame readable, HEIGHT_FLOOR of its height (median), where the
  short shot did, or as tall as it did; a shot through a player's eyes started early, or as tall
  as it shows them from its own cut (`_keeps_height`).
A short shot that has none starts earlier instead, where the window still holds the shot before's
last frames that make it `lengthen_s` long and the shot before stays as long (`_earlier`, docs/
casting.md "A short shot starts earlier"): its cut moves to the first of them, the short shot's
camera as it was at its first frame (a copy the window keeps of each cut's) stepped over them, else
held at its first pose (through its player's eyes, a first-person shot), kept as a neighbour
keeps a short shot's frames (`_may_take` with the shot before as the short one, its kills, subjects
seen, players readable); applied before the first of them is answered. Failing that, it holds on
(`_hold`): the copy of its own camera
(the shadow its cut started) takes the shot after's first frames until the short shot is
`min_shot_s` long, the copy's last pose held where it met a wall or lost its subjects, and the cut
moves there, when the window reaches that frame (the shot after's frames may not cut before it,
and are kept as a neighbour keeps a short shot's: kills, subjects seen, players readable). The
neighbours first, as they move no cut later than the director chose it. One that cannot hold on
either (the shot after cut before, or its frames kept nothing) goes, where its frames are still
the window's, to the neighbour that takes it under the last resort's floors (`LAST_RESORT`,
flagged `edit_window_last_resort`: the players READABLE_HEIGHT tall rather than HEIGHT_FLOOR, its
subjects under SEEN_FLOOR on at most SEEN_MISSES of its frames and never under half of it, every
kill kept); with none, to the neighbour that keeps its kills whatever else it shows (`KILLS_ONLY`,
flagged `edit_window_kills_only` too), else it holds on keeping its kills alone, and before that
neighbour where the hold loses its subjects on fewer frames (`_alone_first`: each counted where it
shows its subjects under SEEN_FLOOR in its frame and the picture it replaces showed them more);
with none either, to the neighbour that takes it whatever it shows, a kill in its frames given up
(`ANY`, flagged `edit_window_kill_given_up` too; the hold by its kills alone first where there is
one): issue 41 bars every shot under 2 s and kill coverage is a share (on the 2on2 imported half a
row late, a DUEL cut by a wall 0.4 s before an OVERVIEW, with a kill in those frames that the
OVERVIEW showed at 0.38-0.5 of its players' points); failing all, it stays short, flagged at the cut
that ends it. A hold is judged on the program as
repaired: a repair waiting that gives a short piece of the shot after to the shot after it is
applied first (`_settle_inside`), and a hold set once the window is past the frame it ends on is
judged there at once (`_hold_reached`); the last resort applies only where the shot after still
starts at the pose it judged, or, where that pose was given since to the shot after it (a short
piece's repair), judged again on that one (`_judged_again`: by its floors or the kills alone,
never a kill given up), and before the shot after's own cut joins the window where that cut
comes before the hold's end and nothing removes it (`_hold_cut_short`); a cut that comes before
the hold's end applies the repair waiting of the shot after's short piece first (its cut would
refuse the last resort), and where the repair that cut draws removes it (its own short piece to
the shot after it), the hold waits for its end (`_cut_goes`); a hold whose end is the cut that
sets it is judged at that cut (`_held_to_cut`). A human's take is never
given away.

A shot `min_shot_s` long or more but under `lengthen_s` (2.4 s: the settings' `edit_lengthen_s`,
within the window) is given to a neighbour too, by the same rules but with its subjects counted
seen only in the neighbour's frame (`SHOWN`: judged by a ray alone, a neighbour of the real 2on2
showed nobody for 2 s), else left as it is: it is not short, so it neither holds on nor starts
earlier. On the real 2on2, 13 of 48 shots were 2.0-2.13 s and its median 2.7 s; 3.13 s with it
(docs/casting.md, "Shots a little over min_shot_s").

Off the frame path: a repair (up to a `window_s` of a camera copy's steps, each the rig's CAMERA
stage, and the visibility judged over them: a median 18 ms and up to 90 ms on the real wipeout,
which set the rig's compute p99) is drawn at the cut that made the shot short, with what it reads
taken then (`Repair`), worked out in the worker's idle moments (infra/slices.py, as a drawn plan
is) and applied (`settle`) when the short shot's first frame is answered, the next cut joins the
window, or at once in a session whose ray scene moves every frame (the idle moments would see
another scene). Applied at those frames whatever the idle moments did, the program does not
depend on when or in how many slices a repair was worked out; until then the shadow of the cut
before it steps on as if it carried the short shot, and the one this cut starts beside it. A hold
is judged at the frame it would end on (what remains of its copy's steps, and the visibility of a
held pose at every JUDGED_EVERY-th frame: 4-8 ms, a few frames a match), worked out ahead in the
idle moments before that frame where nothing it reads changed since (`HoldAhead`), else then.

The offline bound that led to it (load_tests/edit_window_bound.py) gave every short shot of the
real matches' programs to a neighbour, a held pose where no eyes carried on; here the shot before
goes on moving.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from camdirector.geometry.camera import CameraPose, level_angles, level_matrix, level_rotation
from camdirector.geometry.transforms import matrix_to_quat, quat_to_matrix
from camdirector.infra.slices import SlicedRun, pause
from camdirector.pipeline.inputs import EventKind
from camdirector.pipeline.match.first_person import FirstPersonCamera
from camdirector.pipeline.match.frame import PlannedCut, ShotChoice
from camdirector.pipeline.match.moments import TIME_EPSILON_S, Moment
from camdirector.pipeline.match.program_camera import CUT_TO_SEEN_PLACE, HOLD_LEFT_FOR_CUT, SUBJECTS_LOST
from camdirector.pipeline.match.program_shot import CandidateShot, Shot, ShotCamera, unchanged
from camdirector.pipeline.match.shots import StaticCamera

JUMP_M = 2.0  # a camera or an eye moving this far between two frames jumped (a teleport, a respawn): no carrying across, m
KILL_SEEN = 0.5  # a kill in a short shot's frames is shown where killer and victim each have this share of points seen
SEEN_FLOOR = 0.5  # a neighbour may not show its subjects less than this (eval-match's shown fraction) where the short
# shot showed its own more
HEIGHT_FLOOR = 0.15  # the median shown height issue 41 bars, share of the frame's height
# the last resort's floors (`LAST_RESORT`): the players readable at all, the floor the eyes are held to (settings.py
# eyes_shown_height_min), share of the frame's height
READABLE_HEIGHT = 0.1
SEEN_MISSES = 0.1  # and the share of the short shot's frames it may show its subjects under SEEN_FLOOR (never under half)
JUDGED_EVERY = 3  # a neighbour's visibility over a short shot is judged at every this-th frame (a frame's ray budget)
# a shot started early standing at its first place turns toward its subjects no faster than this (`_turned_toward`): a
# quick pan, a quarter turn in a second, as the lens narrows back at its own pace (settings.py narrow_deg_s), deg/s
TURN_DEG_S = 90.0
CARRIED_ON = "edit_window_carried_on"  # a short shot's frames given to the shot before
STARTED_EARLY = "edit_window_started_early"  # a short shot's frames given to the shot after
HELD_ON = "edit_window_held_on"  # the shot after's first frames given to a short shot neither neighbour could take
MOVED_EARLIER = "edit_window_moved_earlier"  # the shot before's last frames given to a short shot neither neighbour took
SHORT_LEFT = "edit_window_short_left"  # a short shot neither neighbour could take nor hold on
LAST_RESORT_FLAG = "edit_window_last_resort"  # a short shot's frames given to a neighbour by the last resort's floors
KILLS_ONLY_FLAG = "edit_window_kills_only"  # and by its kills alone (`KILLS_ONLY`), to a neighbour or held on
KILL_GIVEN_UP_FLAG = "edit_window_kill_given_up"  # and to a neighbour whatever it shows (`ANY`), a kill in its frames lost
# a copy of a camera stepped on goes no further where it would cut, or shows its subjects no more (program_camera.py)
ENDS_A_COPY = (CUT_TO_SEEN_PLACE, HOLD_LEFT_FOR_CUT, SUBJECTS_LOST)


@dataclass
class WorkedFrame:
    """One program frame the rig has worked out (rig.py `_work`): its moment and the one its picture
    shows (a REPLAY's: replays.py), the pose, whether it cuts, its flags, the framed subjects'
    visibility share, the shot on air and what `MatchFrame.shot` names, and the candidates of that
    frame's tick (their poses are worked out when the frame is answered, at its moment)."""

    moment: Moment
    shown: Moment
    pose: CameraPose
    cut: bool
    flags: list[str]
    visibility: float  # [0, 1]
    shot: Shot
    choice: ShotChoice
    candidates: list[CandidateShot]


@dataclass
class Shadow:
    """The camera that went off air at the program's last cut, stepped on from a copy (module
    docstring): its poses and visibility at each worked frame from the cut, until `until_s`. A
    frame's step waits in `due` (off the frame path, as a repair: `EditWindow.work`) until a
    repair reads the steps; it reads the copy and the moments alone, so when it runs does not
    change it."""

    shot: Shot
    camera: ShotCamera  # a copy, as it was before the cut's frame
    last_pose: CameraPose
    until_s: float  # stepped until this program time, s
    steps: list[tuple[Moment, CameraPose, float]] = field(default_factory=list)  # (moment, pose, visibility) from the cut
    alive: bool = True  # False once it met a wall, lost its subjects or jumped
    due: list[tuple[Moment, Moment, float]] = field(default_factory=list)  # frames to step: (moment, shown, dt_s)

    @functools.cached_property
    def judged(self) -> Shot:
        """The shot with the copy as its camera (whom a step frames: the copy's pair window); made
        once, as the shadow's shot and copy are never replaced."""
        return dataclasses.replace(self.shot, camera=self.camera)

    def __setstate__(self, state: dict[str, object]) -> None:
        """A shadow from a checkpoint (one written before its steps waited: none due)."""
        self.__dict__.update({"due": [], **state})


class Decision(NamedTuple):
    """What a repair decided: the neighbour the short shot's frames go to (BEFORE, AFTER; None:
    neither, the short shot stays) and the pose and visibility each of them gets there; with
    None, the neighbour the last resort's floors allow, taken where the short shot cannot hold on
    either (`LAST_RESORT`, else `KILLS_ONLY`: kills_only)."""

    neighbour: str | None
    poses: list[CameraPose]
    seen: list[float]
    last_resort: Decision | None = None
    kills_only: bool = False
    # the frames on which it shows its subjects under SEEN_FLOOR (judged as its floors judge them) where the frames it
    # takes showed theirs more (`_missed`), count
    lost: int = 0
    kill_given_up: bool = False  # by the floors `ANY`: a kill in its frames not shown (last: a checkpoint's older
    # decisions, pickled as tuples, read on)


class Floors(NamedTuple):
    """What a neighbour must keep of a short shot's picture: its subjects seen SEEN_FLOOR on
    every frame where the short shot showed them so, but for a `misses` share of its frames
    (never under `seen_min` there), and its players `height` of the frame's height (median)
    where the short shot showed them as tall; `in_frame`: its subjects' points counted seen only
    inside its frame (eval-match's shown share: a held pose looks where its subject was), else
    wherever a ray reaches them (the program's visibility)."""

    misses: float  # [0, 1]
    height: float  # share of the frame's height
    in_frame: bool
    seen_min: float = SEEN_FLOOR / 2.0  # [0, SEEN_FLOOR]
    kills: bool = True  # each kill in the short shot's frames shown (`_shows_kill`)


STRICT = Floors(0.0, HEIGHT_FLOOR, False)
# where neither neighbour keeps the strict floors nor the short shot can start earlier or hold on, a short shot is
# jarring for longer than a wider picture is (issue 41: none under 2 s): players readable at all, subjects seen on
# nearly every frame; kills are never given up
LAST_RESORT = Floors(SEEN_MISSES, READABLE_HEIGHT, True)
# and where none keeps even those, the neighbour (else the hold) that keeps its kills, whatever else it shows: a
# picture that lingers where its subjects went, or waits where they come, for under 2 s is what a broadcast shows
# when a player runs behind a wall; a cut under 2 s after the one before is not (docs/casting.md, "Kills only")
KILLS_ONLY = Floors(1.0, 0.0, True, 0.0)
# and where none keeps its kills either (nor holds on by them), the neighbour that takes it whatever it shows: issue 41
# bars every shot under 2 s, while a kill missed is a share of the kill coverage (module docstring)
ANY = Floors(1.0, 0.0, True, 0.0, kills=False)
# a shot min_shot_s long but under the window's `lengthen_s` is given to a neighbour only where that one shows its
# subjects in its frame as the shot did (eval-match's shown share: a neighbour judged by a ray alone showed nobody for
# 2 s on the real 2on2) and its kills as any repair does (`_shows_kill`); else it stays as it is, neither started
# earlier, held on nor given by a last resort
SHOWN = Floors(0.0, HEIGHT_FLOOR, True)


# Decision.neighbour: the shot before (carried on), the shot after (started early), or neither, the short shot's cut
# moved earlier into the shot before (`_earlier`)
BEFORE, AFTER, EARLIER = "before", "after", "earlier"


class Side(NamedTuple):
    """A neighbour of a short shot as its repair reads it, taken at the cut (what the rig goes on
    changing meanwhile, it reads as it was): the shot, given the frames; a copy of it with a copy
    of its camera, judged; the moments its picture shows at the short shot's frames (a replay's:
    the buffer lets the earliest go as the program moves on)."""

    shot: Shot
    judged: Shot
    shown: list[Moment]
    stepped: bool = True  # whether a copy of its camera may step over the frames (False: it is as it was after them)


def _side(shot: Shot, rows: list[WorkedFrame], judges: Judges, camera: ShotCamera | None = None) -> Side:
    """The shot as a neighbour of the short shot's frames (rows), taken now, or with a copy of
    `camera`, its camera as it was at its first frame (Side)."""
    judged = dataclasses.replace(shot, camera=copy.copy(shot.camera if camera is None else camera))
    return Side(shot, judged, [judges.shown_of(judged, r.moment) for r in rows])


@dataclass
class Repair:
    """A short shot's repair, drawn at the cut that made it short and applied by `settle`
    (module docstring, "Off the frame path")."""

    rows: list[WorkedFrame]  # the short shot's frames
    frame: WorkedFrame  # the cut after it
    run: SlicedRun[Decision] | None  # None once worked out (a snapshot pickles the window: worked out first)
    before: Side | None  # the shot before, where a shadow may carry it on
    after: Side  # the shot after
    carried: Shadow | None  # the shadow of the cut before the short shot, stepped on as if it carried it
    carried_until_s: float  # that shadow's own end where it does not, program time, s
    started: Shadow | None  # the shadow this cut starts, where the short shot is not given to the shot before
    decision: Decision | None = None
    back: list[WorkedFrame] = field(default_factory=list)  # the shot before's last frames the short shot may start at
    earlier: Side | None = None  # the short shot as their neighbour (`_back`, `_earlier`)
    first: CameraPose | None = None  # the shot after's first pose as the decision read it (None: a checkpoint's, unknown)
    long_enough: bool = False  # the short shot min_shot_s long already: given to a neighbour at SHOWN, else left as it is

    def after_moved(self) -> bool:
        """Whether the shot after's first frame was given since the decision read it (to the shot after
        that one, started early: its own short piece's repair); False where unknown (a checkpoint's)."""
        return self.first is not None and self.frame.pose is not self.first

    def carried_back(self) -> None:
        """The shadow it carried stepped to that shadow's own end again (it does not carry the
        short shot: `_drawn` stepped it on as if it did)."""
        if self.carried is not None:
            self.carried.until_s = self.carried_until_s

    def work_out(self, budget_s: float | None = None) -> None:
        """Works the decision out, whole (budget_s None) or for about budget_s more."""
        run = self.run
        if run is not None and (budget_s is None or run.step(budget_s)):
            self.decision, self.run = run.finish(), None

    def __getstate__(self) -> dict[str, object]:
        self.work_out()  # a greenlet cannot be pickled; worked out now or later, the decision is the same
        return self.__dict__

    def __setstate__(self, state: dict[str, object]) -> None:
        """A repair from a checkpoint (one written before a short shot could start earlier: it does not)."""
        self.__dict__.update({"back": [], "earlier": None, "first": None, "long_enough": False, **state})


@dataclass
class HoldAhead:
    """`EditWindow._hold`'s verdict for the frame of a moment, worked out ahead (`work_hold`), with
    what it read: the repair held, the window's frames (their count and the newest, by identity)
    and the short shot's camera's attributes (by identity, as camera_ahead.py's steps)."""

    repair: Repair
    moment: Moment
    count: int
    newest: WorkedFrame | None
    camera: dict[str, object]
    verdict: tuple[list[WorkedFrame], Side, Decision] | None

    @classmethod
    def of(cls, window: EditWindow, moment: Moment, verdict: tuple[list[WorkedFrame], Side, Decision] | None) -> HoldAhead:
        repair = window.holding
        assert repair is not None and repair.started is not None  # held only with a shadow (settle)
        newest = window.frames[-1] if window.frames else None
        return cls(repair, moment, len(window.frames), newest, dict(vars(repair.started.shot.camera)), verdict)

    def holds(self, window: EditWindow, moment: Moment) -> bool:
        """Whether it is the verdict the window would give at the frame of the moment now."""
        repair = window.holding
        if repair is not self.repair or moment is not self.moment or len(window.frames) != self.count:
            return False
        if (window.frames[-1] if window.frames else None) is not self.newest:
            return False
        assert repair is not None and repair.started is not None  # held only with a shadow (settle)
        return unchanged(repair.started.shot.camera, self.camera)


class Judges(NamedTuple):
    """What the window asks of the rig (rig.py, program_camera.py, in_level.py)."""

    shown_of: Callable[[Shot, Moment], Moment]  # the moment a shot's picture shows at a program moment (a REPLAY's)
    # a shot's camera stepped dt_s to a moment from the pose before, held before walls: (pose, flags), None for none
    step: Callable[[Moment, float, ShotCamera, Shot, CameraPose | None], tuple[CameraPose, list[str]] | None]
    visibility: Callable[[Moment, CameraPose, Shot], float]  # the mean share of a shot's framed subjects seen from a pose
    # the (k,) share of each of k players' sample points in a pose's frame and seen from it
    seen: Callable[[CameraPose, Moment, tuple[int, ...]], np.ndarray]
    # the median share of the frame's height the players a pose shows stand, about, but the one whose eyes a shot's
    # first-person view is (NaN: none shown)
    height: Callable[[CameraPose, Moment, Shot], float]
    choice_of: Callable[[Shot, float], ShotChoice]  # what MatchFrame.shot names of a shot at a time, s
    inside: Callable[[np.ndarray], bool]  # a (3,) point inside the level
    crossed: Callable[[np.ndarray, np.ndarray], bool]  # level geometry between two (3,) points


class EditWindow:
    """The frames worked out and not yet answered, the shadow of the last cut, and the repairs
    (module docstring). The rig's `window_s` 0 answers each frame as it is worked out: no repairs."""

    def __init__(
        self,
        min_shot_s: float,
        players: list[str],
        defer: bool = True,
        window_s: float | None = None,
        lengthen_s: float | None = None,
    ):
        self.min_shot_s = min_shot_s
        # a shot at least min_shot_s long but under this is given to a neighbour too, where that one shows its subjects
        # in its frame as the shot did (SHOWN), s; None: min_shot_s, none
        self.lengthen_s = min_shot_s if lengthen_s is None else lengthen_s
        self.players = players
        # how far ahead of the frame it answers the rig works, s: a short shot starts no earlier than a new cut's frame
        # less this (the frames before are answered: `_back`); None: min_shot_s, no room to start one earlier
        self.window_s = min_shot_s if window_s is None else window_s
        self.defer = defer  # repairs worked out off the frame path (module docstring); False: a moving ray scene
        self.frames: deque[WorkedFrame] = deque()
        self.shadow: Shadow | None = None
        self.repair: Repair | None = None  # the repair drawn and not yet applied
        self.holding: Repair | None = None  # a short shot no neighbour took, that may hold on (_hold)
        self.hold_ahead: HoldAhead | None = None  # its verdict at the next frame, worked out ahead (work_hold)
        self.answered: WorkedFrame | None = None  # the last frame answered
        self.last_cut_s = -math.inf  # program time of the last cut answered, s
        # the newest cut's frame and a copy of the camera it put on air as it was there (a short shot started earlier
        # steps it from there: `_earlier`)
        self.cut_camera: tuple[WorkedFrame, ShotCamera] | None = None

    def __setstate__(self, state: dict[str, object]) -> None:
        """A window from a checkpoint (one written before repairs were drawn: none waiting; before
        a short shot could start earlier: no room for it)."""
        defaults = {
            "defer": True,
            "repair": None,
            "holding": None,
            "window_s": state["min_shot_s"],
            "lengthen_s": state["min_shot_s"],
            "cut_camera": None,
            "hold_ahead": None,
        }
        self.__dict__.update({**defaults, **state})

    @functools.cached_property
    def columns(self) -> dict[str, int]:
        """Each player's index in the moments, by id (the kills' pairs, `_kills`)."""
        return {p: i for i, p in enumerate(self.players)}

    @property
    def shot_s(self) -> float:
        """How long a short shot started earlier is made (`_earlier`), and the longest given to a neighbour, s:
        lengthen_s, at least min_shot_s (a hold makes one min_shot_s long)."""
        return max(self.min_shot_s, self.lengthen_s)

    def drop(self) -> None:
        """Forgets the frames not yet answered (a take applies at once: rig.py)."""
        self.frames.clear()
        self.shadow = self.repair = self.holding = self.cut_camera = self.hold_ahead = None

    @property
    def waiting(self) -> bool:
        """Whether a shadow's steps or a repair drawn wait to be worked out (the rig's deferred work)."""
        return any(s.due and s.alive for s in self._shadows()) or (self.repair is not None and self.repair.run is not None)

    def work(self, judges: Judges, budget_s: float | None = None, clock: Callable[[], float] = time.perf_counter) -> None:
        """Works on what waits, the shadows' steps first (a repair drawn reads them), whole
        (budget_s None) or for about budget_s more, s; what the program gets from it, and when,
        does not change (module docstring)."""
        deadline_s = math.inf if budget_s is None else clock() + budget_s
        if all(self._caught_up(s, judges, deadline_s, clock) for s in self._shadows()) and self.repair is not None:
            self.repair.work_out(None if budget_s is None else max(deadline_s - clock(), 0.0))

    def last_pose(self) -> CameraPose | None:
        """The pose of the newest frame worked out (or answered)."""
        last = self.frames[-1] if self.frames else self.answered
        return None if last is None else last.pose

    def step_shadow(self, moment: Moment, dt_s: float, judges: Judges) -> None:
        """The shadow's step to the worked frame's moment, while it lives and its window lasts
        (and, while a repair waits, the one its cut started beside it): due, taken at once where
        the window does not defer (Shadow)."""
        for shadow in self._shadows():
            if shadow.alive and moment.time_s <= shadow.until_s + TIME_EPSILON_S:
                shadow.due.append((moment, judges.shown_of(shadow.judged, moment), dt_s))
                if not self.defer:
                    self._caught_up(shadow, judges)

    def _shadows(self) -> list[Shadow]:
        started = None if self.repair is None else self.repair.started
        return [s for s in (self.shadow, started) if s is not None]

    @staticmethod
    def _caught_up(
        shadow: Shadow, judges: Judges, deadline_s: float = math.inf, clock: Callable[[], float] = time.perf_counter
    ) -> bool:
        """The shadow's due steps taken, one at least, until the clock reads deadline_s; whether
        none is left."""
        judged = shadow.judged
        while shadow.due and shadow.alive:
            moment, shown, dt_s = shadow.due.pop(0)
            stepped = judges.step(shown, dt_s, shadow.camera, judged, shadow.last_pose)
            if stepped is None:
                shadow.alive = False
                break
            pose, flags = stepped
            moved = pose.position_world - shadow.last_pose.position_world
            if (
                any(f in flags for f in ENDS_A_COPY)
                or float(np.linalg.norm(moved)) >= JUMP_M
                or judges.crossed(shadow.last_pose.position_world, pose.position_world)
            ):
                shadow.alive = False
                break
            shadow.steps.append((moment, pose, judges.visibility(shown, pose, judged)))
            shadow.last_pose = pose
            if shadow.due and clock() >= deadline_s:
                return False
        shadow.due.clear()  # a shadow that died steps no more
        return True

    def push(self, frame: WorkedFrame, before: tuple[Shot, ShotCamera] | None, judges: Judges) -> None:
        """A newly worked frame joins the window. A cut first applies the repair waiting; then,
        under min_shot_s after the last cut in the window, it draws the repair that gives the
        short shot to a neighbour (module docstring), applied at once where the window does not
        defer; a cut left a cut starts a shadow of the camera `before` it (the shot on air and a
        copy of its camera as they were before the frame), its last pose the newest frame's."""
        if self.holding is not None and self._hold(frame, judges):
            before = None  # the short shot held on goes off air here: its shadow (the window's) steps on
            if not frame.cut:
                frame.cut = True
                self.frames.append(frame)
                return
        if frame.cut:
            self.settle(judges)  # this cut's short shot is judged on the program as repaired before it
            last = self.last_pose()
            started = None
            if before is not None and last is not None:
                started = Shadow(before[0], before[1], last, frame.moment.time_s + self.shot_s)
            repair = self._drawn(frame, started, judges)
            if repair is not None and self._hold_cut_short(repair, frame, judges):
                repair = self._drawn(frame, started, judges)  # over the short shot its last resort made longer
            self.cut_camera = (frame, copy.copy(frame.shot.camera))
            if repair is None:
                self.shadow = started or self.shadow
            else:
                self.repair = repair
                if not self.defer:
                    self.settle(judges)
        self.frames.append(frame)
        if frame.cut and self.holding is not None and self._hold_end(self.holding) is frame:
            self._held_to_cut(frame, judges)

    def settle(self, judges: Judges) -> None:
        """Applies the repair waiting, worked out first where it is not yet: its frames given to
        the neighbour it chose (flagged), the cut it removes cleared, the shadow that goes on
        kept (module docstring)."""
        repair, self.repair = self.repair, None
        if repair is None:
            return
        repair.work_out()
        decision, rows, frame = repair.decision, repair.rows, repair.frame
        assert decision is not None  # worked out above
        last_resort = decision.neighbour is None and decision.last_resort is not None and not self._may_hold(repair, judges)
        if last_resort:  # the last chance for it: the short shot's first frame is answered next
            assert decision.last_resort is not None  # tested above
            decision = decision.last_resort
        if decision.neighbour == BEFORE:
            assert repair.carried is not None  # only a shadow carries a short shot on
            self._to_neighbour(repair, decision, last_resort, judges)
            self.shadow = repair.carried  # stepped on meanwhile until this frame's cut's shot_s
            return
        repair.carried_back()
        if decision.neighbour == AFTER:
            self._to_neighbour(repair, decision, last_resort, judges)  # the cut before the short shot stays, and its shadow
            return
        if decision.neighbour == EARLIER:
            assert repair.back and repair.earlier is not None  # decided only with them (_decided)
            self._give(repair.back, repair.earlier, decision, MOVED_EARLIER, judges)
            repair.back[0].cut, rows[0].cut = True, False
            self.shadow = repair.started or self.shadow
            return
        if repair.long_enough:  # no neighbour shows it as well: it is not short, so it stays as it is
            self.shadow = repair.started or self.shadow
            return
        if repair.started is None:
            frame.flags.append(SHORT_LEFT)
        else:  # judged when the window reaches min_shot_s past the short shot's start (_hold)
            self.holding = repair
        self.shadow = repair.started or self.shadow
        if self.holding is repair:
            self._hold_reached(judges)

    def _hold_cut_short(self, repair: Repair, frame: WorkedFrame, judges: Judges) -> bool:
        """Whether the hold just set (`settle`, as the frame's cut joined) was given to its last
        resort instead (`_last_resort`), with the repair the cut drew (of the shot after, short
        too) worked out now: the cut comes before the hold's end, and that repair does not give the
        shot after to the one after it, which alone removes the cut (`_settle_inside`). Once the cut
        is the window's the last resort no longer applies, and the hold is left short: on the real
        4on4 a shot of 0.4 s (docs/casting.md, "Shots a little over min_shot_s"). Where it was
        given, the repair is to be drawn again (its short shot starts earlier now) and its change to
        the shadow it carries is undone."""
        held = self.holding
        if (
            held is None
            or held.decision is None
            or held.decision.last_resort is None
            or repair.rows[0] is not held.frame
            or frame.moment.time_s >= held.rows[0].moment.time_s + self.min_shot_s - TIME_EPSILON_S
        ):
            return False
        repair.work_out()
        assert repair.decision is not None  # worked out above
        if repair.decision.neighbour == AFTER:
            return False
        if not self._last_resort(held, judges):  # it reads no shadow's end: the repair stands as drawn
            return False
        repair.carried_back()
        return True

    def _hold_reached(self, judges: Judges) -> None:
        """The hold just set judged at once where the window already holds the frame it ends on
        (min_shot_s past the short shot's start: the repair was applied when the next cut joined,
        or its first frame was answered, after the window passed it), the cut moved there; else
        at the next frame, whose own cut would refuse it (on the real 4on4 a shot showing a kill,
        left 1.23 s long where the shot after was cut 1.0 s after it)."""
        assert self.holding is not None  # set by settle
        at = self._hold_end(self.holding)
        if at is not None and self._hold(at, judges):
            at.cut = True

    def answer(self, moment: Moment, judges: Judges) -> tuple[WorkedFrame, bool]:
        """The frame of the program moment (the newest worked out at or before it), and whether
        the program cuts there (a frame passed over with a cut counts: the picture changed); a
        repair whose short shot starts there, or starts earlier from there (`_earlier`), applied first."""
        repair = self.repair
        if repair is not None and repair.rows[0].moment.time_s <= moment.time_s + TIME_EPSILON_S:
            self.settle(judges)
        elif repair is not None and repair.back and repair.back[0].moment.time_s <= moment.time_s + TIME_EPSILON_S:
            repair.work_out()  # the frames it may move the cut to are answered now: applied first where it does
            if repair.decision is not None and repair.decision.neighbour == EARLIER:
                self.settle(judges)
        if self.holding is not None and self.holding.frame.moment.time_s <= moment.time_s + TIME_EPSILON_S:
            self._left(self.holding)  # its cut answered before the frames it needs were worked out (the match's end)
        cut = False
        while self.frames and self.frames[0].moment.time_s <= moment.time_s + TIME_EPSILON_S:
            frame = self.frames.popleft()
            cut |= frame.cut
            if frame.cut:
                self.last_cut_s = frame.moment.time_s
            self.answered = frame
        assert self.answered is not None  # the rig works the program moment out before it answers it
        return self.answered, cut

    def _hold(self, frame: WorkedFrame, judges: Judges) -> bool:
        """Whether the short shot no neighbour took (`holding`) goes on until the new frame, now
        that it is min_shot_s long there (the frame then cuts, flagged HELD_ON): the frames of the
        shot after from its cut (the frame at which, with its camera's copy, the shadow the cut
        started: Shadow) carried on over them, the copy's last pose held after it stops (it met a
        wall, lost its subjects), where they keep those frames as a neighbour keeps a short shot's
        (their kills, subjects seen and players readable). A cut before the frame, or frames that
        keep none of that, leave it to the last resort (`_last_resort`), but where the hold by its
        kills alone loses fewer frames than a last resort by the kills alone (`_alone_first`); a
        frame short of min_shot_s, it waits."""
        repair = self.holding
        assert repair is not None and repair.started is not None  # held only with a shadow (settle)
        if not repair.frame.cut:  # the shadow carried the short shot on over the shot after (a repair of its own)
            self.holding = None
            return False
        if frame.moment.time_s < repair.rows[0].moment.time_s + self.min_shot_s - TIME_EPSILON_S:
            # the shot after is cut short too: the last resort, before that cut's own repair is drawn, but after the
            # repair waiting that gives the shot after's short piece to the shot after it (whose cut would refuse it)
            if frame.cut:
                self._settle_inside(repair, judges)
                if not self._cut_goes(repair, frame, judges):
                    self._judged_again(repair, judges)
                    if not self._last_resort(repair, judges):
                        self._left(repair)
            return False
        ahead, self.hold_ahead = self.hold_ahead, None
        if self._settle_inside(repair, judges):
            ahead = None  # worked out on the frames before the repair changed them
        if ahead is not None and ahead.holds(self, frame.moment):
            verdict = ahead.verdict
        else:
            verdict = self._hold_verdict(repair, frame.moment, judges)
        self.holding = None
        if verdict is None:
            verdict = self._hold_verdict(repair, frame.moment, judges, KILLS_ONLY)
            self._judged_again(repair, judges)  # before the hold by the kills alone is weighed against it
            if not _alone_first(repair, verdict) and self._last_resort(repair, judges):
                return False
            if verdict is None:
                self._left(repair)
                return False
        rows, side, decision = verdict
        self._give(rows, side, decision, HELD_ON, judges)
        rows[0].cut = False
        started = repair.started
        started.until_s = frame.moment.time_s + self.min_shot_s  # off air at the frame: stepped on from there
        self.shadow = started
        return True

    def _cut_goes(self, held: Repair, frame: WorkedFrame, judges: Judges) -> bool:
        """Whether the cut of the frame joining, before the held short shot's hold would end, goes
        when its own repair is applied: that repair, drawn as the frame joins, gives the shot from
        the held one's end to this cut to the shot after it (`_hold_cut_short` keeps the hold for
        it then). Where no repair waits (one would change what this cut draws), it is drawn here
        first and undone. Judged at once, the hold went to its last resort or was left short (on
        two programs of the real 2on2 at 29 and 30 Hz, 0.83-0.87 s over a kill)."""
        if self.repair is not None or not any(f is held.frame for f in self.frames):
            return False
        drawn = self._drawn(frame, None, judges)
        if drawn is None:
            return False
        drawn.carried_back()
        if drawn.rows[0] is not held.frame:
            return False
        drawn.work_out()
        assert drawn.decision is not None  # worked out above
        return drawn.decision.neighbour == AFTER

    def _held_to_cut(self, frame: WorkedFrame, judges: Judges) -> None:
        """The hold set as the frame's cut joined (`settle`), whose end is that frame (the short
        shot and the shot after together min_shot_s long to it), judged there: its cut ends the
        hold. Judged at the next frame instead, as a hold whose end the window has not reached
        is, the cut fell among the frames it holds on over and refused it, and the last resort
        too (on a 30 Hz program of the real 2on2, shots of 1.77 and 0.23 s, together 2.0 s). Where
        it holds, the repair this cut drew, of the shot after, whose frames the hold took, is
        dropped, and the shadow that repair carried stops with the hold's."""
        drawn = self.repair if self.repair is not None and self.repair.frame is frame else None
        if not self._hold(frame, judges):
            return
        frame.cut = True  # where the repair waiting gave the shot after to the one after it, its cut went (_settle_inside)
        if drawn is not None and self.repair is drawn:
            self.repair = None
            if drawn.carried is not self.shadow:  # the hold's shadow steps on to the hold's end
                drawn.carried_back()

    def _settle_inside(self, held: Repair, judges: Judges) -> bool:
        """Applies the repair waiting where it gives a short piece of the shot after the short
        shot held (from the held one's cut on) to the shot after it, before the hold is judged:
        its cut would refuse the hold, the last resort and the kills alone alike, though it goes
        when the repair is applied a few frames later (on the real 4on4 and wipeout: all four
        shots left under 2 s). Any other waits for its own frame (one carried on by the held
        shot's copy ends the hold; one held on itself, a single hold at a time); whether one was
        applied."""
        repair = self.repair
        if repair is None or held.frame.moment.time_s > repair.rows[0].moment.time_s + TIME_EPSILON_S:
            return False
        repair.work_out()
        assert repair.decision is not None  # worked out above
        if repair.decision.neighbour != AFTER:
            return False
        self.settle(judges)
        return True

    def hold_due(self, following: Moment | None) -> bool:
        """Whether the short shot held waits to be judged at the following frame (the window's
        next moment), and its verdict is not yet worked out ahead (`work_hold`)."""
        repair = self.holding
        return (
            repair is not None
            and following is not None
            and repair.frame.cut
            and following.time_s >= repair.rows[0].moment.time_s + self.min_shot_s - TIME_EPSILON_S
            and (self.hold_ahead is None or not self.hold_ahead.holds(self, following))
        )

    def work_hold(self, following: Moment, judges: Judges) -> None:
        """The verdict `_hold` gives at the following frame, worked out ahead (in the worker's idle
        moments): it reads only what the window holds already (`HoldAhead`)."""
        assert self.holding is not None  # hold_due
        self.hold_ahead = HoldAhead.of(self, following, self._hold_verdict(self.holding, following, judges))

    def _hold_verdict(
        self, repair: Repair, at: Moment, judges: Judges, floors: Floors = STRICT
    ) -> tuple[list[WorkedFrame], Side, Decision] | None:
        """`_hold`'s verdict on the repair held at the frame of the moment `at`: the frames the
        short shot holds on over, the neighbour it is over them and its poses and visibility
        there, kept to the floors (KILLS_ONLY: its kills alone, flagged kills_only; its subjects
        seen in its frame where they say so), and the frames it loses them on; None where it
        stays short."""
        assert repair.started is not None  # held only with a shadow (settle)
        first = next((i for i, f in enumerate(self.frames) if f is repair.frame), None)
        rows = [] if first is None else [f for f in list(self.frames)[first:] if f.moment.time_s < at.time_s - TIME_EPSILON_S]
        if not rows or any(f.cut for f in rows[1:]) or rows[0].shot.held:
            return None
        started = repair.started
        self._caught_up(started, judges)
        side = _side(started.shot, rows, judges)
        steps = [(m, pose, seen) for m, pose, seen in started.steps if m.time_s < at.time_s - TIME_EPSILON_S]
        steps = [step for step, row in zip(steps, rows) if step[0] is row.moment]
        held = steps[-1][1] if steps else started.last_pose if not started.steps else None
        if held is None:  # the copy's first step was worked from a later pose
            return None
        held_moment = side.shown[max(len(steps) - 1, 0)]  # a replay's: the moment its picture shows
        after = _panned_on(side.judged, side.shown[len(steps) :], held, held_moment, judges.crossed)
        poses = [pose for _, pose, _ in steps] + after
        seen = [s for _, _, s in steps] + _judged_seen(side.shown, poses, side.judged, judges, len(steps))[0]
        judged = _judged_seen(side.shown, poses, side.judged, judges, in_frame=True)[0] if floors.in_frame else seen
        if (
            not _may_take(side.judged, rows[0].shot, rows[0].shot, rows)
            or not _keeps_kills(rows, _kills(rows, self.columns, judges), poses, side.judged, judges)
            or not _keeps_seen(rows, judged, floors)
            or not _keeps_height(rows, poses, side.shown, side.judged, judges, floors)
        ):
            return None
        return rows, side, Decision(None, poses, seen, kills_only=floors is KILLS_ONLY, lost=len(_missed(rows, judged)))

    def _may_hold(self, repair: Repair, judges: Judges) -> bool:
        """Whether the short shot of a repair being applied may hold on (`_hold`), judged now at
        the window's frame min_shot_s past its start (the hold is judged again there): keeping the
        strict floors, or by its kills alone before its last resort (`_alone_first`); True where
        the window does not reach that far yet (judged there alone)."""
        if repair.started is None:
            return False
        at = self._hold_end(repair)
        return (
            at is None
            or self._hold_verdict(repair, at.moment, judges) is not None
            or _alone_first(repair, self._hold_verdict(repair, at.moment, judges, KILLS_ONLY))
        )

    def _hold_end(self, repair: Repair) -> WorkedFrame | None:
        """The window's frame a hold of the repair's short shot ends on, min_shot_s past its
        start; None where the window does not reach it yet."""
        end_s = repair.rows[0].moment.time_s + self.min_shot_s - TIME_EPSILON_S
        return next((f for f in self.frames if f.moment.time_s >= end_s), None)

    def _last_resort(self, repair: Repair, judges: Judges) -> bool:
        """The short shot that could not hold on given to the neighbour its repair's last resort
        chose (`LAST_RESORT`, flagged), where its frames are still the window's; whether it was.
        The shadow ends: the camera that went off air at the short shot's end is no longer the
        one it copied."""
        decision = repair.decision
        last = None if decision is None else decision.last_resort
        frames = list(self.frames)
        end = next((i for i, f in enumerate(frames) if f is repair.frame), None)
        # its frames and the shot after's as the repair judged them: none answered, no cut (no repair) after it since
        if last is None or end is None or not any(f is repair.rows[0] for f in frames) or any(f.cut for f in frames[end + 1 :]):
            return False
        # not judged again since the shot after's first frame was given (`_judged_again`; the shot before carried on
        # reads none of it)
        if last.neighbour == AFTER and repair.after_moved():
            return False
        self._to_neighbour(repair, last, True, judges)
        self.shadow = self.holding = None
        return True

    def _judged_again(self, repair: Repair, judges: Judges) -> None:
        """A held short shot's last resort to the shot after, whose first frame was given since
        (`Repair.after_moved`), judged again before the hold is weighed against it or it is
        applied (as drawn it no longer applies: `_last_resort`): the shot that starts there now as
        the shot after (`repair.after`, `repair.first`), started at the short shot's frames into
        the pose it shows at the cut, by the last resort's floors, else by the kills alone
        (`_decided`), never giving a kill up (on program_phases' 2on2, giving them up too left a
        kill and 43 frames of nobody for one shot under 2 s); none where none keeps them. The
        short shot's other neighbour is read as the shot its shadow carried."""
        decision = repair.decision
        last = None if decision is None else decision.last_resort
        if decision is None or last is None or last.neighbour != AFTER or not repair.after_moved():
            return
        rows, frame = repair.rows, repair.frame
        after = _side(frame.shot, rows, judges)
        previous = None if repair.before is None else repair.before.shot
        kills = _kills(rows, self.columns, judges)
        again = None
        for floors in (LAST_RESORT, KILLS_ONLY):
            later = _after(rows, frame.pose, after, rows[0].shot, kills, previous, judges, floors=floors)
            if later is not None:
                repair.after, repair.first = after, frame.pose
                again = later[1]._replace(kills_only=floors is KILLS_ONLY)
                break
        repair.decision = decision._replace(last_resort=again)

    def _to_neighbour(self, repair: Repair, decision: Decision, last_resort: bool, judges: Judges) -> None:
        """The short shot's frames given to the shot before (BEFORE: the cut that starts it
        cleared) or the shot after (AFTER: the cut that ends it cleared), flagged, and
        `edit_window_last_resort` too where the last resort chose it."""
        if last_resort:
            for row in repair.rows:
                row.flags.append(LAST_RESORT_FLAG)
        if decision.neighbour == BEFORE:
            assert repair.before is not None  # only a shadow carries a short shot on
            self._give(repair.rows, repair.before, decision, CARRIED_ON, judges)
            repair.rows[0].cut = False
            if SHORT_LEFT in repair.rows[0].flags:  # the shot before, left short at this cut, goes on now
                repair.rows[0].flags.remove(SHORT_LEFT)
        else:
            self._give(repair.rows, repair.after, decision, STARTED_EARLY, judges)
            repair.frame.cut = False

    def _left(self, repair: Repair) -> None:
        """The short shot of a repair stays short, flagged at the cut that ends it."""
        repair.frame.flags.append(SHORT_LEFT)
        self.holding = None

    def next_cut(self) -> PlannedCut | None:
        """The next cut already worked out, not yet answered, to the shot the director chose (its
        picture may frame one of it first: `WorkedFrame.choice`)."""
        return next((PlannedCut(f.moment.time_s, f.shot.choice) for f in self.frames if f.cut), None)

    # -- the repairs ----------------------------------------------------------------------
    def _drawn(self, frame: WorkedFrame, started: Shadow | None, judges: Judges) -> Repair | None:
        """The repair of the short shot before the frame's cut, with what it reads taken now (the
        shot after's camera as it is at the cut, the shadow's steps so far); None with no short
        shot, or a human's take on air in it."""
        start = next((i for i in range(len(self.frames) - 1, -1, -1) if self.frames[i].cut), None)
        if start is None:
            return None
        length_s = frame.moment.time_s - self.frames[start].moment.time_s
        if length_s >= self.shot_s - TIME_EPSILON_S:
            return None
        long_enough = length_s >= self.min_shot_s - TIME_EPSILON_S
        rows = list(self.frames)[start:]
        if rows[0].shot.held:  # a human's take is on air as long as the human held it
            return None
        previous = self.frames[start - 1].shot if start > 0 else self.answered.shot if self.answered is not None else None
        carried, steps = self.shadow, None
        if carried is not None:
            self._caught_up(carried, judges)
            # from the short shot's first frame: a shadow carried on over an earlier short shot stepped from before it
            first = next((k for k, (m, _, _) in enumerate(carried.steps) if m is rows[0].moment), None)
            steps = None if first is None else carried.steps[first : first + len(rows)]
        before = None if carried is None else _side(carried.shot, rows, judges)
        after = _side(frame.shot, rows, judges)
        back = [] if long_enough else self._back(start, frame)
        earlier = None
        if back:  # the short shot's camera as it was at its first frame, where the window kept it (else held there)
            cut = self.cut_camera
            camera = cut[1] if cut is not None and cut[0] is rows[0] else None
            earlier = _side(rows[0].shot, back, judges, camera)._replace(stepped=camera is not None)
        players = self.columns  # the run reads no window state
        run = SlicedRun(
            lambda: _decided(rows, frame.pose, before, steps, after, previous, players, judges, back, earlier, long_enough)
        )
        until_s = -math.inf if carried is None else carried.until_s
        if carried is not None:  # stepped on as if it carried the short shot: it goes off air at this cut then
            carried.until_s = frame.moment.time_s + self.shot_s
        return Repair(rows, frame, run, before, after, carried, until_s, started, None, back, earlier, frame.pose, long_enough)

    def _back(self, start: int, frame: WorkedFrame) -> list[WorkedFrame]:
        """The last frames of the shot before the short one (its cut at `start` in the window, the
        next at `frame`) that make the short shot lengthen_s long where its cut moves to the first
        of them (`_earlier`); none where the window holds too few (window_s), the shot before would
        be left shorter than that, is a human's take, or a short shot before waits to hold on."""
        if self.holding is not None:
            return []
        frames = list(self.frames)
        start_by_s = frame.moment.time_s - self.shot_s  # the short shot shot_s long from here on
        for j in range(start - 1, -1, -1):
            if frames[j].cut or frames[j].moment.time_s <= frame.moment.time_s - self.window_s + TIME_EPSILON_S:
                return []
            if frames[j].moment.time_s <= start_by_s + TIME_EPSILON_S:
                break
        else:
            return []
        cut_s = next((f.moment.time_s for f in reversed(frames[:j]) if f.cut), self.last_cut_s)
        if frames[j].moment.time_s - cut_s < self.shot_s - TIME_EPSILON_S or frames[j].shot.held:
            return []
        return frames[j:start]

    @staticmethod
    def _give(rows: list[WorkedFrame], neighbour: Side, decision: Decision, flag: str, judges: Judges) -> None:
        for row, shown, pose, seen in zip(rows, neighbour.shown, decision.poses, decision.seen):
            row.shot, row.shown, row.pose, row.visibility = neighbour.shot, shown, pose, seen
            row.choice = judges.choice_of(neighbour.judged, shown.time_s)
            row.flags.extend((flag, KILLS_ONLY_FLAG) if decision.kills_only else (flag,))
            if decision.kill_given_up:
                row.flags.append(KILL_GIVEN_UP_FLAG)


def _alone_first(repair: Repair, alone: tuple[list[WorkedFrame], Side, Decision] | None) -> bool:
    """Whether the short shot holds on by its kills alone (the verdict `alone`) before its
    last resort: where that is a neighbour by the kills alone too, and the hold loses its
    subjects on fewer frames (on the real 4on4 a shot after started 1.5 s early, its first
    pose held where nobody was yet, over a hold of 0.4 s); or a neighbour that gives up a kill."""
    last = None if repair.decision is None else repair.decision.last_resort
    if alone is None or last is None:
        return False
    return last.kill_given_up or (last.kills_only and alone[2].lost < last.lost)


def _decided(
    rows: list[WorkedFrame],
    first: CameraPose,
    before: Side | None,
    steps: list[tuple[Moment, CameraPose, float]] | None,
    after: Side,
    previous: Shot | None,
    players: dict[str, int],
    judges: Judges,
    back: list[WorkedFrame],
    earlier: Side | None,
    long_enough: bool = False,
) -> Decision:
    """Which neighbour takes the short shot's frames (rows), and how (module docstring): the shot
    before, carried on by its shadow (its steps over the rows, None where it has none), or the shot
    after, started at them into its first pose; whichever shows its subjects more (ties to the
    shot before), among those that may take it; `previous` is the shot before the short one. Where
    neither may, the short shot itself, started earlier over the shot before's last frames (back,
    as `earlier` shows them: `_earlier`). A shot min_shot_s long already (long_enough) goes to a
    neighbour at SHOWN or stays. It reads only what its arguments held when the repair was drawn
    (moments, poses, copies)."""
    short = rows[0].shot
    kills = _kills(rows, players, judges)

    def neighbour(floors: Floors) -> Decision | None:
        judged: list[tuple[float, Decision]] = []
        if before is not None and steps is not None:
            carried = _before(rows, before, steps, short, kills, after.judged, judges, floors)
            if carried is not None:
                judged.append(carried)
        later = _after(rows, first, after, short, kills, previous, judges, floors=floors)
        if later is not None:
            judged.append(later)
        # the first of equals: the shot before
        if not judged:
            return None
        return max(judged, key=lambda j: j[0])[1]._replace(kills_only=floors is KILLS_ONLY, kill_given_up=floors is ANY)

    if long_enough:
        return neighbour(SHOWN) or Decision(None, [], [])
    strict = neighbour(STRICT)
    if strict is not None:
        return strict
    moved = None if earlier is None else _earlier(back, rows[0].pose, earlier, players, judges)
    if moved is not None:
        return moved
    return Decision(None, [], [], neighbour(LAST_RESORT) or neighbour(KILLS_ONLY) or neighbour(ANY))


def _before(
    rows: list[WorkedFrame],
    before: Side,
    steps: list[tuple[Moment, CameraPose, float]],
    short: Shot,
    kills: list[tuple[int, tuple[int, ...]]],
    other: Shot,
    judges: Judges,
    floors: Floors = STRICT,
) -> tuple[float, Decision] | None:
    """The shadow's mean visibility and steps over the short shot's frames, where it carries on
    over every one of them as a neighbour of the short shot's kind keeping its kills and the
    floors."""
    if len(steps) < len(rows) or any(m is not r.moment for (m, _, _), r in zip(steps, rows)):
        return None
    poses, seen = [pose for _, pose, _ in steps], [s for _, _, s in steps]
    if not _may_take(before.judged, short, other, rows):
        return None
    if floors.kills and not _keeps_kills(rows, kills, poses, before.judged, judges):
        return None
    judged = _judged_seen(before.shown, poses, before.judged, judges, in_frame=True)[0] if floors.in_frame else seen
    if not _keeps_seen(rows, judged, floors):
        return None
    if not _keeps_height(rows, poses, before.shown, before.judged, judges, floors):
        return None
    return float(np.mean(seen)), Decision(BEFORE, poses, seen, lost=len(_missed(rows, judged)))


def _after(
    rows: list[WorkedFrame],
    first: CameraPose,
    after: Side,
    short: Shot,
    kills: list[tuple[int, tuple[int, ...]]],
    other: Shot | None,
    judges: Judges,
    step_copy: bool = True,
    floors: Floors = STRICT,
) -> tuple[float, Decision] | None:
    """The shot after's mean visibility, poses and visibilities over the short shot's frames,
    started there into its first pose (module docstring), where it is a neighbour of its kind
    keeping its kills and the floors (step_copy: a moving camera's copy, as it is now, may step
    there)."""
    if not _may_take(after.judged, short, other, rows):
        return None
    shot, shown = after.judged, after.shown  # a replay started earlier shows earlier moments
    # through the eyes, as tall as it shows them from its cut on anyway (`_keeps_height`)
    eyes = isinstance(shot.camera, FirstPersonCamera)
    own_height = judges.height(first, shown[-1], shot) if eyes else math.nan
    # a player's eyes stand where their player will be: held still, no view of the player's, their subjects counted
    # seen only in their frame
    for poses, in_frame in (
        (_moving_earlier(shot, shown, first, judges, step_copy), floors.in_frame),
        ([first] * len(rows) if eyes else _turned_toward(shot, shown, first), floors.in_frame or eyes),
    ):
        if poses is None:
            continue
        seen, judged_mean = _judged_seen(shown, poses, shot, judges)
        judged = _judged_seen(shown, poses, shot, judges, in_frame=True)[0] if in_frame else seen
        if (
            (not floors.kills or _keeps_kills(rows, kills, poses, shot, judges))
            and _keeps_seen(rows, judged, floors)
            and _keeps_height(rows, poses, shown, shot, judges, floors, own_height)
        ):
            return judged_mean, Decision(AFTER, poses, seen, lost=len(_missed(rows, judged)))
    return None


def _earlier(back: list[WorkedFrame], first: CameraPose, short: Side, players: dict[str, int], judges: Judges) -> Decision | None:
    """The short shot started earlier, its cut moved to the first of the shot before's last frames
    (back), lengthen_s before the cut that ends it: through its player's eyes where it is a
    first-person shot, a copy of its camera as it was at its first frame stepped from the first of
    them (`_moving_earlier`: where the window kept that copy, the copy meets no wall and joins the
    first pose), else held at its first pose, where it takes those frames as a neighbour of the shot
    before would (`_after`: a replay's piece not showing its kill, a live shot's with no kill in
    them for a replay; their kills, subjects seen and players readable). None where it may not."""
    before = back[0].shot  # its frames before `back` stay its own: a replay there goes on
    kills = _kills(back, players, judges)
    moved = _after(back, first, short, before, kills, before, judges, step_copy=short.stepped)
    return None if moved is None else moved[1]._replace(neighbour=EARLIER)


def _judged_seen(
    shown: list[Moment], poses: list[CameraPose], shot: Shot, judges: Judges, start: int = 0, in_frame: bool = False
) -> tuple[list[float], float]:
    """The visibility of the shot's framed subjects from each of the poses at the moments shown,
    from `start` on ((len(poses) - start,) values), judged at every JUDGED_EVERY-th of them and
    carried to the frames between, and the mean of those judged (NaN: none; a sliced repair
    hands back between them). in_frame: the mean share of their points inside the pose's frame
    and seen from it (eval-match's shown share; 1 where it frames nobody), not the program's."""
    judged = {}
    for k in range(start, len(poses), JUDGED_EVERY):
        pause()
        if not in_frame:
            judged[k] = judges.visibility(shown[k], poses[k], shot)
        elif framed := shot.framed(shown[k].time_s):
            judged[k] = float(judges.seen(poses[k], shown[k], framed).mean())
        else:
            judged[k] = 1.0
    mean = float(np.mean(list(judged.values()))) if judged else math.nan
    return [judged[k - (k - start) % JUDGED_EVERY] for k in range(start, len(poses))], mean


def _kills(rows: list[WorkedFrame], players: dict[str, int], judges: Judges) -> list[tuple[int, tuple[int, ...]]]:
    """The kills the short shot shows: (row, (killer, victim)) where its pose at the kill's frame
    shows them (`_shows_kill`; a neighbour must show them as well); players: each player's index
    by id."""
    out: list[tuple[int, tuple[int, ...]]] = []
    for k, row in enumerate(rows):
        for event in row.moment.events:
            if event.kind != EventKind.KILL or event.actor_id not in players or event.other_actor_id not in players:
                continue
            pair = (players[event.actor_id], players[event.other_actor_id])
            if row.shown is row.moment and _shows_kill(row.shot, row.pose, row.moment, pair, judges):
                out.append((k, pair))
    return out


def _shows_kill(shot: Shot, pose: CameraPose, moment: Moment, pair: tuple[int, ...], judges: Judges) -> bool:
    """Whether the shot's pose shows a kill (killer, victim) at its moment: both seen at least
    KILL_SEEN, or, as eval-match counts it covered, the victim so through the killer's own eyes
    (its body is behind the lens: on the real 2on2 and 4on4 a repair that did not count those
    gave a kill shown through them to a shot of another player, and the suite's objective a
    kill's DUEL through its killer's eyes: docs/casting.md)."""
    through = isinstance(shot.camera, FirstPersonCamera) and shot.camera.player == pair[0]
    return bool(np.all(judges.seen(pose, moment, pair[1:] if through else pair) >= KILL_SEEN))


def _turned_toward(shot: Shot, shown: list[Moment], first: CameraPose) -> list[CameraPose]:
    """The shot's first pose over the short shot's moments (shown) where no camera of it moves
    there (`_after`): standing at its first place and turning, no roll, to keep its framed
    subjects' aims where the first pose shows them at the last of them, as a camera operator at the
    place pans onto the players coming in, no faster than TURN_DEG_S (worked back from the first
    pose, which it joins), its turn held where it frames nobody alive. Held still where the first
    pose rolls or frames nobody alive at the join. A pose held still looks where its subjects
    will be (on the real 4on4 a shot after started 1.2 s early framed nobody, by eval-match's shown
    share, on 25 of those frames, its subjects seen only by a ray)."""
    rotation = quat_to_matrix(first.rotation_xyzw)
    aim = _aim(shot, shown[-1], first.position_world) if shown else None
    if aim is None or abs(rotation[1, 0]) > 1e-9:  # level rotations only (camera.py level_rotation)
        return [first] * len(shown)
    # where the first pose shows the subjects' aims, camera space
    step_s = (shown[-1].time_s - shown[0].time_s) / max(len(shown) - 1, 1)
    return [*_panned(shot, shown[-2::-1], first, rotation.T @ aim, step_s)[::-1], first]


def _panned_on(
    shot: Shot, shown: list[Moment], held: CameraPose, held_moment: Moment, crossed: Callable[[np.ndarray, np.ndarray], bool]
) -> list[CameraPose]:
    """A hold's last pose (`_hold_verdict`: its copy met a wall or lost its subjects at
    held_moment) over the moments after it (shown): standing at its place and turning, no roll,
    onto its framed subjects alive as a camera operator there pans after the players running off,
    no faster than TURN_DEG_S, keeping them where the held pose shows them when that is within half
    its vertical field of view of its axis, else bringing them to its centre (an aim behind a wall
    or out of the frame: the pan brings them into it). Held still through a player's eyes, where
    the pose rolls, or while it frames nobody alive. On the real 2on2 at 31 Hz, two holds by the
    kills alone (issue 41's last resort for a shot under 2 s) held a pose still for 25 and 35
    frames while their player ran out of it: frames of nobody (docs/casting.md, "A held camera pans
    after its player"). Where every framed subject stands behind a wall from the place (crossed:
    the segment to its aim point meets the level), it pans onto the nearest other player alive in
    sight instead, as an operator whose player ran off finds the play it can see (`_aim_in_sight`):
    in casts of the 2on2, 42-103 frames a cast showed nobody in holds by the kills alone
    (docs/casting.md, "Where a cast's frames of nobody come from")."""
    rotation = quat_to_matrix(held.rotation_xyzw)
    if isinstance(shot.camera, FirstPersonCamera) or abs(rotation[1, 0]) > 1e-9:
        return [held] * len(shown)
    aim = _aim(shot, held_moment, held.position_world)
    toward = np.array((0.0, 0.0, -1.0)) if aim is None else rotation.T @ aim  # the camera looks down -z
    if math.degrees(math.acos(max(-1.0, min(1.0, -float(toward[2]))))) > 0.5 * held.vertical_fov_deg:
        toward = np.array((0.0, 0.0, -1.0))  # off the frame's middle: onto its centre
    step_s = (shown[-1].time_s - held_moment.time_s) / len(shown) if shown else 0.0
    return _panned(shot, shown, held, toward, step_s, functools.partial(_aim_in_sight, crossed=crossed))


def _panned(
    shot: Shot,
    moments: list[Moment],
    start: CameraPose,
    toward: np.ndarray,
    step_s: float,
    aim: Callable[[Shot, Moment, np.ndarray], np.ndarray | None] | None = None,
) -> list[CameraPose]:
    """The poses over `moments` (in the order turned through, step_s apart, s) of a camera
    standing at the level start pose's place and turning from it, no roll, to bring its framed
    subjects' mean aim (`aim`, default `_aim`) to the unit camera-space direction `toward` (3,),
    no faster than TURN_DEG_S, its turn held at a moment where it frames nobody alive."""
    place = start.position_world
    yaw, pitch = level_angles(quat_to_matrix(start.rotation_xyzw))
    limit = math.radians(TURN_DEG_S) * step_s
    poses = []
    for m in moments:
        direction = (aim or _aim)(shot, m, place)
        if direction is not None:
            target_yaw, target_pitch = level_angles(level_rotation(direction, toward))
            yaw += max(-limit, min(limit, math.remainder(target_yaw - yaw, math.tau)))
            pitch += max(-limit, min(limit, target_pitch - pitch))
        poses.append(CameraPose(place, matrix_to_quat(level_matrix(yaw, pitch)), start.vertical_fov_deg))
    return poses


def _aim(shot: Shot, moment: Moment, place: np.ndarray) -> np.ndarray | None:
    """The unit (3,) direction from a place to the mean aim of the shot's framed subjects alive at
    the moment; None where it frames none, or they stand at the place."""
    framed = [i for i in shot.framed(moment.time_s) if moment.alive[i]]
    return _toward(place, moment.aims_world[framed].mean(axis=0)) if framed else None


def _toward(place: np.ndarray, point: np.ndarray) -> np.ndarray | None:
    """The unit (3,) direction from a place to a point (3,), m; None where the point is at the place."""
    offset = point - place
    length = float(np.linalg.norm(offset))
    return None if length < 1e-6 else offset / length


def _aim_in_sight(
    shot: Shot, moment: Moment, place: np.ndarray, crossed: Callable[[np.ndarray, np.ndarray], bool]
) -> np.ndarray | None:
    """`_aim`'s direction where a framed subject alive is in sight from the place (the segment
    to its aim point meets no wall: crossed), else the unit (3,) direction to the nearest other
    player alive in sight; `_aim`'s where nobody is."""
    framed = [i for i in shot.framed(moment.time_s) if moment.alive[i]]
    if any(not crossed(place, moment.aims_world[i]) for i in framed):
        return _aim(shot, moment, place)
    others = [i for i in range(len(moment.alive)) if moment.alive[i] and i not in framed]
    for i in sorted(others, key=lambda i: float(np.linalg.norm(moment.aims_world[i] - place))):
        direction = _toward(place, moment.aims_world[i])
        if direction is not None and not crossed(place, moment.aims_world[i]):
            return direction
    return _aim(shot, moment, place)


def _moving_earlier(
    after: Shot, shown: list[Moment], first: CameraPose, judges: Judges, step_copy: bool = True
) -> list[CameraPose] | None:
    """The poses of the shot after's camera at the short shot's moments (shown), started earlier and
    moving as it would have, into `first`, its first pose: a first-person camera's eyes; a moving
    camera (a Toric one), a copy of it as it is now stepped from the first of them (the rig's
    CAMERA stage: walls, the level, the lens); None for a fixed camera, or where the copy met a
    wall or lost its subjects, or the path jumps JUMP_M in a frame, leaves the level or (but an
    eye's, which goes where its player went) crosses a wall (then its first pose is held); None
    for a moving camera too without step_copy."""
    camera = after.camera
    if isinstance(camera, FirstPersonCamera):
        poses = [camera.pose(m) for m in shown]
    elif step_copy and not isinstance(camera, StaticCamera):
        camera, poses, last = copy.copy(camera), [], None
        for k, moment in enumerate(shown):
            pause()  # a step is the rig's CAMERA stage: a sliced repair hands back between them
            stepped = judges.step(moment, 0.0 if last is None else moment.time_s - shown[k - 1].time_s, camera, after, last)
            if stepped is None or any(f in stepped[1] for f in (*ENDS_A_COPY, "held_before_wall")):
                return None
            last = stepped[0]
            poses.append(last)
    else:
        return None
    path = [p.position_world for p in [*poses, first]]
    if not all(judges.inside(p) for p in path[:-1]) or np.any(np.linalg.norm(np.diff(path, axis=0), axis=1) >= JUMP_M):
        return None
    if not isinstance(camera, FirstPersonCamera) and any(judges.crossed(a, b) for a, b in zip(path, path[1:])):
        return None
    return poses


def _keeps_kills(
    rows: list[WorkedFrame], kills: list[tuple[int, tuple[int, ...]]], poses: list[CameraPose], shot: Shot, judges: Judges
) -> bool:
    """Whether the neighbour's (shot's) poses over the short shot's frames show each of its kills
    (`_shows_kill`)."""
    return all(_shows_kill(shot, poses[k], rows[k].moment, pair, judges) for k, pair in kills)


def _keeps_seen(rows: list[WorkedFrame], seen: list[float], floors: Floors = STRICT) -> bool:
    """Whether a neighbour's visibility over the short shot's frames (seen) falls under
    SEEN_FLOOR where the short shot's did not (a picture of nobody for a shot's length) on no
    frame, or on no more than the floors' `misses` share of them and never under its `seen_min`."""
    missed = _missed(rows, seen)
    return len(missed) <= floors.misses * len(rows) and all(s >= floors.seen_min for s in missed)


def _missed(rows: list[WorkedFrame], seen: list[float]) -> list[float]:
    """A neighbour's visibility (seen) on the short shot's frames (rows) where it falls under
    SEEN_FLOOR and under the short shot's own."""
    return [s for r, s in zip(rows, seen) if s < SEEN_FLOOR and s < r.visibility]


def _keeps_height(
    rows: list[WorkedFrame],
    poses: list[CameraPose],
    shown: list[Moment],
    other: Shot,
    judges: Judges,
    floors: Floors = STRICT,
    own_height: float = math.nan,
) -> bool:
    """Whether the neighbour (its poses at the moments it shows) shows the players in its frame
    readable, the floors' height share of the frame's height (median over the judged frames),
    where the short shot showed its own so, or at least as tall as it did; or, a shot through a
    player's eyes started early, at least as tall as it shows them at its own first frame
    (own_height, NaN: none): the picture the viewer gets at its cut anyway, which the director
    took by the eyes' own floor (first_person.py `eyes_shown_height_min`). On the real duel a
    replay through the killer's eyes, its victim far off, was refused the 0.2 s of a shot cut by
    a wall before it; on the real 4on4 an eyes shot the 1.0 s of one before it."""
    judged = range(0, len(rows), JUDGED_EVERY)
    short = [judges.height(rows[k].pose, rows[k].shown, rows[k].shot) for k in judged]
    mine = [judges.height(poses[k], shown[k], other) for k in judged]
    short, mine = [h for h in short if math.isfinite(h)], [h for h in mine if math.isfinite(h)]
    if not short or not mine:
        return True
    median = float(np.median(mine))
    return median >= min(floors.height, float(np.median(short))) or median >= own_height


def _may_take(donor: Shot, short: Shot, other: Shot | None, rows: list[WorkedFrame]) -> bool:
    """Whether the donor may take the short shot's frames, `other` the short shot's other
    neighbour: a replay's piece the same replay going on, or a live shot where the replay goes on
    in its other neighbour and the piece does not show the replayed kill (the replay shortened,
    its kill never left out); a live shot's frames a live shot, or a replay where no kill happens
    in them (a replay started earlier never hides a live kill)."""
    rd, rs = donor.choice.replay, short.choice.replay
    if rs is not None:
        if rd is not None:
            return rd.kill_time_s == rs.kill_time_s
        ro = None if other is None else other.choice.replay
        shows_kill = rows[0].shown.time_s - TIME_EPSILON_S <= rs.kill_time_s <= rows[-1].shown.time_s + TIME_EPSILON_S
        return ro is not None and ro.kill_time_s == rs.kill_time_s and not shows_kill
    if rd is None:
        return True
    return not any(e.kind == EventKind.KILL for r in rows for e in r.moment.events)


def shadow_of(shot: Shot) -> tuple[Shot, ShotCamera]:
    """The shot on air and a copy of its camera as it is before a frame (what a shadow steps on)."""
    return shot, copy.copy(shot.camera)
