"""The MATCH rig on tiny hand-built matches: planned cuts before buffered kills, the delay's
buffering, film grammar (min shot, no jump cut, line of action), takes and their fallback, the
HLTV baseline's chase on a kill, and determinism by seed."""

from __future__ import annotations

import copy
import dataclasses
import math
import pickle

import numpy as np
import pytest

from camdirector.geometry.camera import CameraPose
from camdirector.infra.slices import SlicedRun, pause
from camdirector.pipeline.match.camera_ahead import AnswerLens, CameraStep
from camdirector.pipeline.match.director_registry import registered
from camdirector.pipeline.match.drawn_plan import DrawnPlan, PlanResult
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.grammar import is_jump_cut
from camdirector.pipeline.match.program_shot import Shot
from camdirector.pipeline.match.settings import HltvSettings, MatchSettings
from camdirector.pipeline.match.shots import StaticCamera, ToricCamera
from camdirector.pipeline.session import Session
from camdirector.pipeline.style import Rig, Style
from tests.pipeline.match.scenes import (
    EYE_M,
    RATE_HZ,
    BareRig,
    Match,
    at_time,
    facing,
    kill,
    melee,
    on_screen,
    run_session,
    shots,
    shows,
)

TEAMS = {"a1": 1, "b1": 2, "a2": 1, "b2": 2}
IDS = list(TEAMS)
KILL_S = 25.0


def two_fronts(t: float):
    """a1 and b1 face each other 8 m apart (the obvious fight); a2 and b2 stand 15 m apart, b2
    turned away, no fight until a2 kills b2 at KILL_S."""
    return {
        "a1": ((0.0, 0.0), facing((0, 0), (0, 8))),
        "b1": ((0.0, 8.0), facing((0, 8), (0, 0))),
        "a2": ((40.0, 0.0), 0.0),
        "b2": ((40.0, 15.0), 0.0),
    }


@pytest.mark.parametrize("first_person", [True, False])
def test_buffered_kill_gets_a_duel_cut_one_to_four_seconds_before_it(first_person):
    """The cut comes 1-4 s before the kill, on the killer alone (the pair only around the kill:
    shots.py PairWindow); at the kill the shot is the DUEL of both, both shown: a Toric camera
    frames them, a first-person one is a2's eyes, b2 in its frame (a2 faces it)."""
    match = Match(TEAMS, two_fronts, [kill("a2", "b2", KILL_S)], delay_s=10.0)
    # b2, 15 m from a2, fills under 0.1 of its frame (the default floor): a lower one lets a2's eyes show it
    states = BareRig(match, MatchSettings(first_person=first_person, eyes_shown_height_min=0.05)).run(40.0)
    covering = [(start, s) for start, end, s in shots(states) if start <= KILL_S < end]
    assert len(covering) == 1
    start, first = covering[0]
    assert first.match.shot.kind == ShotKind.FOLLOW and first.match.shot.subject_ids == ("a2",)
    assert "planned kill" in first.match.shot.reason and "a2 alone" in first.match.shot.reason
    assert KILL_S - 4.0 <= start <= KILL_S - 1.0
    at_kill = at_time(states, KILL_S)
    assert at_kill.match.shot.kind == ShotKind.DUEL and set(at_kill.match.shot.subject_ids) == {"a2", "b2"}
    assert shows(at_kill, IDS, 2) and shows(at_kill, IDS, 3)
    assert (at_kill.match.shot.eyes_id == "a2") == first_person


@pytest.mark.parametrize("first_person", [True, False])
def test_a_planned_duel_frames_the_pair_only_around_its_kill_and_reframes_without_a_jump(first_person):
    """Before the pair's window (pair_before_s plus the easing) and after it, the program names the
    killer alone and shows it; between, both; the camera moves from one framing to the other
    within the shot, never by more than a cut's jump between two frames (through a2's eyes it
    does not move: a2 stands still)."""
    settings = MatchSettings(first_person=first_person, eyes_shown_height_min=0.05)  # b2 is 15 m from a2
    match = Match(TEAMS, two_fronts, [kill("a2", "b2", KILL_S)], delay_s=10.0)
    states = BareRig(match, settings).run(40.0)
    start, end, _ = next((a, b, s) for a, b, s in shots(states) if a <= KILL_S < b)
    shot = [s for s in states if not s.match.buffering and start <= s.time_s < end]
    opens, closes = KILL_S - settings.pair_before_s, KILL_S + settings.pair_after_s
    for state in shot:
        names = state.match.shot.subject_ids
        if opens <= state.time_s <= closes:
            assert set(names) == {"a2", "b2"}
        elif state.time_s < opens - 0.5 * settings.reframe_s or state.time_s > closes + 0.5 * settings.reframe_s:
            assert names == ("a2",)
            assert shows(state, IDS, 2)
    alone = [s for s in shot if s.match.shot.subject_ids == ("a2",)]
    assert alone and any(s.time_s < opens for s in alone) and any(s.time_s > closes for s in alone)
    steps_m = [np.linalg.norm(b.pose.position_world - a.pose.position_world) for a, b in zip(shot, shot[1:])]
    # a2 stands still: 15 m from b2, the pair's torus is ~8 m across; one frame of the 0.5-s easing moves ~1 m
    assert max(steps_m) < 2.0


