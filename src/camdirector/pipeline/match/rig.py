"""The MATCH rig of a session: the program of a whole match, chosen among the players by
events and interest, shown with the broadcast delay (issue 12).

Per frame `MatchRig.run` (stage timings in `stage_ms`: `buffer`, `plan`, `camera`, `visibility`):
1. buffer   the frame's players and events join the buffered moments (moments.py); the program's
            moment is the newest one at or before `time_s - delay_s`. Until one exists the
            answer is `buffering` with no pose. `state.frame`, `time_s`, `dt_s` and
            `aim_points_world` become the program moment's (the input frame's number stays the
            Session's business: Session.is_stale compares with the last answered state, whose
            frame is now the program's, so a re-sent input frame is also refused here, by the
            buffer, and flagged `match_stale_frame`).
2. plan     at `plan_rate_hz` (and at once after a take), the director of the style decides
            whether to cut: ours (plan.py), the HLTV baseline (hltv.py) or ezQuake's autotrack
            (autotrack.py: it ranks by the players' stats, `player_stats`, each player's latest
            sent with a frame up to the program moment); a human's take (`take`) overrides them
            until released. Ours also re-places an occluded camera
            within its shot (shots.py) and offers the best other situations as candidates.
            Ours is off the frame path (below): each tick applies the plan drawn at the tick
            before and draws the next.
3. camera   every frame, the shot's camera at the program moment; a Toric camera from whose place
            walls hide most of its first subject comes in front of the wall (shots.py `pulled_in`,
            flagged `pulled_in_front_of_wall`).
4. visibility  the share of the framed subjects' sample points seen from the camera.
Every cut's `shot.reason` says why, its sub-scores go to `scores`, and degraded choices to `flags`.

Our plan is drawn at a tick for the buffered moment of the next, `plan_interval_s` later, and
applied then (the moment it was made for; made for the tick that drew it, one kill in 14 of the
real duel's first 3 minutes went unshown, 0.786 -> 0.714 kill coverage): drawn, it holds
what it reads (the buffer's view, a copy of the shot's camera, the last pose), and the session's
worker computes it in slices of `PLAN_SLICE_S` in its idle moments (infra/slices.py; the pause
points are the place searches' ray casts, shots.py `framed_seen`). A plan is applied at the first
tick by which it needed at most `plan_work_per_tick` of work per tick since it was drawn (its work
counted in camera-point pairs, the same on any machine); until then no other plan is drawn (flag
`plan_late`), and each tick computes it up to that much, whatever the idle moments left. On the
4on4's first minute on dm2 a plan costs 9 ms on average and up to 140 ms (3.7 ms per 1e4 pairs),
against 3 ms for the rest of a frame; 3% of plans need more than one tick's 1e5 pairs, mostly the
searches of a new kill's joint shot (`_join`). Computed whole in the frame that applies it (the
rule before), the server's compute p99 was 25 ms at 30 Hz and 8.9 ms at 60 Hz (load_tests/
match_live.py); applied by its work, 8.1 and 5.7 ms; with the camera's steps worked out ahead
(below) and snapshots that no longer grow with the match (moments.py), 3.1 ms at both rates.
Applied by its work, the program does not depend on when, in how many slices or on
how fast a machine it was computed, only on its inputs: a take or a style change, which would
change what a drawn plan reads, finishes it first. The first shot and a take's are planned at
once; the baselines (cheap) and a session with dynamic objects (whose ray scene every frame moves)
plan in the frame, as before.

Ahead: with a delay, the next frame's program moment is most likely the next buffered one,
known already. After a frame the rig works out, in the worker's idle moments (its deferred work,
before the drawn plan's slices), that moment's CAMERA and VISIBILITY from a copy of the shot's
camera, and the candidates' poses (those of the drawn plan too, once computed: the tick that
applies it shows them). The frame takes them when they are its own: the same moment and time
step, the same shot, style and pose shown before, and the camera's attributes the same objects
(cameras change only by assigning them, so a tick's new goal or pair window, or a cut, shows);
otherwise it computes them as before. What a frame answers does not depend on whether they were
worked out ahead (tests/pipeline/match/test_match_rig.py). A session with dynamic objects does
not look ahead. On the 4on4's first 40 s at 30 Hz, paced, in process, a frame's median went
2.5 -> 1.0 ms and its p99 4.3 -> 2.8 ms; of the frames that tick, 1.2 ms (those that apply a plan
that changes the camera compute their step).

A take whose held subject dies (at the program moment) falls back, still held: to the player
who killed it, else the nearest fight to where it died, else an overview; `shot.reason` says so.

`MatchRig` implements `CameraRig` (pipeline/camera_rig.py) with, of what only some rigs do, its
player inputs (game events and a human's takes: it is its own `PlayerInputs`) and the program's
delayed target transforms; it has no occlusion maps; its deferred work is the drawn plan. Its part of a frame's
state is `MatchFrame` (frame.py), made anew every frame.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections import deque
from collections.abc import Callable, Mapping

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform, quat_to_matrix
from camdirector.infra.slices import SlicedRun
from camdirector.infra.stage_clock import StageClock
from camdirector.pipeline.inputs import FrameInput, PlayerStats, SceneSpec
from camdirector.pipeline.match.autotrack import AutotrackDirector
from camdirector.pipeline.match.frame import Candidate, MatchFrame, PlannedCut, ShotChoice, ShotKind
from camdirector.pipeline.match.grammar import Grammar
from camdirector.pipeline.match.hltv import HltvDirector
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.plan import Beat, PlannedDirector, Shot, ShotBuilder
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import Place, ToricCamera, best_place, framed_seen, place_grid
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.pipeline.stages import MatchStage
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import MatchDirectorKind, Style

REPLACE_LOOKAHEAD_S = 1.0  # an occluded place is replaced by the best one over now and this far ahead, s
PLAN_SLICE_S = 0.002       # a drawn plan is computed this long per idle moment of the worker, s


@dataclasses.dataclass
class PlanResult:
    """What one planning tick decided, applied to the program at once or at the next tick."""

    shot: Shot | None                  # the cut, None: the current shot goes on
    goal: Place | None                 # the current Toric camera's new goal (re-placed for visibility)
    pair_place: Place | None           # its pair window's new place (re-placed for visibility)
    held: ShotChoice | None            # the take held from now on (a fallback when its subject died)
    candidates: list[tuple[ShotChoice, ToricCamera | None, float]]
    beats: list[Beat]                  # our director's plan (MatchRig.planned_cut)
    flags: list[str]


@dataclasses.dataclass
class DrawnPlan:
    """A plan drawn at a tick with what it reads, computed in slices until the tick that applies
    it (module docstring)."""

    current: Shot
    run: SlicedRun[PlanResult] | None  # None once finished (a snapshot pickles the rig)
    result: PlanResult | None = None
    work: float = 0.0                  # its whole work once finished, camera-point pairs (infra/slices.py)
    ticks: int = 0                     # the ticks since it was drawn

    def finish(self) -> PlanResult:
        if self.run is not None:
            self.result, self.work, self.run = self.run.finish(), self.run.work, None
        return self.result

    def due(self, work_per_tick: float) -> bool:
        """At a tick: whether it is applied now, i.e. whether its whole work is at most
        work_per_tick per tick since it was drawn. Computes it up to that much (what the idle
        moments left); the answer depends on its work alone, not on time."""
        self.ticks += 1
        allowed = self.ticks * work_per_tick
        if self.run is not None and self.run.run_until(allowed):
            self.finish()
        return self.run is None and self.work <= allowed


@dataclasses.dataclass
class CameraStep:
    """The CAMERA and VISIBILITY stages of a frame with no cut, worked out ahead (module docstring,
    "Ahead"): what they made of the shot's camera, and what the frame shows."""

    moment: Moment
    dt_s: float
    shot: Shot                    # the shot, and its camera, it is a step of
    camera: object
    camera_before: dict           # the camera's attributes it stepped from (compared by identity)
    camera_after: dict            # and those it left
    last_pose: CameraPose | None  # the pose shown before, held when the camera has none
    style: Style
    pose: CameraPose
    flags: list[str]
    visibility: float             # mean share of the framed subjects seen


