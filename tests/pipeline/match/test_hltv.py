"""The HLTV baseline against Valve's SourceTV director (hltvdirector.cpp, hltvcamera.cpp): the best
player followed at rank 0, only the heard events with the SDK's priorities, fixed cameras that turn,
a dead first-person target seen from the chase view, and the rank's and the chase camera's traces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform, matrix_to_quat, quat_to_matrix
from camdirector.pipeline.inputs import EventKind, GameEvent
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.hltv import ChaseCamera, ChaseParams, FixedCamera, HltvDirector, smooth_angles
from camdirector.pipeline.match.moments import Moment, horizontal_forward
from camdirector.pipeline.match.settings import INCH_M, HltvSettings, MatchSettings
from camdirector.pipeline.style import Rig, Style
from tests.pipeline.match.scenes import EYE_M, BareRig, Match, at_time, facing, kill, shots

HLTV = Style(rig=Rig.MATCH, match_director="hltv")
TEAMS = {"a1": 1, "b1": 2, "a2": 1, "b2": 2}
EVENT_S = 20.0


def wall(centre, size) -> TriMesh:
    mesh = box(size)
    return TriMesh(mesh.vertices + np.asarray(centre, dtype=float), mesh.faces)


def view_quat(forward) -> np.ndarray:
    """xyzw rotation turning local +Z onto forward (3,), local +Y up-ish (no roll)."""
    z = np.asarray(forward, dtype=float) / np.linalg.norm(forward)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    return matrix_to_quat(np.stack([x, np.cross(z, x), z], axis=1))


def moment(feet, forwards, alive=None) -> Moment:
    """One hand-built moment: players' feet (n, 3) m and 3-D view directions (n, 3)."""
    feet = np.asarray(feet, dtype=float)
    rotations = np.array([view_quat(f) for f in forwards])
    transforms = [RigidTransform(p, q) for p, q in zip(feet, rotations)]
    alive = np.ones(len(feet), dtype=bool) if alive is None else np.asarray(alive)
    return Moment(0, 0.0, transforms, feet + [0.0, EYE_M, 0.0], feet, horizontal_forward(rotations), alive)


def director(n: int, walls=(), settings: MatchSettings = MatchSettings()) -> HltvDirector:
    return HltvDirector(
        [f"p{i}" for i in range(n)], settings, Lens(), RayScene(list(walls)), np.random.default_rng(0), 10.0, np.zeros((0, 3))
    )


def forward_of(pose) -> np.ndarray:
    return -quat_to_matrix(pose.rotation_xyzw)[:, 2]


def angle_deg(u, v) -> float:
    return math.degrees(math.acos(np.clip(np.dot(u, v) / np.linalg.norm(u) / np.linalg.norm(v), -1.0, 1.0)))


# -- 1. StartBestPlayerCameraShot: the best player from -1, so rank 0 is followed ---------------
def test_players_far_apart_are_still_followed_and_nobody_alive_gives_a_fixed_camera():
    def far_apart(t):  # 40 m apart (over 1024 units: they never rank each other), looking away
        return {"a": ((0.0, 0.0), 0.0), "b": ((40.0, 0.0), 0.0)}

    settings = MatchSettings(hltv=HltvSettings(fixed_camera_share=0.0))
    states = BareRig(Match({"a": 1, "b": 2}, far_apart, [], delay_s=10.0, style=HLTV), settings).run(30.0)
    program = shots(states)
    assert len(program) >= 3
    for _, _, first in program:
        shot = first.match.shot
        assert shot.kind == ShotKind.FOLLOW and "best-ranked player" in shot.reason
        x = 0.0 if shot.subject_ids == ("a",) else 40.0
        eye = np.array([x, EYE_M, 0.0])
        assert np.linalg.norm(first.pose.position_world - eye) == pytest.approx(112 * INCH_M, rel=1e-3)
        assert first.pose.position_world[2] < 0.0 and first.pose.position_world[1] > EYE_M  # over the shoulder

    # with nobody alive, the best fixed camera (forced)
    world_kills = [GameEvent(EventKind.KILL, "", p, 0, 1.0, "kill") for p in ("a", "b")]
    states = BareRig(Match({"a": 1, "b": 2}, far_apart, world_kills, delay_s=10.0, style=HLTV), settings).run(30.0)
    later = at_time(states, 8.0).match.shot
    assert later.kind == ShotKind.OVERVIEW and "nobody alive" in later.reason


# -- 2. and 3. only the heard events, with the SDK's priorities ---------------------------------
def standing(t):
    """a1 and b1 face each other 8 m apart; a2 and b2 likewise, 30 m away."""
    return {
        "a1": ((0.0, 0.0), facing((0, 0), (0, 8))),
        "b1": ((0.0, 8.0), facing((0, 8), (0, 0))),
        "a2": ((30.0, 0.0), facing((30, 0), (30, 8))),
        "b2": ((30.0, 8.0), facing((30, 8), (30, 0))),
    }