def test_the_delay_buffers_then_answers_the_moment_delay_seconds_ago():
    match = Match(TEAMS, two_fronts, [], delay_s=2.0)
    _, states = run_session(match, 4.0)
    waiting = [s for s in states if s.match.buffering]
    assert waiting and all(s.pose is None and s.time_s < 2.0 for s in waiting)
    shown = [s for s in states if not s.match.buffering]
    assert shown[0].time_s == pytest.approx(0.0) and shown[-1].time_s == pytest.approx(2.0, abs=1e-6)
    assert shown[-1].frame == len(states) - 1 - 60 and all(s.pose is not None for s in shown)


@pytest.mark.parametrize("delay_s", [0.0, 10.0])
def test_grammar_holds_over_a_melee(delay_s):
    match = melee(seed=3, duration_s=50.0 + delay_s, delay_s=delay_s)
    _, states = run_session(match, 50.0 + delay_s)
    ids = list(match.teams)
    program = shots(states)
    assert len(program) >= 6
    assert all(end - start >= Style().min_shot_s - 1e-6 for start, end, _ in program[:-1])
    shown = [s for s in states if not s.match.buffering]
    left_of = {}
    for before, after in zip(shown, shown[1:]):
        if not after.cut:
            continue
        subjects = [ids.index(p) for p in after.match.shot.subject_ids]
        points = np.array(after.aim_points_world)[subjects] if subjects else np.zeros((0, 3))
        assert not is_jump_cut(
            before.match.shot.subject_ids,
            before.pose.position_world,
            after.match.shot.subject_ids,
            after.pose.position_world,
            points,
            30.0,
        )
        if after.match.shot.kind == ShotKind.DUEL:
            x = on_screen(after, points)[:, 0]
            left = after.match.shot.subject_ids[int(np.argmin(x))]
            assert left_of.setdefault(frozenset(after.match.shot.subject_ids), left) == left, "line of action crossed"


def test_kills_in_a_melee_are_framed_with_a_delay_and_not_all_without():
    framed = {}
    for delay_s in (0.0, 10.0):
        match = melee(seed=3, duration_s=60.0 + delay_s, delay_s=delay_s)
        _, states = run_session(match, 60.0 + delay_s)
        ids = list(match.teams)
        hits = []
        for event in (e for e in match.events if e.time_s <= 60.0):
            s = at_time(states, event.time_s)
            hits.append(shows(s, ids, ids.index(event.actor_id)) and shows(s, ids, ids.index(event.other_actor_id)))
        framed[delay_s] = np.mean(hits)
    assert framed[10.0] == 1.0
    assert framed[0.0] < framed[10.0]


def test_take_is_held_past_max_shot_until_released():
    match = Match(TEAMS, two_fronts, [], delay_s=0.0)
    session, states = run_session(match, 1.0)
    choice = session.rig.take(["a2"], None, release=False)
    assert choice.kind == ShotKind.FOLLOW
    held = [session.frame(u) for u in list(match.frames(20.0))[31:]]
    assert all(
        shot.subject_ids == ("a2",) and shot.held and shot.reason.startswith("take") for shot in (s.match.shot for s in held)
    )
    assert sum(s.cut for s in held) == 1
    session.rig.take([], None, release=True)
    after = [session.frame(u) for u in list(match.frames(25.0))[601:]]
    assert after[0].cut and after[0].match.shot.subject_ids != ("a2",)


