"""EDIT WINDOW of the MATCH rig (issue 41, item 3; docs/casting.md, "The edit window"): the rig
works the program `window_s` (the style's `min_shot_s`, 2 s) ahead of the moment it answers, on
the broadcast delay's own buffer, and keeps the frames it has worked out and not yet answered.
A cut within a shot (a camera met a wall, its player teleported: rig.py) is found the frame it
happens; here the frames before it are still the rig's to change. Where a cut comes under
`min_shot_s` after the one before, the short shot between is given to a neighbour:

- to the shot before, carried on: a copy of the camera that went off air at a cut is stepped on
  for `window_s` after it (the `Shadow`, as camera_ahead.py steps one for a frame), and holds its
  poses where it met no wall, lost its subjects nowhere (a copy is never re-placed) and jumped
  nowhere over the short shot's frames;
- or to the shot after, started earlier: through the same eyes where it is a first-person shot
  whose player does not jump there, a copy of its camera stepped from the short shot's first frame
  where it moves (a Toric camera) and meets no wall on the way, else its first pose held still;

whichever shows its subjects more over those frames (the share of their points seen, visibility.py;
ties to the shot before), among the neighbours that
- may take it (`_may_take`): a replay's piece goes to the same replay, or to a live shot where the
  replay goes on on its other side and the piece does not show its kill (never left out); a live
  shot's to a live one, or to a replay starting earlier where no kill happens in its frames;
- show each kill the short shot showed (killer and victim each with KILL_SEEN of their points in
  the frame and seen at the kill's frame, as eval-match counts a kill covered);
- show their subjects at least SEEN_FLOOR on every frame the short shot showed its own so (no
  picture of nobody where there was one of somebody);
- and show the players in their frame readable, HEIGHT_FLOOR of its height (median), where the
  short shot did, or as tall as it did.
A short shot that has none stays, flagged; a human's take is never given away.

The offline bound that led to it (load_tests/edit_window_bound.py) gave every short shot of the
real matches' programs to a neighbour, a held pose where no eyes carried on; here the shot before
goes on moving.
"""

from __future__ import annotations

import copy
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.pipeline.inputs import EventKind
from camdirector.pipeline.match.first_person import FirstPersonCamera
from camdirector.pipeline.match.frame import PlannedCut, ShotChoice
from camdirector.pipeline.match.moments import TIME_EPSILON_S, Moment
from camdirector.pipeline.match.program_camera import CUT_TO_SEEN_PLACE, HOLD_LEFT_FOR_CUT, SUBJECTS_LOST
from camdirector.pipeline.match.program_shot import CandidateShot, Shot, ShotCamera
from camdirector.pipeline.match.shots import StaticCamera