@dataclasses.dataclass
class CandidatePoses:
    """The candidates' cameras' poses at a moment (None: an OVERVIEW candidate's, the program's)."""

    moment: Moment
    candidates: list[tuple[ShotChoice, ToricCamera | None, float]]   # the list they are of (by identity)
    poses: list[CameraPose | None]


class MatchRig:
    """The match director of one session; implements `CameraRig` (module docstring). Players are
    the scene's targets."""

    def __init__(self, scene: SceneSpec, ray_scene: RayScene, rng: np.random.Generator,
                 clock: Callable[[], float] = time.perf_counter, settings: MatchSettings = MatchSettings()):
        self.players = [t.id for t in scene.targets]
        self.player_ids = frozenset(self.players)  # PlayerInputs: whom events and takes may name
        self.index = {p: i for i, p in enumerate(self.players)}
        self.teams = np.array([t.team for t in scene.targets])
        self.roster = tuple((t.id, t.team) for t in scene.targets)  # MatchFrame.players, shared by every frame
        self.lens, self.style, self.delay_s = scene.lens, scene.style, scene.delay_s
        self.ray_scene, self.rng, self.clock, self.settings = ray_scene, rng, clock, settings
        self.buffer = MomentBuffer(self.players, settings)
        self.visibility = SubjectVisibility(ray_scene, [t.mesh for t in scene.targets], settings.samples_per_player, rng)
        self.level_nodes = (scene.level.artifact.nodes_world if scene.level is not None
                            else np.zeros((0, 3)))
        self.builder = ShotBuilder(self.players, self.style, self.lens, settings, self.visibility,
                                   Grammar(settings.jump_cut_deg), self.level_nodes)
        self.planned = PlannedDirector(self.players, self.teams, settings, self.builder, self.delay_s)
        self._stats: dict[str, PlayerStats] = {}  # each player's latest stats sent up to the program moment
        self._stats_ahead: deque[tuple[float, list[PlayerStats]]] = deque()  # (frame time s, stats) not yet on air
        # the directors' view, read only by its type (a mappingproxy would not pickle into the checkpoint)
        self.player_stats: Mapping[str, PlayerStats] = self._stats
        self.director = self._director(self.style.match_director)
        self.shot: Shot | None = None
        self.held: ShotChoice | None = None
        self._take_pending = False
        self._drawn: DrawnPlan | None = None
        self._beats: list[Beat] = []  # our director's plan as of the last applied tick
        # a session whose objects move every frame plans in the frame (its ray scene is the frame's)
        self._defer_plans = not any(o.dynamic for o in scene.objects)
        self._next_plan_s = -math.inf
        self._last_time_s: float | None = None
        self._last_pose: CameraPose | None = None
        self._candidates: list[tuple[ShotChoice, ToricCamera | None, float]] = []
        self._ahead_for: Moment | None = None    # the next frame's likely moment, not yet worked out ahead
        self._ahead: CameraStep | None = None     # the camera's step to it, worked out ahead
        self._ahead_candidates: list[CandidatePoses] = []  # the candidates' poses at it
        self.program_transforms: list[RigidTransform] | None = None  # the players at the program's moment (None: buffering)

    def _director(self, kind: MatchDirectorKind) -> PlannedDirector | HltvDirector | AutotrackDirector:
        if kind == MatchDirectorKind.HLTV:
            return HltvDirector(self.players, self.settings, self.lens, self.ray_scene, self.rng, self.delay_s,
                                self.level_nodes)
        if kind == MatchDirectorKind.AUTOTRACK:
            return AutotrackDirector(self.players, self.teams, self.lens, self.player_stats)
        return self.planned

    def _stats_to(self, time_s: float) -> None:
        """The stats sent with the frames up to the program moment (time_s) join the directors' view."""
        while self._stats_ahead and self._stats_ahead[0][0] <= time_s:
            self._stats.update((stats.id, stats) for stats in self._stats_ahead.popleft()[1])

    def set_style(self, style: Style) -> None:
        """From the next frame on; the current shot goes on (a new director decides at its next tick)."""
        self._finish_drawn()  # the drawn plan reads the style
        if style.match_director != self.style.match_director:
            self.director = self._director(style.match_director)
        self.style = self.builder.style = style

    @property
    def player_inputs(self) -> MatchRig:
        """CameraRig: a frame's game events and a human's takes (`take`) name this rig's players."""
        return self

    def anticipation_map(self, state: FrameState | None) -> None:
        """CameraRig: None, the match rig has no occlusion maps (it ray-casts its candidate places)."""
        return None

    @property
    def has_deferred_work(self) -> bool:
        """CameraRig: whether the next frame's camera is to be worked out ahead, or a drawn plan
        waits to be computed."""
        return self._ahead_for is not None or self.plan_waiting

    @property
    def plan_waiting(self) -> bool:
        """Whether a drawn plan waits to be computed (a part of has_deferred_work)."""
        return self._drawn is not None and self._drawn.run is not None

    def do_deferred_work(self, whole: bool = True) -> bool:
        """CameraRig: works the next frame's camera out ahead (first: it is due soonest), else
        computes the drawn plan, whole or for PLAN_SLICE_S; whether there was any."""
        if self._ahead_for is not None:
            self._work_ahead(self._ahead_for)
            self._ahead_for = None
            if not whole:
                return True
        drawn = self._drawn
        if drawn is None or drawn.run is None:
            return False
        if whole:
            drawn.finish()
        elif drawn.run.step(PLAN_SLICE_S):
            drawn.finish()
        return True

    def _finish_drawn(self) -> None:
        if self._drawn is not None:
            self._drawn.finish()

    def close(self) -> None:
        """Drops the buffered moments."""
        self.buffer = MomentBuffer(self.players, self.settings)

    def planned_cut(self, now_s: float) -> PlannedCut | None:
        """The next cut our director planned at its last tick that is still ahead of now_s; None
        while a take is held, under the HLTV baseline, or with nothing planned (no delay: no known future)."""
        if self.held is not None or self.director is not self.planned:
            return None
        beat = next((b for b in self._beats if b.cut_s is not None and b.cut_s > now_s), None)
        if beat is None:
            return None
        return PlannedCut(beat.cut_s, ShotChoice(tuple(self.players[i] for i in beat.subjects), beat.kind,
                                                 "planned " + beat.reason))

    # -- a human's choice -------------------------------------------------------------------
    def take(self, subject_ids: list[str], kind: ShotKind | None, release: bool) -> ShotChoice | None:
        """Holds a human's shot from the next frame until released; returns it (None on release).
        kind None: FOLLOW for one player, DUEL for two, GROUP for more, OVERVIEW for none.
        Raises ValueError for an unknown or repeated player or a kind that does not fit the count."""
        self._finish_drawn()  # the drawn plan reads the take
        if release:
            self.held, self._take_pending = None, True
            return None
        unknown = [s for s in subject_ids if s not in self.index]
        if unknown:
            raise ValueError(f"take: unknown player {unknown[0]!r}; the players are {', '.join(self.players)}")
        if len(set(subject_ids)) != len(subject_ids):
            raise ValueError("take: a player is named twice")
        n = len(subject_ids)
        if kind is None:
            kind = {0: ShotKind.OVERVIEW, 1: ShotKind.FOLLOW, 2: ShotKind.DUEL}.get(n, ShotKind.GROUP)
        fits = {ShotKind.FOLLOW: n == 1, ShotKind.DUEL: n == 2, ShotKind.GROUP: 2 <= n <= self.settings.max_group,
                ShotKind.OVERVIEW: True}[ShotKind(kind)]
        if not fits:
            raise ValueError(f"take: a {ShotKind(kind).name} shot cannot show {n} players")
        self.held = ShotChoice(tuple(subject_ids), ShotKind(kind), "take: a human's choice, held until released",
                               held=True)
        self._take_pending = True
        return self.held

    def _held_shot(self, moment: Moment, buffer: MomentBuffer, current: Shot | None,
                   flags: list[str]) -> tuple[Shot | None, ShotChoice]:
        """The held take as a shot when it must be (re)built: just taken, or a held subject died;
        and the take held from now on (the fallback's, when one died)."""
        held = self.held
        subjects = tuple(self.index[s] for s in held.subject_ids)
        dead = [i for i in subjects if not moment.alive[i]]
        if not dead and not self._take_pending and current is not None and current.held:
            return None, held
        if dead:
            choice, subjects = self._fallback(moment, buffer, dead[0])
            choice = held = dataclasses.replace(choice, held=True)
            flags.append("take_fallback")
        else:
            choice = held
            previewed = self._previewed(choice, moment)
            if previewed is not None:
                return previewed, held
        shot, _ = self.builder.build(choice, subjects, moment, [moment], current, None, moment.time_s)
        shot.held = True
        return shot, held

    def _previewed(self, choice: ShotChoice, moment: Moment) -> Shot | None:
        """A take of a shot the candidates offer goes to air as its preview monitor showed it:
        the candidate's own camera and place, not a new search (a human took what they saw; the
        30-degree rule is theirs to judge). None when no candidate matches the take."""
        for candidate, camera, _ in self._candidates:
            if camera is None or candidate.kind != choice.kind or set(candidate.subject_ids) != set(choice.subject_ids):
                continue
            if choice.kind == ShotKind.DUEL:
                self.builder.grammar.remember_duel(self.players[camera.a_index], self.players[camera.b_index])
            shot = Shot(choice, tuple(self.index[s] for s in candidate.subject_ids), camera, moment.time_s)
            shot.held = True
            return shot
        return None

    def _fallback(self, moment: Moment, buffer: MomentBuffer, dead: int) -> tuple[ShotChoice, tuple[int, ...]]:
        who = self.players[dead]
        killer = buffer.killed_by.get(who)
        if killer is not None and moment.alive[self.index[killer]]:
            return (ShotChoice((killer,), ShotKind.FOLLOW,
                               f"take fallback: held player {who} died (killed by {killer}); following {killer}"),
                    (self.index[killer],))
        place = moment.feet_world[dead]
        fights = [o for o in self.planned.options(moment, buffer) if o.kind == ShotKind.DUEL]
        if fights:
            nearest = min(fights, key=lambda o: float(np.linalg.norm(moment.feet_world[list(o.subjects)].mean(axis=0)
                                                                      - place)))
            names = tuple(self.players[i] for i in nearest.subjects)
            return (ShotChoice(names, ShotKind.DUEL,
                               f"take fallback: held player {who} died; the nearest fight, {names[0]} vs {names[1]}"),
                    nearest.subjects)
        return ShotChoice((), ShotKind.OVERVIEW, f"take fallback: held player {who} died; no fight, overview"), ()

    # -- the frame --------------------------------------------------------------------------
    def run(self, state: FrameState, update: FrameInput, target_transforms: list[RigidTransform],
            last: FrameState | None) -> None:
        """BUFFER, PLAN, CAMERA and VISIBILITY (module docstring) into state and its part
        `state.match`, timed into state.stage_ms."""
        match = state.match = MatchFrame(self.roster)
        stages = StageClock(clock=self.clock, timings_ms=state.stage_ms)
        if not self.buffer.push(update.frame, update.time_s, target_transforms, state.aim_points_world, update.events):
            state.flags.append("match_stale_frame")
        elif update.player_stats:
            self._stats_ahead.append((update.time_s, update.player_stats))
        moment = self.buffer.program_moment(update.time_s - self.delay_s)
        if moment is not None:
            self._stats_to(moment.time_s)
        stages.done(MatchStage.BUFFER)
        self.program_transforms = None if moment is None else moment.transforms
        if moment is None:
            match.buffering, state.pose, state.visibility = True, None, 0.0
            state.flags.append("buffering")
            return
        state.frame, state.time_s = moment.frame, moment.time_s
        state.dt_s = 0.0 if self._last_time_s is None else max(0.0, moment.time_s - self._last_time_s)
        state.aim_points_world = list(moment.aims_world)
        self._last_time_s = moment.time_s
        cut = False
        if self._take_pending or self.shot is None or moment.time_s >= self._next_plan_s:
            self._next_plan_s = moment.time_s + self.settings.plan_interval_s
            cut = self._tick(moment, state.flags)
        stages.done(MatchStage.PLAN)
        dt_s = 0.0 if cut else state.dt_s
        ahead, self._ahead = self._ahead, None
        camera = self.shot.camera
        worked_out = ahead is not None and self._ahead_holds(ahead, moment, dt_s, camera)
        if worked_out:
            vars(camera).update(ahead.camera_after)
            pose, flags = ahead.pose, ahead.flags
        else:
            stepped = self._camera_step(moment, dt_s, camera)
            if stepped is None:  # a degenerate first shot: look from the overview
                self.shot = self.builder.build(ShotChoice((), ShotKind.OVERVIEW, "overview: degenerate framing"), (),
                                               moment, [moment], None, None, moment.time_s)[0]
                stepped = self._camera_step(moment, dt_s, self.shot.camera)
            pose, flags = stepped
        state.flags.extend(flags)
        state.pose, state.cut = pose, cut
        match.candidates = self._candidate_views(moment, pose)
        self._last_pose, self._ahead_candidates = pose, []
        stages.done(MatchStage.CAMERA)
        state.visibility = ahead.visibility if worked_out else self._visibility(moment, pose)
        # the next frame's moment is most likely the next buffered one: its camera is worked out
        # in the worker's idle moments (a session whose ray scene moves every frame cannot)
        self._ahead_for = self.buffer.following(moment) if self._defer_plans else None
        subjects = self.shot.framed(moment.time_s)
        match.shot = self.shot.choice if subjects == self.shot.subjects else dataclasses.replace(
            self.shot.choice, subject_ids=tuple(self.players[i] for i in subjects), kind=ShotKind.FOLLOW,
            reason=f"{self.shot.choice.reason}; framing {self.players[subjects[0]]} alone away from the pair's kills")
        match.events, match.planned_cut = moment.events, self.planned_cut(moment.time_s)
        state.scores = dict(self.shot.scores, visibility=state.visibility,
                            shot_length_s=moment.time_s - self.shot.start_s)
        stages.done(MatchStage.VISIBILITY)

    # -- the camera's step, in the frame or ahead of it -------------------------------------
    def _camera_step(self, moment: Moment, dt_s: float, camera) -> tuple[CameraPose, list[str]] | None:
        """CAMERA (module docstring) of the shot by `camera` (its own, or a copy ahead) stepped
        dt_s to the moment: the pose and its flags. None when it has no pose and none was shown
        before (a degenerate first shot)."""
        camera.advance(moment, dt_s, self.style.response_time_s)
        flags: list[str] = []
        pose = camera.pose(moment)
        if pose is not None and isinstance(camera, ToricCamera):
            pose, pulled = self._pulled_in(moment, pose, dt_s, camera)
            if pulled:
                flags.append("pulled_in_front_of_wall")
        if pose is None:
            if self._last_pose is None:
                return None
            pose = self._last_pose
            flags.append("pose_held")
        return pose, flags

    def _visibility(self, moment: Moment, pose: CameraPose) -> float:
        """VISIBILITY: the mean share of the shot's framed subjects seen from the pose (1 for none)."""
        subjects = self.shot.framed(moment.time_s)
        return float(self.visibility.visible_share(pose.position_world, moment, subjects).mean()) if subjects else 1.0

    def _ahead_holds(self, ahead: CameraStep, moment: Moment, dt_s: float, camera) -> bool:
        """Whether the step worked out ahead is this frame's: the same moment, time step, style
        and pose before, from the camera exactly as it is (every camera changes by assigning its
        attributes, so identity tells any change: a tick's new goal or pair window, a cut)."""
        return (ahead.moment is moment and ahead.dt_s == dt_s and ahead.shot is self.shot and ahead.camera is camera
                and ahead.style is self.style
                and ahead.last_pose is self._last_pose and vars(camera).keys() == ahead.camera_before.keys()
                and all(vars(camera)[k] is v for k, v in ahead.camera_before.items()))

    def _work_ahead(self, moment: Moment) -> None:
        """Works out, ahead of the frame, what the frame whose moment is `moment` computes the
        same way when no tick changes the shot (module docstring, "Ahead"): the camera's step
        from a copy of it, and the candidates' poses, those of the drawn plan too once it is
        computed (a tick that applies it shows them)."""
        if self.shot is None or self._last_time_s is None:
            return
        camera, dt_s = self.shot.camera, max(0.0, moment.time_s - self._last_time_s)
        ahead = copy.copy(camera)
        stepped = self._camera_step(moment, dt_s, ahead)
        if stepped is not None:
            pose, flags = stepped
            self._ahead = CameraStep(moment, dt_s, self.shot, camera, dict(vars(camera)), dict(vars(ahead)),
                                     self._last_pose, self.style, pose, flags, self._visibility(moment, pose))
        lists = [self._candidates]
        drawn = self._drawn
        if drawn is not None and drawn.run is None and drawn.result is not None:
            lists.append(drawn.result.candidates)
        self._ahead_candidates = [CandidatePoses(moment, c, [None if cam is None else cam.pose(moment) for _, cam, _ in c])
                                  for c in lists]

    def _candidate_views(self, moment: Moment, pose: CameraPose) -> list[Candidate]:
        """The frame's candidates: each camera's pose at the moment (worked out ahead, or now; an
        OVERVIEW candidate's is the program's)."""
        camera = self.shot.camera
        ahead = next((a for a in self._ahead_candidates if a.moment is moment and a.candidates is self._candidates),
                     None)
        poses = ahead.poses if ahead is not None else [None] * len(self._candidates)
        views = []
        for (choice, cam, score), known in zip(self._candidates, poses):
            if cam is None:
                shown = pose
            elif known is not None and cam is not camera:
                shown = known
            else:
                shown = cam.pose(moment)
            if shown is not None:
                views.append(Candidate(shown, choice, score))
        return views

    def _pulled_in(self, moment: Moment, pose: CameraPose, dt_s: float, camera: ToricCamera) -> tuple[CameraPose, bool]:
        """The Toric shot's pose pulled in front of a wall (shots.py `pulled_in`) when walls hide
        most of its first subject, kept only if it frames the shot's subjects better (their mean
        seen share, framed_seen): close to A, a pair far apart may no longer fit. On 90 s of the
        4on4 on dm2 this kept program visibility 0.58 and kill coverage 0.60 (0.38 and 0.53 with no
        pull; 0.52 and 0.63 judging by the worst-seen subject; 0.56 and 0.57 pulling always)."""
        s, subjects = self.settings, self.shot.framed(moment.time_s)
        hidden = self.visibility.visible_share(pose.position_world, moment, (camera.anchor_index,))[0, 0] < s.pull_below
        reach_before = camera.reach_m
        pulled, moved = camera.pulled_in(moment, pose, bool(hidden), self.ray_scene, dt_s, s.pull_margin_m,
                                         s.pull_regrow_m_s)
        if not moved or not subjects:
            return pulled, moved
        both = [pose, pulled]
        seen = framed_seen(self.visibility, moment, subjects, np.array([p.position_world for p in both]),
                           quat_to_matrix(np.array([p.rotation_xyzw for p in both])), self.lens).mean(axis=1)
        if seen[1] > seen[0] or (reach_before is not None and not hidden):  # going back out: at its pace
            return pulled, True
        camera.reach_m = None
        return pose, False

    def _tick(self, moment: Moment, flags: list[str]) -> bool:
        """A planning tick (module docstring): the drawn plan applied and the next drawn, or a
        plan made and applied at once; whether it cut."""
        drawn, self._drawn = self._drawn, None
        if self._take_pending or self.shot is None or not (self._defer_plans and self.director is self.planned):
            if drawn is not None:
                drawn.finish()  # a take overrides it; finished, so that it never depends on the moment of the take
            result = self._plan(moment, self.buffer, self.shot, None, self._last_pose)
            self._take_pending = False
            return self._apply(result, moment, flags)
        if drawn is not None and not drawn.due(self.settings.plan_work_per_tick):
            self._drawn = drawn  # a long plan: applied at a later tick, none drawn meanwhile
            flags.append("plan_late")
            return False
        cut = drawn is not None and self._apply(drawn.result, moment, flags, drawn.current)
        # planned for the moment it goes on air, the next tick's (buffered: the delay's future)
        on_air = self.buffer.at(moment.time_s + self.settings.plan_interval_s)
        current, camera, buffer, last_pose = self.shot, copy.copy(self.shot.camera), self.buffer.view(), self._last_pose
        self._drawn = DrawnPlan(current, SlicedRun(lambda: self._plan(on_air, buffer, current, camera, last_pose),
                                                   self.clock))
        return cut

    def _apply(self, result: PlanResult, moment: Moment, flags: list[str], drawn_on: Shot | None = None) -> bool:
        """A tick's decisions onto the program (drawn_on: the shot the plan was drawn on, whose
        camera gets the new goal); whether it cut."""
        flags.extend(result.flags)
        self.held, self._candidates, self._beats = result.held, result.candidates, result.beats
        if result.shot is not None and drawn_on is not None and self._jump_cut(result.shot, moment):
            flags.append("cut_refused_jump")  # the next plan, drawn now, judges it from the picture now on air
            return False
        if result.shot is not None:
            result.shot.start_s = moment.time_s  # on air from now: the shot's length counts from here
            self.shot = result.shot
            return True
        if drawn_on is None or self.shot is drawn_on:
            camera = self.shot.camera
            # assigned only when changed: the camera's step worked out ahead holds while its attributes do
            if result.goal is not None and result.goal != camera.goal:
                camera.goal = result.goal
            if isinstance(camera, ToricCamera) and camera.pair is not None:  # the plan may have held it for more events
                pair = dataclasses.replace(camera.pair, times_s=tuple(self.shot.cover_times_s),
                                           place=result.pair_place or camera.pair.place)
                if pair != camera.pair:
                    camera.pair = pair
        return False

    def _jump_cut(self, shot: Shot, moment: Moment) -> bool:
        """Whether cutting to the shot now breaks the 30-degree rule against the pose on air: a
        drawn plan judged it against the pose of the tick that drew it (or earlier, applied late),
        and the camera has moved since (the real wipeout and 4on4 each had one such jump cut)."""
        shared = sorted(set(self.shot.framed(moment.time_s)) & set(shot.framed(moment.time_s)))
        pose = shot.camera.pose(moment)
        if not shared or pose is None or self._last_pose is None:
            return False
        return not self.builder.grammar.allows_cut(self._last_pose.position_world, moment.aims_world[shared],
                                                   pose.position_world)[0]

    def _plan(self, moment: Moment, buffer: MomentBuffer, current: Shot | None, camera: ToricCamera | None,
              last_pose: CameraPose | None) -> PlanResult:
        """The cut decision of a tick (take, else the director), the re-placement of an occluded
        camera (ours) and the candidates, from the moment, a buffer, the current shot, a copy of
        its camera (None: the shot's own) and the last pose."""
        flags: list[str] = []
        held = self.held
        if held is not None:
            new, held = self._held_shot(moment, buffer, current, flags)
        else:
            new = self.director.decide(moment, buffer, None if current is None or current.held else current,
                                       last_pose, flags)
            if new is None and current is not None and current.held:  # released: the director starts afresh
                new = self.director.decide(moment, buffer, None, last_pose, flags)
        goal = pair_place = None
        if new is None and current is not None and (self.director is self.planned or held is not None):
            goal, pair_place = self._replaced_places(moment, buffer, current, camera or current.camera, flags)
        beats = list(self.planned.plan) if self.director is self.planned else []
        return PlanResult(new, goal, pair_place, held, self._candidate_shots(moment, buffer, new or current), beats,
                          flags)

    def _replaced_places(self, moment: Moment, buffer: MomentBuffer, shot: Shot, camera,
                         flags: list[str]) -> tuple[Place | None, Place | None]:
        """Ours: a Toric camera whose goal place sees its subjects under min_visible glides to the
        best place on its side: the new goal, None to keep it. With planned events still ahead in
        the buffer the place is judged at their moments (plan.py's event cover: being hidden now
        matters less than at the kill); otherwise now and REPLACE_LOOKAHEAD_S ahead. A camera
        whose pair window holds the pair's place (shots.py `ToricCamera.split`): its own place,
        the killer's, is judged for the killer alone, from all the grid, at those of now and
        REPLACE_LOOKAHEAD_S ahead where it frames the killer alone; the pair's place at the
        upcoming events while the picture is not yet on it, and replaced at once (it is not on
        screen): the second place returned, None to keep it."""
        if not isinstance(camera, ToricCamera):
            return None, None
        now = moment.time_s
        upcoming = [t for t in shot.cover_times_s if now <= t <= buffer.horizon_s]
        ahead = now + REPLACE_LOOKAHEAD_S
        soon = [moment] + ([buffer.at(ahead)] if ahead <= buffer.horizon_s else [])
        if not camera.split:
            side = None if camera.b_index is None else camera.side
            cover, weights = PlannedDirector.event_cover(buffer, now, upcoming) if upcoming else (soon, None)
            return self._better_place(camera, camera.goal, place_grid(side), cover, weights, shot.subjects, flags), None
        pair, pair_place = camera.pair, None
        if upcoming and pair.weight(now) <= 0.0:
            cover, weights = PlannedDirector.event_cover(buffer, now, upcoming)
            side = math.copysign(1.0, pair.place.phi_rad)
            pair_place = self._better_place(camera, pair.place, place_grid(side), cover, weights, shot.subjects, flags)
        alone = [m for m in soon if pair.weight(m.time_s) <= 0.0]
        goal = self._better_place(camera, camera.goal, place_grid(None), alone, None, (pair.keep_index,), flags) \
            if alone else None
        return goal, pair_place

    def _better_place(self, camera: ToricCamera, place: Place, grid: list[Place], cover: list[Moment],
                      weights: list[float] | None, subjects: tuple[int, ...], flags: list[str]) -> Place | None:
        """The best place of grid for the subjects over cover when `place` sees them under
        min_visible and it sees them better (flagged replaced_for_visibility); else None."""
        _, seen = best_place(camera, [place], cover, subjects, self.visibility, weights=weights)
        if seen >= self.settings.min_visible:
            return None
        better, score = best_place(camera, grid, cover, subjects, self.visibility, weights=weights)
        if score <= seen:
            return None
        flags.append("replaced_for_visibility")
        return better

    def _candidate_shots(self, moment: Moment, buffer: MomentBuffer,
                         program: Shot | None) -> list[tuple[ShotChoice, ToricCamera | None, float]]:
        """The best other situations, each with a Toric camera at the style's place (an OVERVIEW
        candidate reuses the program pose until it is taken)."""
        out = []
        program_set = set(program.subjects) if program is not None else set()
        for option in self.planned.options(moment, buffer):
            if len(out) >= self.settings.candidates:
                break
            if set(option.subjects) == program_set or option.kind == ShotKind.OVERVIEW:
                continue
            camera = self.builder.cameras(option.kind, option.subjects, moment, default=True)[0][0]
            out.append((ShotChoice(tuple(self.players[i] for i in option.subjects), option.kind, option.reason),
                        camera, option.score))
        return out