def test_a_take_no_place_of_its_kind_frames_goes_wide_and_is_held(monkeypatch):
    """A take of a DUEL that no DUEL place frames within the band (the builder finds none: isolated
    here) goes to air as the wide view of its players, held and flagged `take_wide`; before, the
    frame failed (an AssertionError: a live cast's dashboard take ended its stream)."""
    match = Match(TEAMS, two_fronts, [], delay_s=0.0)
    session, _ = run_session(match, 1.0)
    build = session.rig.builder.build

    def no_duel_place(choice, *args, **kwargs):
        return (None, -1.0) if choice.kind == ShotKind.DUEL and choice.held else build(choice, *args, **kwargs)

    monkeypatch.setattr(session.rig.builder, "build", no_duel_place)
    session.rig.take(["a1", "b1"], ShotKind.DUEL, release=False)
    held = [session.frame(u) for u in list(match.frames(3.0))[31:]]
    shots = [s.match.shot for s in held]
    assert all(shot.kind == ShotKind.OVERVIEW and shot.held and shot.subject_ids == ("a1", "b1") for shot in shots)
    assert "take_wide" in held[0].flags and sum(s.cut for s in held) == 1


def test_taking_a_candidate_puts_its_previewed_camera_on_air():
    """What the candidate's monitor showed is what the program cuts to: its camera and place, not
    a new search (which for a1/b1 would film the fight from wherever the program stood)."""
    match = Match(TEAMS, two_fronts, [], delay_s=0.0)
    session, states = run_session(match, 1.0)
    last = states[-1]
    candidate = last.match.candidates[0]
    session.rig.take(list(candidate.shot.subject_ids), candidate.shot.kind, release=False)
    after = [session.frame(u) for u in list(match.frames(2.0))[31:]]
    assert after[0].cut and set(after[0].match.shot.subject_ids) == set(candidate.shot.subject_ids) and after[0].match.shot.held
    # one program frame later than the preview: the players moved a little, the place did not
    assert np.linalg.norm(after[0].pose.position_world - candidate.pose.position_world) < 0.5
    forward = [2.0 * np.array(q[:3]) for q in (after[0].pose.rotation_xyzw, candidate.pose.rotation_xyzw)]
    assert np.linalg.norm(forward[0] - forward[1]) < 0.1
    assert not any(s.cut for s in after[1:])


def test_a_take_goes_on_air_at_the_next_program_frame_with_the_window_full():
    """With a 10 s delay the rig works 2.5 s ahead; a take drops those frames and is on air at once."""
    match = Match(TEAMS, two_fronts, [], delay_s=10.0)
    session, states = run_session(match, 14.0)
    last = states[-1]
    assert math.isclose(session.rig.window_s, 2.5) and len(session.rig.window.frames) >= 70  # the window is full
    candidate = last.match.candidates[0]
    session.rig.take(list(candidate.shot.subject_ids), candidate.shot.kind, release=False)
    after = [session.frame(u) for u in list(match.frames(16.0))[14 * 30 + 1 :]]
    assert after[0].cut and after[0].match.shot.held
    assert set(after[0].match.shot.subject_ids) == set(candidate.shot.subject_ids)
    assert math.isclose(after[0].time_s, last.time_s + (1.0 / 30.0), abs_tol=1e-6)  # the program's time goes on
    assert np.linalg.norm(after[0].pose.position_world - candidate.pose.position_world) < 0.5
    assert not any(s.cut for s in after[1:]) and all(s.match.shot.held for s in after)
    assert [round(s.time_s - t.time_s, 6) for s, t in zip(after[1:], after)] == [round((1.0 / 30.0), 6)] * (len(after) - 1)


def test_a_rig_checkpointed_before_the_edit_window_works_on_and_refills_it():
    """A checkpoint of an earlier version (no window in the rig) restores, answers the next
    program moment and works the window out again."""
    match = Match(TEAMS, two_fronts, [], delay_s=10.0)
    session, states = run_session(match, 12.0)
    while session.rig.do_deferred_work(True):  # as a snapshot does: no plan half computed
        pass
    session.rig._rewind()  # as an earlier version left it: working at the moment it last answered
    old = copy.copy(session.rig)
    for name in ("window", "_head", "_answered_s", "_body_heights_m"):
        del old.__dict__[name]
    session.rig = pickle.loads(pickle.dumps(old))
    after = [session.frame(u) for u in list(match.frames(15.0))[12 * 30 + 1 :]]
    assert math.isclose(after[0].time_s, states[-1].time_s + 1.0 / 30.0, abs_tol=1e-6) and after[0].pose is not None
    assert len(session.rig.window.frames) >= 55  # refilled, one more frame a frame


