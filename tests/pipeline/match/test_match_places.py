"""Where our director puts the camera for a kill and which events it plans: a corridor that hides
the style's place, an objective that gives way to a kill, and the hysteresis on discretionary cuts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from camdirector.geometry.camera import project_to_screen
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.inputs import EventKind, GameEvent
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.moments import MomentBuffer
from camdirector.pipeline.match.planned import JUMP_TICKS
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import Place, ToricCamera, best_place, place_grid, wall_free
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.pipeline.style import Style
from camdirector.pipeline.toric.target_sampling import SurfaceSampler
from tests.pipeline.match.scenes import (
    LENS,
    RATE_HZ,
    BareRig,
    Match,
    at_time,
    facing,
    kill,
    melee,
    player_mesh,
    run_session,
    shots,
    yaw_quat,
)

KILL_S = 25.0


def block(centre, size) -> TriMesh:
    mesh = box(size)
    return TriMesh(mesh.vertices + np.asarray(centre, dtype=float), mesh.faces)


def duel(t: float):
    """a and b face each other 8 m apart along +z."""
    return {"a": ((0.0, 0.0), facing((0, 0), (0, 8))), "b": ((0.0, 8.0), facing((0, 8), (0, 0)))}


def seen_share(pose, walls: list[TriMesh], transform: RigidTransform, rng: np.random.Generator) -> float:
    """Share of 32 fresh surface points of a player inside the frame and not hidden by the walls
    (the evaluation's measure, independent of the director's own samples)."""
    points = transform.apply(SurfaceSampler(player_mesh()).sample(32, rng))
    inside = np.all(np.abs(project_to_screen(pose, LENS, points)) <= 1.0, axis=1)
    return float((inside & ~RayScene(walls).occluded(pose.position_world, points)).mean())


def test_a_corridor_hiding_the_styles_place_still_gets_a_place_that_sees_both_at_the_kill():
    # walls 3 m high along the duel, 1.5 m each side of it: the style's place (phi 70 deg, beside
    # the pair on a torus about 10 m across) is outside the corridor; a place above or over a
    # shoulder is not
    walls = [block((x, 1.5, 4.0), (0.2, 3.0, 30.0)) for x in (-1.5, 1.5)]
    match = Match({"a": 1, "b": 2}, duel, [kill("a", "b", KILL_S)], delay_s=10.0, walls=walls)
    # the Toric camera's place (our director would otherwise look through a's eyes: first_person.py)
    states = BareRig(match, MatchSettings(first_person=False)).run(KILL_S + 10.0 + 2.0)
    state = at_time(states, KILL_S)
    transforms = [RigidTransform(np.array([0.0, 0.0, z]), np.array([0.0, 0.0, 0.0, 1.0])) for z in (0.0, 8.0)]
    rng = np.random.default_rng(11)
    # the style's own place is hidden (so the test can fail): both orders of the pair
    buffer = MomentBuffer(["a", "b"], MatchSettings())
    aims = [t.apply(np.array([[0.0, 1.6, 0.0]]))[0] for t in transforms]
    buffer.push(0, KILL_S, transforms, aims, [])
    style = match.style
    default = Place(style.preferred_theta_ratio, math.radians(style.preferred_phi_deg))
    for a, b in ((0, 1), (1, 0)):
        camera = ToricCamera(ShotKind.DUEL, a, b, style, LENS, default)
        pose = camera.pose(buffer.newest)
        assert min(seen_share(pose, walls, t, rng) for t in transforms) < 0.5
    assert set(state.match.shot.subject_ids) == {"a", "b"}
    assert min(seen_share(state.pose, walls, t, rng) for t in transforms) >= 0.5


def four_corners(t: float):
    """o1 stands on an objective at the west; a2 and b2 duel 60 m east, in a roofed corridor."""
    return {
        "o1": ((-30.0, 0.0), 0.0),
        "o2": ((-30.0, 40.0), 0.0),
        "a2": ((30.0, 0.0), facing((30, 0), (30, 8))),
        "b2": ((30.0, 8.0), facing((30, 8), (30, 0))),
    }


def test_a_kill_too_close_after_an_objective_takes_its_place():
    objective = GameEvent(EventKind.OBJECTIVE, "o1", "", 0, KILL_S - 0.8, "objective", None)
    # the corridor hides a2 and b2 from any camera far enough back to frame o1 with them (a GROUP)
    corridor = [block((x, 1.5, 4.0), (0.2, 3.0, 40.0)) for x in (28.5, 31.5)] + [block((30.0, 3.1, 4.0), (3.2, 0.2, 40.0))]
    match = Match(
        {"o1": 1, "o2": 2, "a2": 1, "b2": 2}, four_corners, [objective, kill("a2", "b2", KILL_S)], delay_s=10.0, walls=corridor
    )
    _, states = run_session(match, KILL_S + 10.0 + 2.0)
    state = at_time(states, KILL_S)
    assert state.match.shot.kind == ShotKind.DUEL and set(state.match.shot.subject_ids) == {"a2", "b2"}
    assert "planned kill" in state.match.shot.reason


def test_without_a_delay_a_cut_for_a_better_situation_waits_for_settle_s():
    match = melee(seed=3, duration_s=60.0, delay_s=0.0)
    _, states = run_session(match, 60.0)
    program = shots(states)
    better = [
        (previous, start)
        for (previous, _, _), (start, _, s) in zip(program, program[1:])
        if s.match.shot.reason.endswith("(better situation)")
    ]
    assert better, "the melee has discretionary cuts"
    settle_s = MatchSettings().settle_s
    assert all(start - previous >= settle_s - 1e-6 for previous, start in better)


def two_corridors(t: float):
    """a1 and b1 duel in one corridor, a2 and b2 in another 12 m east."""
    return {
        "a1": ((0.0, 0.0), facing((0, 0), (0, 6))),
        "b1": ((0.0, 6.0), facing((0, 6), (0, 0))),
        "a2": ((12.0, 0.0), facing((12, 0), (12, 6))),
        "b2": ((12.0, 6.0), facing((12, 6), (12, 0))),
    }


def test_two_kills_too_close_for_two_cuts_share_a_high_wide_shot_when_no_group_framing_sees_them():
    # 5 m walls 3 m apart: every Toric GROUP place sees into one corridor at most; a camera 30 m
    # above the pair of corridors looks down into both
    walls = [block((x, 2.5, 3.0), (0.2, 5.0, 40.0)) for x in (-1.5, 1.5, 10.5, 13.5)]
    match = Match(
        {"a1": 1, "b1": 2, "a2": 1, "b2": 2},
        two_corridors,
        [kill("a1", "b1", KILL_S), kill("a2", "b2", KILL_S + 0.5)],
        delay_s=10.0,
        walls=walls,
    )
    states = BareRig(match, MatchSettings(overview_height_m=30.0)).run(KILL_S + 10.0 + 2.0)
    rng = np.random.default_rng(5)
    for time_s, pair in ((KILL_S, ("a1", "b1")), (KILL_S + 0.5, ("a2", "b2"))):
        state = at_time(states, time_s)
        assert state.match.shot.kind == ShotKind.OVERVIEW and "planned kill" in state.match.shot.reason
        places = two_corridors(time_s)
        for player in pair:
            transform = RigidTransform(np.array([places[player][0][0], 0.0, places[player][0][1]]), yaw_quat(places[player][1]))
            assert seen_share(state.pose, walls, transform, rng) >= 0.5, (time_s, player)


def two_duels_side_by_side(t: float):
    """a1 and b1 duel on open ground, a2 and b2 6 m east of them; e1 and f1 duel 60 m away."""
    return {
        "a1": ((0.0, 0.0), facing((0, 0), (0, 6))),
        "b1": ((0.0, 6.0), facing((0, 6), (0, 0))),
        "a2": ((6.0, 0.0), facing((6, 0), (6, 6))),
        "b2": ((6.0, 6.0), facing((6, 6), (6, 0))),
        "e1": ((60.0, 0.0), facing((60, 0), (60, 6))),
        "f1": ((60.0, 6.0), facing((60, 6), (60, 0))),
    }


def test_a_kill_soon_after_another_gets_a_later_cut_so_that_the_shot_before_lasts_preferred_shot_s():
    # the program is on e1 and f1 for their kill at 21 s; the kill at 25 s gets its DUEL at 22.5 s
    # (lead_s); the one at 27.5 s would get its own at 25 s, 2.5 s later: it comes at 25.5 s instead
    kills = [kill("e1", "f1", KILL_S - 4.0), kill("a1", "b1", KILL_S), kill("a2", "b2", KILL_S + 2.5)]
    match = Match({"a1": 1, "b1": 2, "a2": 1, "b2": 2, "e1": 1, "f1": 2}, two_duels_side_by_side, kills, delay_s=10.0)
    settings = MatchSettings()
    states = [s for s in BareRig(match, settings).run(KILL_S + 10.0 + 4.0) if not s.match.buffering]
    cuts = [s.time_s for s in states if s.cut and KILL_S - 4.0 < s.time_s <= KILL_S + 2.5]
    assert len(cuts) == 2 and cuts[1] - cuts[0] >= settings.preferred_shot_s - 1e-6
    assert KILL_S + 2.5 - cuts[1] >= settings.min_lead_s - 1e-6
    for time_s, pair in ((KILL_S, {"a1", "b1"}), (KILL_S + 2.5, {"a2", "b2"})):
        state = at_time(states, time_s)
        assert state.match.shot.kind == ShotKind.DUEL and set(state.match.shot.subject_ids) == pair


def _teleported(who: str, at_s: float, away_s: float = 0.3):
    """two_duels_side_by_side, but `who` stands 14 m south of its place, behind a wall, for
    away_s before at_s, s: two teleports through the wall (moments.py: jumps no run makes), the
    last at at_s. Returns the script and the wall."""

    def script(t: float):
        places = two_duels_side_by_side(t)
        if at_s - away_s <= t < at_s:
            (x, z), yaw = places[who]
            places[who] = ((x, z - 14.0), yaw)
        return places

    (x, z), _ = two_duels_side_by_side(0.0)[who]
    return script, block((x, 1.5, z - 7.0), (2.0, 3.0, 0.2))


def _cuts_between(states: list, start_s: float, end_s: float) -> list[float]:
    return [s.time_s for s in states if s.cut and start_s < s.time_s <= end_s]


def test_a_kill_cut_to_comes_after_its_killers_teleport_and_not_before_it():
    # the cut for a1's kill at 25 s would come at 22.5 s (lead_s); a1 teleports at 23.5 s, where
    # a camera on a1 (its eyes, its anchor) would cut again a second into the shot
    teleport_s = KILL_S - 1.5
    settings = MatchSettings()
    places, wall = _teleported("a1", teleport_s)
    states = _kills_after_one_elsewhere(places, KILL_S + 2.5, settings, [wall])
    cuts = _cuts_between(states, KILL_S - 4.0, KILL_S)
    assert len(cuts) == 1 and teleport_s <= cuts[0] <= KILL_S - settings.min_lead_s, cuts
    assert set(at_time(states, KILL_S).match.shot.subject_ids) == {"a1", "b1"}


def test_a_kill_cut_to_comes_before_the_shot_on_air_meets_its_players_teleport():
    # the program is on e1 and f1 for e1's kill at 21 s, a camera on e1; e1 teleports away at
    # 22.0 s (and back at 22.3 s), before the cut for a1's kill at 25 s would come (22.5 s): that
    # cut comes before the teleport instead, two planning ticks early (it is made at the first
    # tick at or after its time)
    away_s = KILL_S - 3.0
    settings = MatchSettings()
    kills = [kill("e1", "f1", KILL_S - 4.0), kill("a1", "b1", KILL_S)]
    places, wall = _teleported("e1", away_s + 0.3)
    match = Match({"a1": 1, "b1": 2, "a2": 1, "b2": 2, "e1": 1, "f1": 2}, places, kills, delay_s=10.0, walls=[wall])
    states = [s for s in BareRig(match, settings).run(KILL_S + 10.0 + 2.0) if not s.match.buffering]
    assert "e1" in at_time(states, KILL_S - 3.5).match.shot.subject_ids
    cuts = _cuts_between(states, KILL_S - 3.5, KILL_S)
    assert len(cuts) == 1 and away_s - JUMP_TICKS * settings.plan_interval_s - 1.0 / RATE_HZ <= cuts[0] < away_s, cuts
    assert set(at_time(states, KILL_S).match.shot.subject_ids) == {"a1", "b1"}


def _fights_apart(jump_s: float):
    """e1 and f1 fight 60 m east of a1 and b1, who face away from each other until 14 s and
    fight from then on; at jump_s, s, e1 teleports 14 m south, behind a wall, for good."""
    wall = block((60.0, 1.5, -7.0), (30.0, 3.0, 0.2))

    def script(t: float):
        e = (60.0, -14.0) if t >= jump_s else (60.0, 0.0)
        facing_a = (0, 6) if t >= 14.0 else (0, -6)
        facing_b = (0, 0) if t >= 14.0 else (0, 12)
        return {
            "e1": (e, facing(e, (60, 6))),
            "f1": ((60.0, 6.0), facing((60, 6), (60, 0))),
            "a1": ((0.0, 0.0), facing((0, 0), facing_a)),
            "b1": ((0.0, 6.0), facing((0, 6), facing_b)),
        }

    return script, wall


@pytest.mark.parametrize("frame", [0, 1, 2])  # every phase of the planning ticks (a tick every third frame)
def test_where_the_live_cameras_player_teleports_the_director_cuts_there_to_the_best_situation(frame):
    # the program is on e1 and f1 (the first fight); e1 teleports away through a wall, which its
    # eyes or the camera anchored on it would pass through: the cut that makes is the director's,
    # to a1 and b1's fight, at that very frame, not a tick or a settle later
    jump_s = 15.0 + (frame + 0.5) / RATE_HZ
    script, wall = _fights_apart(jump_s)
    settings = MatchSettings()
    match = Match({"a1": 1, "b1": 2, "e1": 1, "f1": 2}, script, delay_s=10.0, walls=[wall])
    states = [s for s in BareRig(match, settings).run(jump_s + 10.0 + 3.0) if not s.match.buffering]
    assert set(at_time(states, jump_s - 0.5).match.shot.subject_ids) == {"e1", "f1"}
    landed = next(s for s in states if s.time_s >= jump_s)  # the first frame with e1 behind the wall
    assert landed.cut and set(landed.match.shot.subject_ids) == {"a1", "b1"}, (landed.time_s, landed.match.shot)
    assert "its camera's player jumped" in landed.match.shot.reason
    assert not _cuts_between(states, landed.time_s, landed.time_s + match.style.min_shot_s)


def _kills_after_one_elsewhere(places, second_s: float, settings: MatchSettings, walls: list | None = None) -> list:
    """The program (past buffering) of e1's kill of f1 at KILL_S - 4 s, then a1's of b1 at KILL_S
    and a2's of b2 at second_s, the players standing at `places` (among `walls`)."""
    kills = [kill("e1", "f1", KILL_S - 4.0), kill("a1", "b1", KILL_S), kill("a2", "b2", second_s)]
    teams = {"a1": 1, "b1": 2, "a2": 1, "b2": 2, "e1": 1, "f1": 2}
    match = Match(teams, places, kills, delay_s=10.0, walls=walls or [])
    return [s for s in BareRig(match, settings).run(KILL_S + 10.0 + 4.0) if not s.match.buffering]