JUMP_M = 2.0  # a camera or an eye moving this far between two frames jumped (a teleport, a respawn): no carrying across, m
KILL_SEEN = 0.5  # a kill in a short shot's frames is shown where killer and victim each have this share of points seen
SEEN_FLOOR = 0.5  # a neighbour may not show its subjects less than this (eval-match's shown fraction) where the short
# shot showed its own more
HEIGHT_FLOOR = 0.15  # the median shown height issue 41 bars, share of the frame's height
JUDGED_EVERY = 3  # a neighbour's visibility over a short shot is judged at every this-th frame (a frame's ray budget)
CARRIED_ON = "edit_window_carried_on"  # a short shot's frames given to the shot before
STARTED_EARLY = "edit_window_started_early"  # a short shot's frames given to the shot after
SHORT_LEFT = "edit_window_short_left"  # a short shot neither neighbour could take
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
    docstring): its poses and visibility at each worked frame from the cut, until `until_s`."""

    shot: Shot
    camera: ShotCamera  # a copy, as it was before the cut's frame
    last_pose: CameraPose
    until_s: float  # stepped until this program time, s
    steps: list[tuple[Moment, CameraPose, float]] = field(default_factory=list)  # (moment, pose, visibility) from the cut
    alive: bool = True  # False once it met a wall, lost its subjects or jumped


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
    (module docstring). `window_s` 0 answers each frame as it is worked out: no repairs."""

    def __init__(self, min_shot_s: float, players: list[str]):
        self.min_shot_s = min_shot_s
        self.players = players
        self.frames: deque[WorkedFrame] = deque()
        self.shadow: Shadow | None = None
        self.answered: WorkedFrame | None = None  # the last frame answered
        self.last_cut_s = -math.inf  # program time of the last cut answered, s

    def drop(self) -> None:
        """Forgets the frames not yet answered (a take applies at once: rig.py)."""
        self.frames.clear()
        self.shadow = None

    def last_pose(self) -> CameraPose | None:
        """The pose of the newest frame worked out (or answered)."""
        last = self.frames[-1] if self.frames else self.answered
        return None if last is None else last.pose

    def step_shadow(self, moment: Moment, dt_s: float, judges: Judges) -> None:
        """The shadow stepped to the worked frame's moment while it lives and its window lasts."""
        shadow = self.shadow
        if shadow is None or not shadow.alive or moment.time_s > shadow.until_s + TIME_EPSILON_S:
            return
        shown = judges.shown_of(shadow.shot, moment)
        stepped = judges.step(shown, dt_s, shadow.camera, shadow.shot, shadow.last_pose)
        if stepped is None:
            shadow.alive = False
            return
        pose, flags = stepped
        moved = pose.position_world - shadow.last_pose.position_world
        if (
            any(f in flags for f in ENDS_A_COPY)
            or float(np.linalg.norm(moved)) >= JUMP_M
            or judges.crossed(shadow.last_pose.position_world, pose.position_world)
        ):
            shadow.alive = False
            return
        shadow.steps.append((moment, pose, judges.visibility(shown, pose, shadow.shot)))
        shadow.last_pose = pose

    def push(self, frame: WorkedFrame, before: tuple[Shot, ShotCamera] | None, judges: Judges) -> None:
        """A newly worked frame joins the window; a cut under min_shot_s after the last one in the
        window gives the short shot to a neighbour (module docstring); a cut left a cut starts a
        shadow of the camera `before` it (the shot on air and a copy of its camera as they were
        before the frame), its last pose the newest frame's."""
        carried = frame.cut and self._repaired(frame, judges)
        if frame.cut and not carried and before is not None:
            last = self.last_pose()
            if last is not None:
                self.shadow = Shadow(before[0], before[1], last, frame.moment.time_s + self.min_shot_s)
        self.frames.append(frame)

    def answer(self, moment: Moment) -> tuple[WorkedFrame, bool]:
        """The frame of the program moment (the newest worked out at or before it), and whether
        the program cuts there (a frame passed over with a cut counts: the picture changed)."""
        cut = False
        while self.frames and self.frames[0].moment.time_s <= moment.time_s + TIME_EPSILON_S:
            frame = self.frames.popleft()
            cut |= frame.cut
            if frame.cut:
                self.last_cut_s = frame.moment.time_s
            self.answered = frame
        assert self.answered is not None  # the rig works the program moment out before it answers it
        return self.answered, cut

    def next_cut(self) -> PlannedCut | None:
        """The next cut already worked out, not yet answered, to the shot the director chose (its
        picture may frame one of it first: `WorkedFrame.choice`)."""
        return next((PlannedCut(f.moment.time_s, f.shot.choice) for f in self.frames if f.cut), None)

    # -- the repairs ----------------------------------------------------------------------
    def _repaired(self, frame: WorkedFrame, judges: Judges) -> bool:
        """Whether the short shot before the frame's cut, if any, was given to the shot before
        (the cut before removed; True) or to the shot after (this frame's cut removed, False, and
        frame.cut cleared); False with nothing to repair or none to give it to."""
        start = next((i for i in range(len(self.frames) - 1, -1, -1) if self.frames[i].cut), None)
        if start is None or frame.moment.time_s - self.frames[start].moment.time_s >= self.min_shot_s - TIME_EPSILON_S:
            return False
        rows = list(self.frames)[start:]
        short = rows[0].shot
        if short.held:  # a human's take is on air as long as the human held it
            return False
        kills = self._kills(rows, judges)
        previous = self.frames[start - 1].shot if start > 0 else self.answered.shot if self.answered is not None else None
        before = self._before(rows, short, kills, frame.shot, judges)
        after = self._after(rows, frame, short, kills, previous, judges)
        judged = [
            (share, k)
            for k, share in (("before", before[0] if before else None), ("after", after[0] if after else None))
            if share is not None
        ]
        if not judged:
            rows[0].flags.append(SHORT_LEFT)
            return False
        best = max(judged, key=lambda j: j[0])[1]  # the first of equals: the shot before
        if best == "before":
            assert before is not None and self.shadow is not None
            for row, (_, pose, seen) in zip(rows, before[1]):
                self._give(row, self.shadow.shot, pose, seen, CARRIED_ON, judges)
            rows[0].cut = False
            self.shadow.until_s = frame.moment.time_s + self.min_shot_s  # it goes off air at this frame's cut now
            return True
        assert after is not None
        for row, pose, seen in zip(rows, after[1], after[2]):
            self._give(row, frame.shot, pose, seen, STARTED_EARLY, judges)
        frame.cut = False
        return False

    @staticmethod
    def _give(row: WorkedFrame, shot: Shot, pose: CameraPose, seen: float, flag: str, judges: Judges) -> None:
        row.shot, row.pose, row.visibility = shot, pose, seen
        row.shown = judges.shown_of(shot, row.moment)
        row.choice = judges.choice_of(shot, row.shown.time_s)
        row.flags.append(flag)

    def _before(
        self, rows: list[WorkedFrame], short: Shot, kills: list[tuple[int, tuple[int, ...]]], other: Shot, judges: Judges
    ) -> tuple[float, list[tuple[Moment, CameraPose, float]]] | None:
        """The shadow's mean visibility and steps over the short shot's frames, where it carries
        on over every one of them as a neighbour of the short shot's kind keeping its kills."""
        shadow = self.shadow
        if shadow is None:
            return None
        # from the short shot's first frame: a shadow carried on over an earlier short shot stepped from before it
        first = next((k for k, (m, _, _) in enumerate(shadow.steps) if m is rows[0].moment), None)
        steps = [] if first is None else shadow.steps[first : first + len(rows)]
        if len(steps) < len(rows) or any(m is not r.moment for (m, _, _), r in zip(steps, rows)):
            return None
        if not _may_take(shadow.shot, short, other, rows) or not _keeps_kills(
            rows, kills, [pose for _, pose, _ in steps], judges
        ):
            return None
        if not _keeps_seen(rows, [seen for _, _, seen in steps]):
            return None
        shown = [judges.shown_of(shadow.shot, r.moment) for r in rows]
        if not _keeps_height(rows, [pose for _, pose, _ in steps], shown, shadow.shot, judges):
            return None
        return float(np.mean([seen for _, _, seen in steps])), steps

    @staticmethod
    def _after(
        rows: list[WorkedFrame],
        frame: WorkedFrame,
        short: Shot,
        kills: list[tuple[int, tuple[int, ...]]],
        other: Shot | None,
        judges: Judges,
    ) -> tuple[float, list[CameraPose], list[float]] | None:
        """The shot after's mean visibility, poses and visibilities over the short shot's frames,
        started there (module docstring), where it is a neighbour of its kind keeping its kills."""
        after = frame.shot
        if not _may_take(after, short, other, rows):
            return None
        shown = [judges.shown_of(after, r.moment) for r in rows]  # a replay started earlier shows earlier moments
        for poses in (_moving_earlier(after, shown, frame.pose, judges), [frame.pose] * len(rows)):
            if poses is None:
                continue
            judged = {k: judges.visibility(shown[k], poses[k], after) for k in range(0, len(rows), JUDGED_EVERY)}
            seen = [judged[k - k % JUDGED_EVERY] for k in range(len(rows))]
            if (
                _keeps_kills(rows, kills, poses, judges)
                and _keeps_seen(rows, seen)
                and _keeps_height(rows, poses, shown, after, judges)
            ):
                return float(np.mean(list(judged.values()))), poses, seen
        return None

    def _kills(self, rows: list[WorkedFrame], judges: Judges) -> list[tuple[int, tuple[int, ...]]]:
        """The kills the short shot shows: (row, (killer, victim)) where both are seen at least
        KILL_SEEN from its pose at the kill's frame (a neighbour must show them as well)."""
        index = {p: i for i, p in enumerate(self.players)}
        out: list[tuple[int, tuple[int, ...]]] = []
        for k, row in enumerate(rows):
            for event in row.moment.events:
                if event.kind != EventKind.KILL or event.actor_id not in index or event.other_actor_id not in index:
                    continue
                pair = (index[event.actor_id], index[event.other_actor_id])
                if row.shown is row.moment and np.all(judges.seen(row.pose, row.moment, pair) >= KILL_SEEN):
                    out.append((k, pair))
        return out