def test_take_falls_back_to_the_attacker_when_the_held_player_dies():
    match = Match(TEAMS, two_fronts, [kill("a2", "b2", 3.0)], delay_s=0.0)
    session, _ = run_session(match, 1.0)
    session.rig.take(["b2"], ShotKind.FOLLOW, release=False)
    states = [session.frame(u) for u in list(match.frames(6.0))[31:]]
    after = [s for s in states if s.time_s > 3.0 + 0.2]
    assert all(s.match.shot.subject_ids == ("a2",) and s.match.shot.held for s in after)
    assert "b2 died (killed by a2)" in after[0].match.shot.reason and "take fallback" in after[0].match.shot.reason


def test_take_refuses_an_unknown_player_and_a_kind_that_does_not_fit():
    session, _ = run_session(Match(TEAMS, two_fronts), 0.2)
    with pytest.raises(ValueError, match="unknown player 'zz'"):
        session.rig.take(["a1", "zz"], None, release=False)
    with pytest.raises(ValueError, match="DUEL shot cannot show 1"):
        session.rig.take(["a1"], ShotKind.DUEL, release=False)


def test_hltv_shows_a_kill_as_a_chase_camera_behind_the_victim():
    hltv = HltvSettings(in_eye_kill_chance=0.0, swap_chance_chase=0.0)
    style = Style(rig=Rig.MATCH, match_director="hltv")
    match = Match(TEAMS, two_fronts, [kill("a2", "b2", KILL_S)], delay_s=10.0, style=style)
    states = BareRig(match, MatchSettings(hltv=hltv)).run(40.0)
    start = max(start for start, _, _ in shots(states) if start <= KILL_S)
    shot = at_time(states, KILL_S).match.shot
    assert shot.kind == ShotKind.DUEL and shot.subject_ids == ("b2", "a2") and "chase behind b2" in shot.reason
    assert KILL_S - 8.0 <= start <= KILL_S
    victim_eye, attacker_eye = np.array([40.0, EYE_M, 15.0]), np.array([40.0, EYE_M, 0.0])
    camera = at_time(states, KILL_S - 0.1).pose.position_world  # the victim still standing
    assert np.linalg.norm(camera - victim_eye) == pytest.approx(hltv.kill_chase_distance_m, rel=1e-3)
    assert np.linalg.norm(camera - attacker_eye) > np.linalg.norm(victim_eye - attacker_eye)  # behind the victim
    assert camera[1] < victim_eye[1]  # pitch -20: the low view


def test_hltv_without_look_ahead_cuts_every_six_seconds_on_ranked_players():
    style = Style(rig=Rig.MATCH, match_director="hltv")
    match = dataclasses.replace(melee(seed=4, duration_s=40.0, delay_s=0.0), style=style)
    program = shots(run_session(match, 40.0)[1])
    lengths = [end - start for start, end, _ in program[:-1]]
    tick_s = MatchSettings().plan_interval_s + 1.0 / RATE_HZ  # a cut waits for the next planning tick and frame
    assert lengths and all(0.0 <= length - HltvSettings().default_shot_s <= tick_s + 1e-9 for length in lengths)
    assert all(s.match.shot.reason.startswith("hltv: ") for _, _, s in program)


@pytest.mark.parametrize("kind", [entry.name for entry in registered()])
def test_same_seed_same_program(kind):
    style = Style(rig=Rig.MATCH, match_director=kind)
    runs = []
    for _ in range(2):
        match = dataclasses.replace(melee(seed=5, duration_s=30.0, delay_s=10.0), style=style)
        runs.append(run_session(match, 30.0)[1])
    poses = [np.array([s.pose.position_world for s in states if s.pose is not None]) for states in runs]
    assert np.array_equal(poses[0], poses[1])
    reasons = [[s.match.shot.reason for s in states if s.cut and s.match.shot] for states in runs]
    assert reasons[0] == reasons[1]


def test_style_refuses_a_max_shot_under_the_min_shot():
    with pytest.raises(ValueError, match="max_shot_s"):
        Style(rig=Rig.MATCH, min_shot_s=5.0, max_shot_s=4.0)