@pytest.mark.parametrize("preferred_shot_s", [0.0, 3.0])
def test_kills_too_close_for_a_preferred_shot_each_share_one_shot_when_it_sees_them_all(preferred_shot_s):
    # the program is on e1 and f1 for their kill at 21 s; the kills at 25 and 25.8 s each get a
    # DUEL (the second 2.7 s after the first: no later cut leaves min_lead_s), unless one GROUP of
    # the four sees both kills
    second_s = KILL_S + 0.8
    states = _kills_after_one_elsewhere(two_duels_side_by_side, second_s, MatchSettings(preferred_shot_s=preferred_shot_s))
    between = [s for s in states if KILL_S - 2.0 < s.time_s <= second_s]
    first, second = at_time(states, KILL_S), at_time(states, second_s)
    if preferred_shot_s == 0.0:
        assert any(s.cut for s in between) and first.match.shot.kind == second.match.shot.kind == ShotKind.DUEL
        return
    assert first.match.shot.kind == ShotKind.GROUP and not any(s.cut for s in states if first.time_s < s.time_s <= second_s)
    assert set(first.match.shot.subject_ids) == {"a1", "b1", "a2", "b2"}
    rng = np.random.default_rng(2)
    for time_s, state in ((KILL_S, first), (second_s, second)):
        places = two_duels_side_by_side(time_s)
        for player in ("a1", "b1", "a2", "b2"):
            (x, z), yaw = places[player]
            transform = RigidTransform(np.array([x, 0.0, z]), yaw_quat(yaw))
            assert seen_share(state.pose, [], transform, rng) >= 0.5, (time_s, player)