def event_shot(events) -> tuple[str, tuple[str, ...], list[str]]:
    states = BareRig(Match(TEAMS, standing, events, delay_s=10.0, style=HLTV), MatchSettings()).run(EVENT_S + 13.0)
    shot = at_time(states, EVENT_S).match.shot
    return shot.reason, shot.subject_ids, [f for s in states for f in s.flags]


def test_an_unheard_kind_never_draws_the_shot_however_high_its_priority():
    custom = GameEvent(EventKind.CUSTOM, "a2", "b2", 15, EVENT_S, "custom")
    damage = GameEvent(EventKind.DAMAGE, "a1", "b1", 0, EVENT_S, "hurt")
    reason, subjects, flags = event_shot([custom, damage])
    assert reason.startswith("hltv: damage") and set(subjects) == {"a1", "b1"}
    assert "hltv_no_shot_for_event" not in flags
    reason, _, flags = event_shot([custom])
    assert "custom" not in reason and "hltv_no_shot_for_event" not in flags


def test_damage_has_the_sdk_priority_5_and_a_client_priority_is_kept():
    damage = GameEvent(EventKind.DAMAGE, "a1", "b1", 0, EVENT_S, "hurt")
    kill_at_4 = GameEvent(EventKind.KILL, "a2", "b2", 4, EVENT_S, "kill")  # the client's 4 beats no default
    reason, subjects, _ = event_shot([damage, kill_at_4])
    assert reason.startswith("hltv: damage") and set(subjects) == {"a1", "b1"}
    kill_at_6 = GameEvent(EventKind.KILL, "a2", "b2", 6, EVENT_S, "kill")
    reason, subjects, _ = event_shot([damage, kill_at_6])
    assert reason.startswith("hltv: kill") and set(subjects) == {"a2", "b2"}
    assert MatchSettings().priorities[EventKind.DAMAGE] == 3  # our planner's table is not the baseline's


def test_hltv_settings_refuse_bad_priorities_and_hulls():
    with pytest.raises(ValueError, match="priorities"):
        HltvSettings(priorities={EventKind.KILL: 20})
    with pytest.raises(ValueError, match="wall_hull_half_m"):
        HltvSettings(wall_hull_half_m=2.0)


# -- 4. a fixed camera turns toward its target every frame --------------------------------------
def test_a_fixed_camera_turns_toward_its_walking_target_and_holds_when_it_dies():
    def walk(t):  # p walks along +x at 2 m/s until killed at 3 s; q was killed at the start
        return {"p": ((2.0 * min(t, 3.0), 0.0), math.pi / 2), "q": ((0.0, 10.0), 0.0)}

    events = [kill("p", "q", 0.0), GameEvent(EventKind.KILL, "", "p", 0, 3.0, "kill")]
    settings = MatchSettings(hltv=HltvSettings(fixed_camera_share=1.0))
    states = BareRig(Match({"p": 1, "q": 2}, walk, events, delay_s=0.0, style=HLTV), settings).run(5.9)
    assert not any(s.cut for s in states[1:])
    assert states[0].match.shot.kind == ShotKind.OVERVIEW and states[0].match.shot.subject_ids == ("p",)
    positions = np.array([s.pose.position_world for s in states])
    assert np.allclose(positions, positions[0])
    alive = [s for s in states if s.time_s < 3.0]
    assert angle_deg(forward_of(alive[0].pose), forward_of(alive[-1].pose)) > 20.0  # it turned
    for s in alive[30:]:  # smoothed, it trails its target, by far less than a camera that did not turn
        eye = np.array([2.0 * s.time_s, EYE_M, 0.0])
        lag = angle_deg(forward_of(s.pose), eye - positions[0])
        assert lag < 20.0 and lag < 0.5 * angle_deg(forward_of(alive[0].pose), eye - positions[0])
        assert abs(quat_to_matrix(s.pose.rotation_xyzw)[1, 0]) < 1e-9  # no roll: the right vector is level
    dead = [s for s in states if s.time_s > 3.1]
    assert all(np.allclose(forward_of(s.pose), forward_of(dead[0].pose)) for s in dead)


def test_fixed_camera_smooths_its_turn_by_three_per_second():
    camera = FixedCamera(np.zeros(3), 0, np.array([0.0, 0.0, 10.0]), Lens(), HltvSettings())
    scene = moment([[0.0, -EYE_M, 10.0]], [[0.0, 0.0, 1.0]])
    camera.advance(scene, 0.0, 0.0)
    assert camera.angles == pytest.approx((0.0, 0.0))
    scene.aims_world[0] = [10.0, 0.0, 0.0]  # the target now 90 degrees to the side
    camera.advance(scene, 0.1, 0.0)
    assert camera.angles == pytest.approx((27.0, 0.0))  # 0.1 s * 3 / s of the 90-degree gap
    assert smooth_angles((170.0, 0.0), (-170.0, 10.0), 0.1, 3.0) == pytest.approx((176.0, 3.0))  # the short way