def _program_with_idle_work(
    idle: str, work_per_tick: float | None = None
) -> tuple[list[tuple], int, tuple[int, int], int, int, int, int]:
    """The melee's program through a Session whose clock ticks 1 ms a read, with the worker's idle
    moments after each frame: none, a seeded-random number of slices, or all the deferred work.
    Returns each shown frame's pose (7,), visibility, flags and candidates' poses; how many frames
    left a drawn plan; in "slices" how many slices left it unfinished and how many plans idle
    moments finished; how many ticks found their plan late (work_per_tick: the rig's
    plan_work_per_tick, default MatchSettings'); and how many frames took their camera's step
    as worked out ahead, how many did not though their shot went on (a tick's new goal), and how
    many answered the lens checked ahead."""
    ticks = iter(range(10**9))
    session = Session("s", melee(seed=3, duration_s=40.0, delay_s=10.0).scene(), clock=lambda: next(ticks) * 1e-3)
    rig = session.rig
    if work_per_tick is not None:  # a Session takes the default settings; the rig reads this one field at its ticks
        rig.settings = dataclasses.replace(rig.settings, plan_work_per_tick=work_per_tick)
    worked_out: list[tuple[bool, bool]] = []  # (held, the same shot went on)
    holds = CameraStep.holds

    def counted(step: CameraStep, moment, dt_s, shot, *args) -> bool:
        worked_out.append((holds(step, moment, dt_s, shot, *args), step.shot is shot and step.moment is moment))
        return worked_out[-1][0]

    lens_holds = AnswerLens.holds
    lenses: list[bool] = []

    def lens_counted(lens: AnswerLens, *args) -> bool:
        lenses.append(lens_holds(lens, *args))
        return lenses[-1]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(CameraStep, "holds", counted)
        patch.setattr(AnswerLens, "holds", lens_counted)
        program = _program_of(session, idle, worked_out)
    return *program, sum(lenses)


def _program_of(
    session: Session, idle: str, worked_out: list[tuple[bool, bool]]
) -> tuple[list[tuple], int, tuple[int, int], int, int, int]:
    rig = session.rig
    rng = np.random.default_rng(11)
    program, drawn, partial, finished, late = [], 0, 0, 0, 0
    for update in melee(seed=3, duration_s=40.0, delay_s=10.0).frames(40.0):
        state = session.frame(update)
        late += "plan_late" in state.flags
        if state.pose is not None:
            program.append(
                (
                    np.concatenate([state.pose.position_world, state.pose.rotation_xyzw]),
                    state.visibility,
                    tuple(state.flags),
                    [(c.shot, c.pose.position_world.tolist(), c.pose.rotation_xyzw.tolist()) for c in state.match.candidates],
                )
            )
        drawn += rig.plan_waiting
        if idle == "whole":
            session.do_deferred_work()
        elif idle == "slices":
            for _ in range(int(rng.integers(0, 4))):
                if session.do_deferred_work(whole=False):
                    partial += rig.plan_waiting
                    finished += not rig.plan_waiting
    held = sum(h for h, _ in worked_out)
    return program, drawn, (partial, finished), late, held, sum(not h and same for h, same in worked_out)


@pytest.mark.parametrize("work_per_tick", [None, 2e3])
def test_the_program_does_not_depend_on_when_or_in_how_many_slices_the_plan_was_computed(work_per_tick):
    """The plan drawn at a tick is computed in the worker's idle moments and applied at the first
    tick its work allows (rig.py): the program (poses, visibility, flags, candidates) is the same
    whether no idle moment came (each tick computes it up to its work), some slices ran, or all
    the deferred work was done at once; also when most plans need more than one tick's work (2e3
    camera-point pairs). So with the camera's steps worked out ahead in the idle moments, which
    most frames took: with the idle moments' work all done, every frame whose shot went on, a
    tick's new goal too (worked out again with it once the plan was computed), and most answers'
    lens checks (camera_ahead.py)."""
    none, drawn, _, late, ahead_none, _, lens_none = _program_with_idle_work("none", work_per_tick)
    sliced, _, (partial, finished), late_sliced, ahead_sliced, _, _ = _program_with_idle_work("slices", work_per_tick)
    whole, _, _, late_whole, ahead_whole, missed_whole, lens_whole = _program_with_idle_work("whole", work_per_tick)
    assert missed_whole == 0
    assert lens_none == 0 and lens_whole > len(whole) * 0.9
    assert drawn > 50  # ours defers: a plan was waiting after many frames
    assert partial > 0 and finished > 0  # slices of 2 ms (a clock ticking 1 ms a read) left some unfinished
    if work_per_tick is not None:
        assert late > 20  # many plans were applied at a later tick
    assert late == late_sliced == late_whole
    assert ahead_none == 0 and ahead_sliced > 100 and ahead_whole > len(whole) / 2
    for other in (sliced, whole):
        assert len(none) == len(other)
        for a, b in zip(none, other):
            assert np.array_equal(a[0], b[0]) and a[1:] == b[1:]