def test_a_planned_shot_is_placed_for_the_frame_that_shows_the_kill_too():
    """The kill is on screen at the first frame at or after its time; buffer.at gives the one at
    or before, so the cover holds the frame after it as well (a place seeing both a frame early
    was often at a wall's edge)."""
    from camdirector.pipeline.match.planned import POST_EVENT_S, PRE_EVENT_S, PlannedDirector

    buffer = MomentBuffer(["a", "b"], MatchSettings())
    for k in range(0, 30 * 40):
        t = k / 30.0
        places = duel(t)
        buffer.push(
            k,
            t,
            [RigidTransform(np.array([x, 0.0, z]), yaw_quat(yaw)) for (x, z), yaw in places.values()],
            [np.array([x, 1.6, z]) for (x, z), _ in places.values()],
            [],
        )
    kill_s = 25.01  # between the frames at 25.0 and 25.0333
    cover, weights = PlannedDirector.event_cover(buffer, 20.0, [kill_s])
    times = [m.time_s for m in cover]
    assert times[0] == pytest.approx(kill_s - PRE_EVENT_S, abs=1 / 30.0) and weights[0] < 1.0
    assert times[1] <= kill_s < times[2] <= kill_s + POST_EVENT_S and weights[1:] == [1.0, 1.0]