def _moving_earlier(after: Shot, shown: list[Moment], first: CameraPose, judges: Judges) -> list[CameraPose] | None:
    """The poses of the shot after's camera at the short shot's moments (shown), started earlier and
    moving as it would have, into `first`, its first pose: a first-person camera's eyes; a moving
    camera (a Toric one), a copy of it as it is now stepped from the first of them (the rig's
    CAMERA stage: walls, the level, the lens); None for a fixed camera, or where the copy met a
    wall or lost its subjects, or the path jumps JUMP_M in a frame, leaves the level or (but an
    eye's, which goes where its player went) crosses a wall (then its first pose is held)."""
    camera = after.camera
    if isinstance(camera, FirstPersonCamera):
        poses = [camera.pose(m) for m in shown]
    elif not isinstance(camera, StaticCamera):
        camera, poses, last = copy.copy(camera), [], None
        for k, moment in enumerate(shown):
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
    rows: list[WorkedFrame], kills: list[tuple[int, tuple[int, ...]]], poses: list[CameraPose], judges: Judges
) -> bool:
    """Whether the neighbour's poses over the short shot's frames show each of its kills as it did."""
    return all(np.all(judges.seen(poses[k], rows[k].moment, pair) >= KILL_SEEN) for k, pair in kills)


def _keeps_seen(rows: list[WorkedFrame], seen: list[float]) -> bool:
    """Whether a neighbour's visibility over the short shot's frames (seen) falls under
    SEEN_FLOOR on no frame where the short shot's did not (a picture of nobody for a shot's length)."""
    return all(s >= SEEN_FLOOR or s >= r.visibility for r, s in zip(rows, seen))


def _keeps_height(rows: list[WorkedFrame], poses: list[CameraPose], shown: list[Moment], other: Shot, judges: Judges) -> bool:
    """Whether the neighbour (its poses at the moments it shows) shows the players in its frame
    readable, HEIGHT_FLOOR of the frame's height (median over the judged frames), where the short
    shot showed its own so, or at least as tall as it did."""
    judged = range(0, len(rows), JUDGED_EVERY)
    short = [judges.height(rows[k].pose, rows[k].shown, rows[k].shot) for k in judged]
    mine = [judges.height(poses[k], shown[k], other) for k in judged]
    short, mine = [h for h in short if math.isfinite(h)], [h for h in mine if math.isfinite(h)]
    return not short or not mine or float(np.median(mine)) >= min(HEIGHT_FLOOR, float(np.median(short)))


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
