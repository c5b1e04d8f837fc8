"""The MATCH rig of a session: the program of a whole match, chosen among the players by
events and interest, shown with the broadcast delay (issue 12).

Per frame `MatchRig.run` (stage timings in `stage_ms`: `buffer`, `plan`, `camera`, `visibility`,
`edit`):
1. buffer   the frame's players and events join the buffered moments (moments.py); the program's
            moment is the one nearest `time_s - delay_s`. Until one exists the
            answer is `buffering` with no pose. `state.frame`, `time_s`, `dt_s` and
            `aim_points_world` become the program moment's (the input frame's number stays the
            Session's business: Session.is_stale compares with the last answered state, whose
            frame is now the program's, so a re-sent input frame is also refused here, by the
            buffer, and flagged `match_stale_frame`).
The rig works the program `window_s` (2.5 s at a 10 s delay) ahead of the program moment: stages
2-4 run for each buffered moment up to then, at most HEAD_STEPS a frame, each frame they work out
joining the edit window (edit_window.py: 5.), which answers the program moment's. The window
fills while the delay does (its first moment is worked out at the frame `delay_s - window_s`
after the first), so every moment is worked out with the same span of buffered future after it,
the delay less the window. Everything below
("the program moment", the director's ticks, the buffered future it plans on) is that worked-out
moment's; a human's take drops the window's frames and goes on air at the program moment itself.
2. plan     at `plan_rate_hz` (and at once after a take, or where the player whose jump moves the
            live camera jumps through the level: `_mover_jumped`), the director of the style decides
            whether to cut: any registered director (director_registry.py): ours (planned.py),
            the HLTV baseline (hltv.py), ezQuake's autotrack (autotrack.py: it ranks by the
            players' stats, `player_stats`, each player's latest sent with a frame up to the
            program moment) or a plugin's; a human's take (takes.py) overrides them until
            released. The rig asks the director's capabilities (director_contract.py), never
            which it is: one that `replaces_occluded_places` (ours) has an occluded camera
            re-placed within its shot (replacement.py); one that `plans_ahead` (ours) is off the
            frame path (drawn_plan.py): each tick applies the plan drawn at the tick before and
            draws the next. Every director's program offers the best other situations
            (situations.py) as candidates.
3. camera   every frame, the shot's camera at the program moment; a Toric camera from whose place
            walls hide most of its first subject comes in front of the wall, and any pose, the
            candidates' too, that would lie outside the level or inside solid comes inside
            (program_camera.py, in_level.py), worked out ahead of the frame when it can be
            (camera_ahead.py); a first-person camera (first_person.py) is its player's eye
            wherever the game puts it, never moved; a camera that moved through a wall since the
            last frame cuts there (`cut_through_wall`): cuts to places, never sweeps through walls;
            one that would jump farther than its pace makes up in `move_cut_s` cuts too
            (`cut_long_move`, program_camera.py). A new shot through the eyes the shot on air
            looks through is no cut, but for a replay: the same picture goes on
            (`same_eyes_no_cut`).
4. visibility  the share of the framed subjects' sample points seen from the camera.
5. edit     the frame joins the edit window; a cut under the style's min_shot_s after the one
            before gives the short shot between to the shot before (its camera carried on) or
            the one after, or starts it earlier in the shot before's last frames (edit_window.py).
            The program moment's frame is answered, its
            candidates' poses worked out at its moment.
During a REPLAY shot (replays.py) CAMERA and VISIBILITY are of the replayed moment (the buffer keeps
the past it shows), and so are `program_transforms` and the frame's `replay_of`, while
`state.frame` and `time_s` stay the program moment's; a cut into or out of a replay is a cut in
time, never a jump cut; a replay is not re-placed (replacement.py). Beside the program, the latest
kill shown live and not yet replayed is offered as a REPLAY candidate from `replay_after_s` after it,
its monitor at the kill.
Every cut's `shot.reason` says why, its sub-scores go to `scores`, and degraded choices to `flags`.

A style that names another director makes it anew from its registry entry at the next tick; the
current shot goes on until it cuts.

`MatchRig` implements `CameraRig` (pipeline/camera_rig.py) with, of what only some rigs do, its
player inputs (game events and a human's takes: it is its own `PlayerInputs`) and the program's
delayed target transforms; it has no occlusion maps; its deferred work is the camera worked out
ahead and the drawn plan. Its part of a frame's state is `MatchFrame` (frame.py), made anew every
frame.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections import deque
from collections.abc import Callable, Mapping

import numpy as np

from camdirector.geometry.camera import CameraPose, in_frame
from camdirector.geometry.inside import LevelInterior
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform
from camdirector.infra.slices import SlicedRun
from camdirector.infra.stage_clock import StageClock
from camdirector.pipeline.camera_rig import RigBase
from camdirector.pipeline.inputs import FrameInput, GameEvent, PlayerStats, SceneSpec
from camdirector.pipeline.match.camera_ahead import (
    AnswerLens,
    CameraStep,
    CandidatePoses,
    answer_lens_ahead,
    candidate_poses,
    candidate_views,
    step_ahead,
)
from camdirector.pipeline.match.director_contract import DirectorContext, MatchDirector
from camdirector.pipeline.match.director_registry import director_entry
from camdirector.pipeline.match.drawn_plan import PLAN_SLICE_S, DrawnPlan, PlanResult
from camdirector.pipeline.match.edit_window import EditWindow, Judges, WorkedFrame, shadow_of
from camdirector.pipeline.match.first_person import FirstPersonCamera
from camdirector.pipeline.match.frame import MatchFrame, PlannedCut, ReplayedMoment, ShotChoice, ShotKind
from camdirector.pipeline.match.grammar import Grammar
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.moments import TIME_EPSILON_S, Moment, MomentBuffer
from camdirector.pipeline.match.program_camera import CUT_LONG_MOVE, CUT_TO_SEEN_PLACE, HOLD_LEFT_FOR_CUT, ProgramCamera
from camdirector.pipeline.match.program_shot import CandidateShot, Shot, ShotCamera, camera_jumps_at
from camdirector.pipeline.match.replacement import replaced_places
from camdirector.pipeline.match.replays import Replays, is_replay, replayed_moment
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shot_builder import ShotBuilder
from camdirector.pipeline.match.shots import ToricCamera
from camdirector.pipeline.match.situations import Situations
from camdirector.pipeline.match.takes import Takes
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.pipeline.stages import MatchStage
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style

SHOWN_SHARE = 0.5  # a player with this share of its points in the frame and seen is shown (eval-match's SHOWN_FRACTION)
PLANNED_AT_JUMP = "planned_at_jump"  # a tick at once where the live camera's player jumped (_mover_jumped)
HEAD_STEPS = 2  # frames worked out per frame answered at most: one, and one more while the window refills (a take)


class MatchRig(RigBase):
    """The match director of one session; implements `CameraRig` (module docstring). Players are
    the scene's targets."""

    def __init__(
        self,
        scene: SceneSpec,
        ray_scene: RayScene,
        rng: np.random.Generator,
        clock: Callable[[], float] = time.perf_counter,
        settings: MatchSettings = MatchSettings(),
    ):
        self.players = [t.id for t in scene.targets]
        self.player_ids = frozenset(self.players)  # PlayerInputs: whom events and takes may name
        self.index = {p: i for i, p in enumerate(self.players)}
        self.teams = np.array([t.team for t in scene.targets])
        self.roster = tuple((t.id, t.team) for t in scene.targets)  # MatchFrame.players, shared by every frame
        self.lens, self.style, self.delay_s = scene.lens, scene.style, scene.delay_s
        self.ray_scene, self.rng, self.clock, self.settings = ray_scene, rng, clock, settings
        self.buffer = MomentBuffer(self.players, settings)
        self.visibility = SubjectVisibility(ray_scene, [t.mesh for t in scene.targets], settings.samples_per_player, rng)
        self._body_heights_m = np.array([np.ptp(o[:, 1]) for o in self.visibility.outlines_local])  # (n,) each body's, m
        self.level_nodes = scene.level.artifact.nodes_world if scene.level is not None else np.zeros((0, 3))
        self.builder = ShotBuilder(
            self.players, self.style, self.lens, settings, self.visibility, Grammar(settings.jump_cut_deg), self.level_nodes
        )
        self.situations = Situations(self.players, self.teams, settings, ray_scene)
        self.replays = Replays(self.players, self.builder)  # the REPLAY candidate's and takes'
        self.takes = Takes(self.players, settings, self.builder, self.situations, self.replays)
        # the kills shown live, each with the live camera's centre (3,) m and the moment that showed it,
        # and the kills replayed (s)
        self._kills_shown: deque[tuple[GameEvent, np.ndarray, Moment]] = deque(maxlen=8)
        self._replayed: deque[float] = deque(maxlen=8)
        interior = LevelInterior.of(scene.level.mesh_world) if scene.level is not None else None
        self.in_level = InLevel(interior, self.level_nodes, settings.pull_margin_m)
        self.program_camera = ProgramCamera(
            settings, self.visibility, ray_scene, self.lens, self.in_level, self.builder.grammar, self._future
        )
        self._stats: dict[str, PlayerStats] = {}  # each player's latest stats sent up to the program moment
        self._stats_ahead: deque[tuple[float, list[PlayerStats]]] = deque()  # (frame time s, stats) not yet on air
        # the directors' view, read only by its type (a mappingproxy would not pickle into the checkpoint)
        self.player_stats: Mapping[str, PlayerStats] = self._stats
        self.director = self._director(self.style.match_director)
        self.shot: Shot | None = None
        self._drawn: DrawnPlan | None = None
        self._planned_cuts: list[PlannedCut] = []  # the director's planned cuts as of the last applied tick
        # a session whose objects move every frame plans in the frame (its ray scene is the frame's)
        self._defer_plans = not any(o.dynamic for o in scene.objects)
        self._next_plan_s = -math.inf
        self._last_time_s: float | None = None  # the moment of the newest frame worked out, s
        self._head: Moment | None = None  # that moment: the edit window's end (edit_window.py)
        self._answered_s: float | None = None  # the program moment last answered, s
        self.window = EditWindow(self.style.min_shot_s, self.players, self._defer_plans, self.window_s, self._lengthen_s)
        self._last_pose: CameraPose | None = None
        self._last_cut_s = -math.inf  # program time of the picture's last cut, s
        self._candidates: list[CandidateShot] = []
        self._ahead_for: Moment | None = None  # the next frame's likely moment, not yet worked out ahead
        self._ahead: CameraStep | None = None  # the camera's step to it, worked out ahead
        self._ahead_candidates: list[CandidatePoses] = []  # the candidates' poses at it
        self._answer_lens: AnswerLens | None = None  # the lens of the window's next frame to answer, worked out ahead
        self.program_transforms: list[RigidTransform] | None = None  # the players at the program's moment (None: buffering)

    def __setstate__(self, state: dict[str, object]) -> None:
        """A rig from a checkpoint; one written before the edit window (an earlier version, a
        rolling upgrade) works on from its program moment, the window refilling."""
        self.__dict__.update({"_answer_lens": None, **state})
        if "window" in state:
            self.window.defer = self._defer_plans  # a window written before repairs were drawn defers by default
        else:
            self.window = EditWindow(self.style.min_shot_s, self.players, self._defer_plans, self.window_s, self._lengthen_s)
            self._head, self._answered_s = None, self._last_time_s
            self._body_heights_m = np.array([np.ptp(o[:, 1]) for o in self.visibility.outlines_local])

    def _director(self, name: str) -> MatchDirector:
        """The director of that registry name, made for this session (ValueError for a name the
        registry does not hold: the codec refuses it before)."""
        try:
            entry = director_entry(name)
        except KeyError as exc:
            raise ValueError(exc.args[0]) from None
        return entry.factory(
            DirectorContext(
                self.players,
                self.teams,
                self.lens,
                self.settings,
                self.delay_s,
                self.ray_scene,
                self.rng,
                self.level_nodes,
                self.player_stats,
                self.builder,
                self.situations,
            )
        )

    def _stats_to(self, time_s: float) -> None:
        """The stats sent with the frames up to the program moment (time_s) join the directors' view."""
        while self._stats_ahead and self._stats_ahead[0][0] <= time_s:
            self._stats.update((stats.id, stats) for stats in self._stats_ahead.popleft()[1])

    def set_style(self, style: Style) -> None:
        """From the next frame on; the current shot goes on (a new director decides at its next tick)."""
        self._finish_drawn()  # the drawn plan reads the style
        self.window.work(self._judges())  # and the edit window's copies of cameras (their response time)
        if style.match_director != self.style.match_director:
            self.director = self._director(style.match_director)
            self._planned_cuts = []  # the last director's
        self.style = self.builder.style = style
        self.window.min_shot_s = style.min_shot_s

    @property
    def window_s(self) -> float:
        """How far ahead of the program moment the rig works (edit_window.py), s: the settings',
        at most a quarter of the delay (the director plans on the rest)."""
        return min(self.settings.edit_window_s, self.delay_s / 4.0)

    @property
    def _lengthen_s(self) -> float:
        """A shot under this, min_shot_s long, is given to a neighbour that shows it as well (edit_window.py), s: the
        settings', within the window."""
        return min(self.settings.edit_lengthen_s, self.window_s)

    @property
    def player_inputs(self) -> MatchRig:
        """CameraRig: a frame's game events and a human's takes (`take`) name this rig's players."""
        return self

    @property
    def has_deferred_work(self) -> bool:
        """CameraRig: whether the next frame's camera is to be worked out ahead, an edit window's
        repair or hold or a drawn plan waits to be computed."""
        return self._ahead_for is not None or self.window.waiting or self.plan_waiting or self.window.hold_due(self._following())

    @property
    def plan_waiting(self) -> bool:
        """Whether a drawn plan waits to be computed (a part of has_deferred_work)."""
        return self._drawn is not None and self._drawn.run is not None

    def do_deferred_work(self, whole: bool = True) -> bool:
        """CameraRig: the deferred work, soonest due first (`_deferred_piece`), one piece or all of
        it; whether there was any."""
        if not whole:
            return self._deferred_piece(PLAN_SLICE_S)
        worked = False
        while self._deferred_piece(None):
            worked = True
        return worked

    def _deferred_piece(self, budget_s: float | None) -> bool:
        """One piece of the deferred work, whole where budget_s is None, else for about budget_s,
        s, soonest due first: the next frame's camera worked out ahead, the verdict on a short
        shot's hold due at the next frame, the drawn plan (due at the next tick, within
        1 / plan_rate_hz), and once it is computed the camera ahead again where the next frame's
        tick gives it the plan's new goal (camera_ahead.py), then the edit window's shadow steps
        and repair (due when the window's next cut or the short shot's first frame comes, usually
        later); whether there was any."""
        if self._ahead_for is not None:
            self._work_ahead(self._ahead_for)
            self._ahead_for = None
            return True
        following = self._following()
        if following is not None and self.window.hold_due(following):  # a short shot's hold, judged at the next frame
            self.window.work_hold(following, self._judges())
            return True
        drawn = self._drawn
        if drawn is not None and drawn.run is not None:
            if budget_s is None or drawn.run.step(budget_s):
                drawn.finish()
                if following is not None and self._tick_assigns(following):
                    self._ahead_for = following
            return True
        if self.window.waiting:
            self.window.work(self._judges(), budget_s, self.clock)
            return True
        return False

    def _following(self) -> Moment | None:
        """The moment the next frame most likely works out: the buffered one after the window's end."""
        return None if self._head is None else self.buffer.following(self._head)

    def _finish_drawn(self) -> None:
        if self._drawn is not None:
            self._drawn.finish()

    def close(self) -> None:
        """Drops the buffered moments."""
        self.buffer = MomentBuffer(self.players, self.settings)

    def planned_cut(self, now_s: float) -> PlannedCut | None:
        """The next cut the director planned at its last tick that is still ahead of now_s; None
        while a take is held, or with nothing planned (a director without planned cuts; no delay:
        no known future)."""
        return _next_cut(self.takes.held, self._planned_cuts, now_s)

    def take(self, subject_ids: list[str], kind: ShotKind | None, release: bool) -> ShotChoice | None:
        """PlayerInputs: a human's take (takes.py), from the next frame until released."""
        self._finish_drawn()  # the drawn plan reads the take
        return self.takes.take(subject_ids, kind, release)

    # -- the frame --------------------------------------------------------------------------
    def run(
        self, state: FrameState, update: FrameInput, target_transforms: list[RigidTransform], last: FrameState | None
    ) -> None:
        """BUFFER, then PLAN, CAMERA and VISIBILITY of the frames the edit window works out ahead,
        then the program moment's frame answered (module docstring) into state and its part
        `state.match`, timed into state.stage_ms."""
        match = state.match = MatchFrame(self.roster)
        stages = StageClock(clock=self.clock, timings_ms=state.stage_ms)
        if not self.buffer.push(update.frame, update.time_s, target_transforms, state.aim_points_world, update.events):
            state.flags.append("match_stale_frame")
        elif update.player_stats:
            self._stats_ahead.append((update.time_s, update.player_stats))
        program_s = update.time_s - self.delay_s
        moment = self.buffer.nearest(program_s)
        stages.done(MatchStage.BUFFER)
        if moment is None:
            self._work_window(program_s, None, stages)
            self.program_transforms = None
            match.buffering, state.pose, state.visibility = True, None, 0.0
            state.flags.append("buffering")
            return
        if self.takes.pending and self.window.frames and self.window.answered is not None:
            self._rewind()  # a take applies at once, from the program moment (before its first, from the window's end)
        self._work_window(program_s, moment, stages)
        previous = self.window.answered
        frame, cut = self.window.answer(moment, self._judges())
        answered = frame.moment.time_s
        state.frame, state.time_s = frame.moment.frame, answered
        state.dt_s = 0.0 if self._answered_s is None else max(0.0, answered - self._answered_s)
        if frame is not previous:  # the lens checked at the moment answered (program_camera.py widened_for_answer)
            last_fov_deg = None if cut or previous is None else previous.pose.vertical_fov_deg
            lens = self._answer_lens
            if lens is not None and lens.holds(frame.shown, frame.pose, last_fov_deg, state.dt_s, frame.shot, frame.flags):
                frame.pose, frame.flags[:] = lens.pose, lens.flags
            else:
                frame.pose = self.program_camera.widened_for_answer(
                    frame.shown, frame.pose, last_fov_deg, state.dt_s, frame.shot, frame.flags
                )
        self._answer_lens = None
        self._answered_s = answered
        state.aim_points_world = list(frame.moment.aims_world)
        state.pose, state.cut, state.visibility = frame.pose, cut, frame.visibility
        state.flags.extend(frame.flags)
        self.program_transforms = frame.shown.transforms
        if frame.shown is not frame.moment:
            match.replay_of = ReplayedMoment(frame.shown.frame, frame.shown.time_s)
        match.candidates = candidate_views(
            frame.moment,
            frame.pose,
            frame.candidates,
            self._ahead_candidates,
            frame.shot.camera,
            self.in_level,
            self._candidate_moment,
            self._offerable,
        )
        self._ahead_candidates = []
        match.shot, match.events = frame.choice, frame.moment.events
        # the next cut worked out, else the director's next beyond the window
        match.planned_cut = self.window.next_cut() or self.planned_cut(self._head.time_s if self._head else answered)
        state.scores = dict(frame.shot.scores, visibility=frame.visibility, shot_length_s=answered - self.window.last_cut_s)
        stages.done(MatchStage.EDIT)

    def _work_window(self, program_s: float, moment: Moment | None, stages: StageClock) -> None:
        """The window worked out to `window_s` past the program time program_s, s: the program
        moment first (None: none yet, the delay still filling), then HEAD_STEPS frames a call at
        most. The window fills while the delay does, from the first buffered moment: each frame
        then works out one, seeing the buffered future a frame in steady state sees (the delay
        less the window), and the program's first frames wait for none (before, the window refilled from
        the program's first moment at HEAD_STEPS a frame, its first 2.5 s at 5-9 ms a frame)."""
        ahead = self.buffer.nearest(program_s + self.window_s)
        if ahead is None:  # the delay's first moments still to come
            return
        steps = 0
        while self._head is None or self._head.time_s < ahead.time_s - TIME_EPSILON_S:
            behind = moment is not None and (self._head is None or self._head.time_s < moment.time_s - TIME_EPSILON_S)
            if steps >= HEAD_STEPS and not behind:  # the program moment is worked out: the rest at later frames
                break
            if self._head is not None:
                head = self.buffer.following(self._head)
            else:
                head = self.buffer.program_moment(self.buffer.oldest_s if moment is None else moment.time_s)
            if head is None:
                break
            self.buffer.program_moment(head.time_s)  # the buffer's program moment is the head's (its past kept for replays)
            self._work(head, stages)
            steps += 1

    def _work(self, moment: Moment, stages: StageClock) -> None:
        """PLAN, CAMERA and VISIBILITY of the frame at the moment, worked out into the edit window
        (edit_window.py), which may give a short shot before its cut to a neighbour."""
        self._stats_to(moment.time_s)
        flags: list[str] = []
        moment_dt_s = 0.0 if self._last_time_s is None else max(0.0, moment.time_s - self._last_time_s)
        self._last_time_s, self._head = moment.time_s, moment
        before = shadow_of(self.shot) if self.shot is not None else None
        cut = False
        jumped = self._mover_jumped(moment, moment_dt_s)
        if self.takes.pending or self.shot is None or moment.time_s >= self._next_plan_s or jumped:
            self._next_plan_s = moment.time_s + self.settings.plan_interval_s
            cut = self._tick(moment, flags, at_once=jumped)
            if jumped:
                flags.append(PLANNED_AT_JUMP)
        stages.done(MatchStage.PLAN)
        assert self.shot is not None  # the first tick always makes one
        dt_s = 0.0 if cut else moment_dt_s
        cut_short = self._cut_short(moment.time_s)
        shown = self._shown(moment)  # a REPLAY's camera and visibility are of the replayed moment
        ahead, self._ahead = self._ahead, None
        worked_out = ahead is not None and ahead.holds(shown, dt_s, self.shot, self.style, self._last_pose, cut_short)
        if ahead is not None and worked_out:
            vars(self.shot.camera).update(ahead.camera_after)
            pose, step_flags = ahead.pose, ahead.flags
        else:
            stepped = self._camera_step(shown, dt_s, self.shot.camera, cut_short)
            if stepped is None:  # a degenerate first shot: look from the overview
                overview = self.builder.build(
                    ShotChoice((), ShotKind.OVERVIEW, "overview: degenerate framing"),
                    (),
                    moment,
                    [moment],
                    None,
                    None,
                    moment.time_s,
                )[0]
                assert overview is not None  # an overview has no grammar to refuse it
                self.shot = overview
                stepped = self._camera_step(moment, dt_s, self.shot.camera, cut_short)
                assert stepped is not None  # a static camera always has its pose
            pose, step_flags = stepped
        if not cut and (CUT_TO_SEEN_PLACE in step_flags or CUT_LONG_MOVE in step_flags):  # re-placed (program_camera.py)
            cut = True
        elif not cut and self._swept_through_wall(pose):
            cut = True
            step_flags = [*step_flags, "cut_through_wall"]
        elif not cut and HOLD_LEFT_FOR_CUT in step_flags:  # a paced move's whole (program_camera.py): no wall across it
            cut = True
        if cut:
            self._last_cut_s = moment.time_s
        flags.extend(step_flags)
        self._last_pose = pose
        if shown is moment:
            self._kills_shown.extend((e, pose.position_world, moment) for e in moment.events if self.replays.pair(e) is not None)
        stages.done(MatchStage.CAMERA)
        visibility = (
            ahead.visibility if ahead is not None and worked_out else self.program_camera.visibility(shown, pose, self.shot)
        )
        # the next frame's moment is most likely the next buffered one: its camera is worked out
        # in the worker's idle moments (a session whose ray scene moves every frame cannot)
        self._ahead_for = self.buffer.following(moment) if self._defer_plans else None
        frame = WorkedFrame(
            moment, shown, pose, cut, flags, visibility, self.shot, self._choice(self.shot, shown.time_s), self._candidates
        )
        stages.done(MatchStage.VISIBILITY)
        judges = self._judges()
        self.window.push(frame, before, judges)
        self.window.step_shadow(moment, moment_dt_s, judges)
        stages.done(MatchStage.EDIT)

    def _judges(self) -> Judges:
        """What the edit window asks of the rig (edit_window.py)."""
        return Judges(
            self._shown_by,
            self._shadow_step,
            self.program_camera.visibility,
            self._players_seen,
            self._shown_height,
            self._choice,
            self.in_level.inside,
            self.in_level.crossed,
        )

    def _choice(self, shot: Shot, shown_s: float) -> ShotChoice:
        """What `MatchFrame.shot` names of the shot at the shown moment's time, s: a REPLAY frames its
        killer alone before the replayed kill, a pair window its kept player alone away from its
        events (replays.py, shots.py)."""
        subjects = shot.framed(shown_s)
        if subjects == shot.subjects:
            return shot.choice
        return dataclasses.replace(
            shot.choice,
            subject_ids=tuple(self.players[i] for i in subjects),
            kind=ShotKind.REPLAY if is_replay(shot) else ShotKind.FOLLOW,
            reason=f"{shot.choice.reason}; framing {self.players[subjects[0]]} alone away from the pair's kills",
        )

    def _players_seen(self, pose: CameraPose, moment: Moment, players: tuple[int, ...]) -> np.ndarray:
        """(k,) the share of each player's sample points in the pose's frame and seen from it
        (eval-match's shown fraction, evaluation/match/measure.py)."""
        asked = in_frame(pose, self.lens, self.visibility.points_world(moment, players))[None]
        seen: np.ndarray = self.visibility.seen_points(pose.position_world, moment, players, asked)[0].mean(axis=1)
        return seen

    def _shown_height(self, pose: CameraPose, moment: Moment, shot: Shot) -> float:
        """About the median share of the frame's height the players shown from the pose stand (as
        eval-match measures it: each one with half its points in the frame and seen, but the one
        whose eyes a first-person view is; its body's height over the frame's at its aim point's
        distance); NaN: none shown."""
        eyes = shot.camera.player if isinstance(shot.camera, FirstPersonCamera) else -1
        everyone = tuple(i for i in range(len(self.players)) if i != eyes)
        shown = [i for i, seen in zip(everyone, self._players_seen(pose, moment, everyone)) if seen >= SHOWN_SHARE]
        if not shown:
            return math.nan
        distance_m = np.linalg.norm(moment.aims_world[shown] - pose.position_world, axis=1)
        frame_m = 2.0 * np.maximum(distance_m, 0.1) * math.tan(math.radians(pose.vertical_fov_deg) / 2.0)
        return float(np.median(self._body_heights_m[shown] / frame_m))

    def _shown_by(self, shot: Shot, moment: Moment) -> Moment:
        """The moment the shot's picture shows at the program moment (a REPLAY's replayed one)."""
        return replayed_moment(self.buffer, shot, moment.time_s) if is_replay(shot) else moment

    def _shadow_step(
        self, moment: Moment, dt_s: float, camera: ShotCamera, shot: Shot, last_pose: CameraPose | None
    ) -> tuple[CameraPose, list[str]] | None:
        """The edit window's copy of a camera stepped (edit_window.py; last_pose None: its first
        frame): held before walls rather than cut, never re-placed (flagged `subjects_lost`)."""
        return self.program_camera.step(moment, dt_s, camera, shot, self.style.response_time_s, last_pose, True, re_place=False)

    def _rewind(self) -> None:
        """The rig back at the last frame answered, the window's frames dropped (a take: its shot
        on air from the program moment, not the window's end)."""
        answered = self.window.answered
        assert answered is not None  # before the first frame answered a take applies from the window's end (run)
        self.window.drop()
        self._ahead = self._ahead_for = self._answer_lens = None
        self._ahead_candidates = []
        self._next_plan_s = -math.inf
        self.buffer.rewind(answered.moment)
        self._head, self._last_time_s = answered.moment, answered.moment.time_s
        self._last_pose, self._last_cut_s, self.shot = answered.pose, self.window.last_cut_s, answered.shot
        kept = [k for k in self._kills_shown if k[2].time_s <= answered.moment.time_s]
        self._kills_shown = deque(kept, maxlen=8)

    # -- the camera's step, in the frame or ahead of it -------------------------------------
    def _shown(self, moment: Moment) -> Moment:
        """The moment the program's picture shows at the program moment: the replayed one during
        a REPLAY (replays.py), else the program moment itself."""
        return moment if self.shot is None else self._shown_by(self.shot, moment)

    def _future(self, time_s: float) -> Moment | None:
        """The buffered moment at time_s, s, None past the newest (the program camera's look ahead)."""
        return None if time_s > self.buffer.horizon_s else self.buffer.at(time_s)

    def _candidate_moment(self, choice: ShotChoice, moment: Moment) -> Moment:
        """The moment a candidate's monitor shows beside the program moment: a REPLAY candidate's
        kill, as the program showed it (kept with the kill: a plan applied late may offer it after
        the buffer let it go)."""
        if choice.replay is None:
            return moment
        kill_s = choice.replay.kill_time_s
        return next((m for e, _, m in self._kills_shown if e.time_s == kill_s), None) or self.buffer.at(kill_s)

    def _offerable(self, pose: CameraPose, choice: ShotChoice, shown: Moment) -> bool:
        """Whether a candidate's pose shows at least half of its subjects at the moment its monitor
        shows (issue 41: offered only when its camera shows them then; eval-match's measure,
        `_players_seen`). Its place was checked when its situation was chosen, at a plan's tick;
        the players move on between ticks."""
        subjects = tuple(self.index[p] for p in choice.subject_ids)
        if not subjects:
            return True
        seen = self._players_seen(pose, shown, subjects)
        return 2 * int((seen >= SHOWN_SHARE).sum()) >= len(subjects)

    def _swept_through_wall(self, pose: CameraPose) -> bool:
        """Whether the camera moved from the last pose shown through level geometry (a wall between
        the two centres, in_level.py `crossed`): the program cuts there instead of sweeping
        through it."""
        last = self._last_pose
        if last is None or np.array_equal(last.position_world, pose.position_world):
            return False
        return self.in_level.crossed(last.position_world, pose.position_world)

    def _camera_step(
        self, moment: Moment, dt_s: float, camera: ShotCamera, cut_short: bool
    ) -> tuple[CameraPose, list[str]] | None:
        """CAMERA of the shot by `camera` (its own, or a copy ahead), program_camera.py."""
        assert self.shot is not None
        return self.program_camera.step(moment, dt_s, camera, self.shot, self.style.response_time_s, self._last_pose, cut_short)

    def _cut_short(self, now_s: float, applied: PlanResult | None = None) -> bool:
        """Whether a cut within the shot at now_s, s (through a wall, to a seen place) would leave
        a shot on air shorter than the style's `min_shot_s`: under it after the picture's last
        cut, or before the next planned cut or a replay's end. The camera is then held before a
        wall however far while the hold shows one of the framed subjects (program_camera.py), rather
        than cut (issue 41: on the real 4on4's first 3 minutes, 94 cuts within shots, half of
        them under 0.6 s after the cut before, made 111 of its 148 shots shorter than 2 s)."""
        min_shot_s = self.style.min_shot_s
        if now_s - self._last_cut_s < min_shot_s:
            return True
        planned = self.planned_cut(now_s) if applied is None else _next_cut(applied.held, applied.planned_cuts, now_s)
        if planned is not None and planned.time_s - now_s < min_shot_s:
            return True
        shot = self.shot
        return shot is not None and is_replay(shot) and shot.hold_until_s - now_s < min_shot_s

    def _work_ahead(self, moment: Moment) -> None:
        """Works out, ahead of the frame, what the frame whose moment is `moment` computes the
        same way when no tick changes the shot (camera_ahead.py): the camera's step from a copy
        of it, and the candidates' poses, those of the drawn plan too once it is computed (a
        tick that applies it shows them)."""
        if self.shot is None or self._last_time_s is None:
            return
        dt_s = max(0.0, moment.time_s - self._last_time_s)
        applied = self._applied_at(moment)
        assigned = self._drawn_assigns(applied)
        self._ahead = step_ahead(
            self.program_camera,
            self._shown(moment),
            dt_s,
            self.shot,
            self.style,
            self._last_pose,
            self._cut_short(moment.time_s, applied),
            assigned,
        )
        # the candidates are shown with the program moment they were worked out for: the window's next to answer
        if self.window.frames:
            following = self.window.frames[0]
            self._ahead_candidates = candidate_poses(
                following.moment, [following.candidates], self.in_level, self._candidate_moment, self._offerable
            )
            answered = self.window.answered
            if answered is not None and self._answered_s is not None:  # its lens, answered after the last one
                last_fov_deg = None if following.cut else answered.pose.vertical_fov_deg
                dt_s = max(0.0, following.moment.time_s - self._answered_s)
                self._answer_lens = answer_lens_ahead(
                    self.program_camera, following.shown, following.pose, last_fov_deg, dt_s, following.shot, following.flags
                )

    def _applied_at(self, moment: Moment) -> PlanResult | None:
        """The drawn plan the tick at the moment will apply, where that is known already: the
        moment's frame a tick, the plan computed and due then, keeping the shot (`_tick`); None
        otherwise (no tick, a plan at once, one not computed yet or late, a cut)."""
        drawn = self._drawn
        if (
            drawn is None
            or drawn.run is not None
            or drawn.result is None
            or drawn.result.shot is not None
            or self.takes.pending
            or self.shot is None
            or moment.time_s < self._next_plan_s
            or drawn.work > (drawn.ticks + 1) * self.settings.plan_work_per_tick  # DrawnPlan.due at that tick
        ):
            return None
        return drawn.result

    def _tick_assigns(self, moment: Moment) -> bool:
        """Whether the tick at the moment will give the camera a new goal or pair window (`_applied_at`)."""
        return bool(self._drawn_assigns(self._applied_at(moment)))

    def _drawn_assigns(self, applied: PlanResult | None) -> dict[str, object]:
        """What the drawn plan a tick applies (`_applied_at`) assigns the shot's camera; none for none."""
        return {} if applied is None or self._drawn is None else self._assigned(applied, self._drawn.current)

    def _assigned(self, result: PlanResult, drawn_on: Shot | None) -> dict[str, object]:
        """The attributes of the shot's camera a plan that keeps the shot assigns, by name: a
        Toric camera's new goal and pair window (re-placed for visibility, held for more events),
        only those that change; the objects a step worked out ahead assumed where equal (so that
        it holds: camera_ahead.py)."""
        assert self.shot is not None  # a plan keeps a shot on air
        camera = self.shot.camera
        # only a Toric camera is re-placed (replacement.py), and only the shot the plan was drawn on
        if not isinstance(camera, ToricCamera) or (drawn_on is not None and self.shot is not drawn_on):
            return {}
        assigned: dict[str, object] = {}
        if result.goal is not None and result.goal != camera.goal:
            assigned["goal"] = result.goal
        if camera.pair is not None:  # the plan may have held it for more events
            pair = dataclasses.replace(
                camera.pair, times_s=tuple(self.shot.cover_times_s), place=result.pair_place or camera.pair.place
            )
            if pair != camera.pair:
                assigned["pair"] = pair
        known = {} if self._ahead is None or self._ahead.camera is not camera else self._ahead.assigned
        return {k: known[k] if k in known and known[k] == v else v for k, v in assigned.items()}

    # -- the planning tick ------------------------------------------------------------------
    def _mover_jumped(self, moment: Moment, dt_s: float) -> bool:
        """Whether the player whose jump moves the live shot's camera (program_shot.py
        camera_movers: its eyes, its Toric anchor) jumped through the level at this moment from
        the one worked out dt_s, s, before (a teleport, a respawn: camera_jumps_at), under our
        director: the camera cuts there anyway (`cut_through_wall`), so the director decides
        what it cuts to (`_tick` at once). On the real 4on4, a pair's DUEL that the match's
        start split 50 m apart went on from its torus into three cuts through walls in 2 s."""
        shot = self.shot
        if shot is None or dt_s <= 0.0 or is_replay(shot) or not self.director.replaces_occluded_places:
            return False
        return camera_jumps_at(shot.camera, self.buffer, moment.time_s, self.visibility.ray_scene.occluded)

    def _tick(self, moment: Moment, flags: list[str], at_once: bool = False) -> bool:
        """A planning tick (module docstring): the drawn plan applied and the next drawn, or a
        plan made and applied at once (a take, a first shot, a director that does not plan
        ahead, or at_once: the live camera's player jumped, `_mover_jumped`); whether it cut."""
        drawn, self._drawn = self._drawn, None
        if at_once and not self.takes.pending and drawn is not None:  # the plan drawn for now first: it knew the jump
            if self._apply(drawn.finish(), moment, flags, drawn.current):
                return True
            drawn = None  # applied: a plan made now decides what the jump cuts to
        if at_once or self.takes.pending or self.shot is None or not (self._defer_plans and self.director.plans_ahead):
            if drawn is not None:
                drawn.finish()  # a take overrides it; finished, so that it never depends on the moment of the take
            result = self._plan(moment, self.buffer, self.shot, None, self._last_pose, self._replayable())
            self.takes.pending = False
            return self._apply(result, moment, flags)
        if drawn is not None and not drawn.due(self.settings.plan_work_per_tick):
            self._drawn = drawn  # a long plan: applied at a later tick, none drawn meanwhile
            flags.append("plan_late")
            return False
        cut = drawn is not None and self._apply(drawn.finish(), moment, flags, drawn.current)
        # planned for the moment it goes on air, the next tick's (buffered: the delay's future)
        on_air = self.buffer.at(moment.time_s + self.settings.plan_interval_s)
        current, camera, buffer, last_pose = self.shot, copy.copy(self.shot.camera), self.buffer.view(), self._last_pose
        replayable = self._replayable()
        self._drawn = DrawnPlan(
            current, SlicedRun(lambda: self._plan(on_air, buffer, current, camera, last_pose, replayable), self.clock)
        )
        return cut

    def _apply(self, result: PlanResult, moment: Moment, flags: list[str], drawn_on: Shot | None = None) -> bool:
        """A tick's decisions onto the program (drawn_on: the shot the plan was drawn on, whose
        camera gets the new goal); whether it cut."""
        flags.extend(result.flags)
        self.takes.held, self._candidates, self._planned_cuts = result.held, result.candidates, result.planned_cuts
        seen_through = result.shot is not None and self._same_eyes(result.shot)
        if result.shot is not None and not seen_through and drawn_on is not None and self._jump_cut(result.shot, moment):
            flags.append("cut_refused_jump")  # the next plan, drawn now, judges it from the picture now on air
            return False
        if result.shot is not None:
            if result.shot.choice.replay is not None:  # its length counts from now too
                self._replayed.append(result.shot.choice.replay.kill_time_s)
                result.shot.hold_until_s += moment.time_s - result.shot.start_s
            # on air from now: the shot's length counts from here, through the same eyes too, where
            # the picture goes on uncut (a cut to the very same view is none to a viewer): the
            # director chose it anew, and its clock (min and max shot) restarts, else a shot held
            # past max_shot_s through one player's eyes would be chosen again at every tick
            result.shot.start_s = moment.time_s
            self.shot = result.shot
            if seen_through:
                flags.append("same_eyes_no_cut")
            return not seen_through
        assert self.shot is not None  # a tick without a cut keeps the shot on air
        # assigned only when changed: the camera's step worked out ahead holds while its attributes do
        for name, value in self._assigned(result, drawn_on).items():
            setattr(self.shot.camera, name, value)
        return False

    def _same_eyes(self, shot: Shot) -> bool:
        """Whether the shot is through the eyes of the player through whose eyes the shot on air
        is (first_person.py): the same picture, which the program goes on with uncut; but where
        either is a replay, a cut in time (the real 2on2 jumped 7.8 m uncut into one)."""
        current = self.shot
        return (
            current is not None
            and not (is_replay(current) or is_replay(shot))
            and isinstance(current.camera, FirstPersonCamera)
            and isinstance(shot.camera, FirstPersonCamera)
            and current.camera.player == shot.camera.player
        )

    def _jump_cut(self, shot: Shot, moment: Moment) -> bool:
        """Whether cutting to the shot now breaks the 30-degree rule against the pose on air: a
        drawn plan judged it against the pose of the tick that drew it (or earlier, applied late),
        and the camera has moved since (the real wipeout and 4on4 each had one such jump cut)."""
        assert self.shot is not None  # a drawn plan is drawn on a shot
        if is_replay(self.shot) or is_replay(shot):  # a cut into or out of a replay is a cut in time
            return False
        shared = sorted(set(self.shot.framed(moment.time_s)) & set(shot.framed(moment.time_s)))
        pose = shot.camera.pose(moment)
        if not shared or pose is None or self._last_pose is None:
            return False
        return not self.builder.grammar.allows_cut(
            self._last_pose.position_world, moment.aims_world[shared], pose.position_world
        )[0]

    def _plan(
        self,
        moment: Moment,
        buffer: MomentBuffer,
        current: Shot | None,
        camera: ShotCamera | None,
        last_pose: CameraPose | None,
        replayable: tuple[GameEvent, np.ndarray] | None,
    ) -> PlanResult:
        """The cut decision of a tick (take, else the director), the re-placement of an occluded
        camera (a director that asks for it, or a take) and the candidates, from the moment, a
        buffer, the current shot, a copy of its camera (None: the shot's own), the last pose and
        the kill a REPLAY candidate would show (with the live camera's centre at it)."""
        flags: list[str] = []
        held = self.takes.held
        if held is not None:
            new, held = self.takes.held_shot(moment, buffer, current, self._candidates, flags)
            if held is None:  # a human's replay is over (the director starts afresh) or refused
                new = self.director.decide(moment, buffer, None if current is None or current.held else current, last_pose, flags)
        else:
            new = self.director.decide(moment, buffer, None if current is None or current.held else current, last_pose, flags)
            if new is None and current is not None and current.held:  # released: the director starts afresh
                new = self.director.decide(moment, buffer, None, last_pose, flags)
        goal = pair_place = None
        replaces = self.director.replaces_occluded_places or held is not None
        if new is None and current is not None and replaces and not is_replay(current):
            goal, pair_place = replaced_places(
                moment, buffer, current, camera or current.camera, self.visibility, self.settings, flags
            )
        return PlanResult(
            new,
            goal,
            pair_place,
            held,
            self._candidate_shots(moment, buffer, new or current, replayable),
            self.director.planned_cuts(),
            flags,
        )

    def _replayable(self) -> tuple[GameEvent, np.ndarray] | None:
        """The latest kill shown live, unless replayed, with the live camera's centre (3,) m at it."""
        if not self._kills_shown or self._kills_shown[-1][0].time_s in self._replayed:
            return None
        kill, live_world, _ = self._kills_shown[-1]
        return kill, live_world

    def _candidate_shots(
        self, moment: Moment, buffer: MomentBuffer, program: Shot | None, replayable: tuple[GameEvent, np.ndarray] | None
    ) -> list[CandidateShot]:
        """The best other situations whose Toric camera at the style's place shows their subjects
        (shot_builder.py `candidate_camera`; an OVERVIEW candidate reuses the program pose until
        it is taken), and a REPLAY of the replayable kill (replays.py) from replay_after_s after it
        while it can be shown, in the last one's place when they are as many as `candidates`."""
        out: list[CandidateShot] = []
        program_set = set(program.subjects) if program is not None else set()
        for option in self.situations.options(moment, buffer):
            if len(out) >= self.settings.candidates:
                break
            if set(option.subjects) == program_set or option.kind == ShotKind.OVERVIEW:
                continue
            camera = self.builder.candidate_camera(option.kind, option.subjects, moment)
            if camera is None:  # it would show walls (issue 41): the next situation instead
                continue
            out.append(
                (ShotChoice(tuple(self.players[i] for i in option.subjects), option.kind, option.reason), camera, option.score)
            )
        if replayable is None or is_replay(program) or not self.settings.candidates:
            return out
        kill, live_world = replayable
        # offered once the live shot has followed the survivor a moment, as our director replays (and its place
        # search does not weigh on the kill's own tick, when a take's fallback or the next beat is decided)
        later = moment.time_s >= kill.time_s + self.settings.replay_after_s
        if later and any(k is kill for k in self.replays.kills(buffer, moment.time_s)):
            # a Toric camera (the monitors' and takes' kind), never the kill cam our director may replay through
            replay = self.replays.shot(kill, buffer, live_world, moment.time_s, "replay candidate", eyes=False)
            if replay is not None:
                assert isinstance(replay.camera, ToricCamera)  # a replay's camera is a DUEL's
                # in the last situation's place when they fill the monitors
                out = [*out[: self.settings.candidates - 1], (replay.choice, replay.camera, replay.scores["place_visibility"])]
        return out


def _next_cut(held: ShotChoice | None, planned_cuts: list[PlannedCut], now_s: float) -> PlannedCut | None:
    """The first of the planned cuts after now_s, s; None while a take is held (MatchRig.planned_cut)."""
    return None if held is not None else next((cut for cut in planned_cuts if cut.time_s > now_s), None)