def two_duels_far_apart(t: float):
    """two_duels_side_by_side with a2 and b2 20 m east of a1 and b1 instead of 6 m."""
    places = two_duels_side_by_side(t)
    places.update({"a2": ((20.0, 0.0), facing((20, 0), (20, 6))), "b2": ((20.0, 6.0), facing((20, 6), (20, 0)))})
    return places


@pytest.mark.parametrize("join_spread_max_m", [15.0, 1000.0])
def test_kills_of_players_far_apart_never_share_a_shot_that_would_show_them_small(join_spread_max_m):
    # the kills at 25 and 25.3 s are too close for two cuts (no later cut leaves min_lead_s); their
    # players span 21 m: one shot of all four frames them small, so by default the second kill is
    # left out rather than joined (on the open nav_test such joins showed players at 0.03-0.07 of the
    # frame); without the limit they share one shot
    states = _kills_after_one_elsewhere(two_duels_far_apart, KILL_S + 0.3, MatchSettings(join_spread_max_m=join_spread_max_m))
    shown = at_time(states, KILL_S).match.shot
    if join_spread_max_m < 21.0:
        assert shown.kind in (ShotKind.DUEL, ShotKind.FOLLOW) and set(shown.subject_ids) <= {"a1", "b1"}
        assert any("plan_events_left_out" in f for s in states for f in s.flags)
    else:
        assert shown.kind in (ShotKind.GROUP, ShotKind.OVERVIEW) and set(shown.subject_ids) == {"a1", "b1", "a2", "b2"}