# -- 5. first person of a target that dies becomes the chase view ------------------------------
def test_first_person_of_a_victim_that_dies_becomes_the_chase_view():
    def duel(t):
        return {
            "a1": ((0.0, 0.0), 0.0),
            "b1": ((30.0, 0.0), 0.0),
            "a2": ((40.0, 0.0), facing((40, 0), (40, 15))),
            "b2": ((40.0, 15.0), facing((40, 15), (40, 0))),
        }

    hltv = HltvSettings(in_eye_kill_chance=1.0, swap_chance_in_eye=0.0)  # always the victim's eyes
    match = Match(TEAMS, duel, [kill("a2", "b2", EVENT_S)], delay_s=10.0, style=HLTV)
    states = BareRig(match, MatchSettings(hltv=hltv)).run(EVENT_S + 13.0)  # the program runs 10 s behind
    before, after = at_time(states, EVENT_S - 0.2), at_time(states, EVENT_S + 1.0)
    assert "first person of b2" in before.match.shot.reason and after.match.shot == before.match.shot
    assert np.allclose(before.pose.position_world, [40.0, EYE_M, 15.0])
    dead_eye = np.array([40.0, 14 * INCH_M, 15.0])
    camera = after.pose.position_world
    assert np.linalg.norm(camera - dead_eye) == pytest.approx(96 * INCH_M, rel=1e-3)
    assert camera[2] > dead_eye[2] and camera[1] > dead_eye[1]  # behind the body, from above (pitch offset 15)


# -- 6. the rank's traces and facing, the chase camera's hull ----------------------------------
def test_rank_traces_go_feet_to_feet_and_other_players_block_them():
    toward, away = [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]
    open_pair = director(2).rank_players(moment([[0, 0, 0], [0, 0, 10]], [toward, away]))
    assert open_pair[0][0] > 0.0 and open_pair[1][0] == 1
    low_wall = wall([0.0, 0.5, 5.0], (4.0, 1.0, 0.2))  # hides the feet, not the eyes
    rank, target = director(2, [low_wall]).rank_players(moment([[0, 0, 0], [0, 0, 10]], [toward, away]))
    assert rank[0] == 0.0 and target[0] == -1
    between = moment([[0, 0, 0], [0, 0, 10], [0, 0, 5]], [toward, away, [1.0, 0.0, 0.0]])
    rank, target = director(3).rank_players(between)
    assert target[0] == 2 and target[1] == 2  # each sees the one between, not the other
    between.alive[2] = False  # a dead player is not solid
    rank, target = director(3).rank_players(between)
    assert target[0] == 1


def test_rank_uses_the_facing_in_three_dimensions():
    level = director(2).rank_players(moment([[0, 0, 0], [0, 0, 10]], [[0, 0, 1], [0, 0, -1]]))[0][0]
    down = [0.0, -math.sin(math.radians(60)), math.cos(math.radians(60))]
    looking_down = director(2).rank_players(moment([[0, 0, 0], [0, 0, 10]], [down, [0, 0, -1]]))[0][0]
    assert looking_down < 0.8 * level


def chase_distance(walls, feet, alive=None) -> float:
    scene = moment(feet, [[0.0, 0.0, 1.0]] * len(feet), alive)
    camera = ChaseCamera(
        ShotKind.FOLLOW, 0, None, ChaseParams(96 * INCH_M, 0.0, 0.0, False), Lens(), RayScene(list(walls)), MatchSettings()
    )
    camera.advance(scene, 0.0, 0.0)
    return float(np.linalg.norm(camera.pose(scene).position_world - scene.aims_world[0]))


def test_the_chase_camera_sweeps_a_six_unit_box_back_from_the_eye():
    assert chase_distance([], [[0, 0, 0]]) == pytest.approx(96 * INCH_M)
    back_wall = wall([0.0, 1.0, -1.6], (6.0, 6.0, 0.2))  # its face 1.5 m behind the eye
    assert chase_distance([back_wall], [[0, 0, 0]]) == pytest.approx(1.5 - 6 * INCH_M, abs=1e-3)
    post = wall([0.17, EYE_M, -1.5], (0.1, 6.0, 0.1))  # its edge 0.12 m beside the line: the ray misses it
    assert chase_distance([post], [[0, 0, 0]]) == pytest.approx(1.45 - 6 * INCH_M, abs=1e-3)
    # another living player 1.5 m behind: its hull grown by the box; dead, it is not solid
    behind = [[0, 0, 0], [0, 0, -1.5]]
    assert chase_distance([], behind) == pytest.approx(1.5 - 16 * INCH_M - 6 * INCH_M, abs=1e-3)
    assert chase_distance([], behind, alive=[True, False]) == pytest.approx(96 * INCH_M)