def _plan_of_work(*steps: float) -> SlicedRun:
    """A stand-in plan: pauses with each step's work, then returns its total."""

    def work() -> float:
        for step in steps:
            pause(step)
        return sum(steps)

    return SlicedRun(work)


def test_a_drawn_plan_is_applied_at_the_first_tick_its_work_allows_whether_or_not_idle_moments_computed_it():
    """plan_work_per_tick per tick since it was drawn: 2.5 ticks' work is applied at the third tick,
    computed then by the ticks themselves or beforehand, whole, by idle moments."""
    for computed_beforehand in (False, True):
        drawn = DrawnPlan(current=None, run=_plan_of_work(100.0, 100.0, 50.0))
        if computed_beforehand:
            drawn.finish()
        assert [drawn.due(100.0) for _ in range(4)] == [False, False, True, True]
        assert drawn.result == 250.0 and drawn.work == 250.0


def test_a_take_finishes_the_drawn_plan_before_it_changes_what_the_plan_reads():
    """A take arriving while a plan is drawn finishes it first (a style change too): the plan never
    sees a take or style that came after the tick it was drawn on."""
    match = melee(seed=3, duration_s=20.0, delay_s=10.0)
    session = Session("s", match.scene())
    for update in match.frames(15.0):
        session.frame(update)
        if session.rig.plan_waiting:
            break
    assert session.rig.plan_waiting
    session.rig.take(["a0"], None, release=False)
    assert not session.rig.plan_waiting
    for update in match.frames(16.0):
        if update.frame > session.last_input[0]:
            session.frame(update)
            if session.rig.plan_waiting:
                break
    session.rig.set_style(Style(rig=Rig.MATCH, match_director="hltv"))
    assert not session.rig.plan_waiting


def test_a_drawn_cut_that_breaks_the_30_degree_rule_against_the_pose_on_air_is_refused():
    """A plan judged the 30-degree rule against the pose of the tick that drew it; the camera
    moves on until the tick that applies it, which judges the cut again against the pose on air:
    a cut to the same view of the same players is refused (flagged), one from the opposite side
    goes on air."""
    match = melee(seed=3, duration_s=30.0, delay_s=10.0)
    session = Session("s", match.scene())
    for update in match.frames(30.0):
        state = session.frame(update)
        rig = session.rig
        # the rig's shot and pose are those of the window's end (the newest frame worked out)
        if state.pose is not None and isinstance(rig.shot.camera, ToricCamera) and not rig.window.frames[-1].cut:
            break
    moment, pose = rig._head, rig._last_pose
    on_air = rig.shot
    framed = on_air.framed(moment.time_s)
    same = Shot(on_air.choice, on_air.subjects, copy.deepcopy(on_air.camera), moment.time_s)
    centre = moment.aims_world[list(framed)].mean(axis=0)
    behind = StaticCamera(CameraPose(2.0 * centre - pose.position_world, pose.rotation_xyzw, 50.0))
    opposite = Shot(on_air.choice, on_air.subjects, behind, moment.time_s)

    def result(shot: Shot) -> PlanResult:
        return PlanResult(shot, None, None, None, [], [], [])

    flags: list[str] = []
    assert not rig._apply(result(same), moment, flags, drawn_on=on_air)
    assert flags == ["cut_refused_jump"] and rig.shot is on_air
    assert rig._apply(result(opposite), moment, flags, drawn_on=on_air)
    assert rig.shot is opposite and flags == ["cut_refused_jump"]


def test_plan_work_per_tick_is_validated():
    with pytest.raises(ValueError, match="plan_work_per_tick"):
        MatchSettings(plan_work_per_tick=10.0)


@pytest.mark.parametrize("field", ["edit_window_s", "edit_lengthen_s"])
@pytest.mark.parametrize("value", [10.5, -0.1, math.nan])
def test_the_edit_windows_lengths_are_validated(field, value):
    with pytest.raises(ValueError, match=field):
        MatchSettings(**{field: value})