def test_a_place_whose_camera_would_cross_a_wall_in_the_shots_first_seconds_gives_way():
    # a pair 8 m apart along z walks 4 m along +x: every place's camera moves by (4, 0, 0); a wall
    # across x = 2 (its slab 1.9-2.1 m) is met by exactly the cameras whose move overlaps it, and a
    # place seen as well from beyond the wall's reach wins the tie it would lose (shots.py wall_free)
    from tests.pipeline.match.test_match_real_maps import moment_of  # which imports this module's block

    def at(x: float):
        return moment_of({"a": (x, 0.0), "b": (x, 8.0)}, {"a": (x, 8.0), "b": (x, 0.0)})

    scene = RayScene([block((2.0, 0.0, 4.0), (0.2, 100.0, 100.0))])
    visibility = SubjectVisibility(scene, [player_mesh(), player_mesh()], 16, np.random.default_rng(0))
    path = [at(0.0), at(2.0), at(4.0)]
    camera = ToricCamera(ShotKind.DUEL, 0, 1, Style(), LENS, Place(0.5, math.radians(90.0)))
    places = place_grid(None)
    start = camera.positions(path[0], places)[:, 0]
    assert np.allclose(camera.positions(path[-1], places)[:, 0], start + 4.0)  # the torus moves with the pair
    crossing = (start < 2.1) & (start + 4.0 > 1.9)  # the move overlaps the slab
    assert crossing.any() and not crossing.all()
    assert np.array_equal(wall_free(camera, places, path, visibility), ~crossing)
    # two places this side of the wall that see both at the cut: the first crosses it on the way
    seen = np.array([best_place(camera, [p], path[:1], (0, 1), visibility)[1] for p in places])
    near = next(k for k in np.flatnonzero(crossing & (start < -0.5) & (seen == 1.0)))
    far = next(k for k in np.flatnonzero(~crossing & (start < -2.5) & (seen == 1.0)))
    pair = [places[near], places[far]]
    assert best_place(camera, pair, path[:1], (0, 1), visibility)[0] == places[near]
    assert best_place(camera, pair, path[:1], (0, 1), visibility, path=path) == (places[far], 1.0)  # its score unchanged
    # where the place seeing more crosses the wall by a margin over PATH_WALL_COST, it still wins
    worse = next(k for k in np.flatnonzero(~crossing & (seen < 0.7) & (seen > 0.0)))
    assert best_place(camera, [places[near], places[worse]], path[:1], (0, 1), visibility, path=path)[0] == places[near]
