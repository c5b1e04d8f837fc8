"""Shots through a player's eyes (first_person.py; issue 41, item 3): a planned kill is shown from
the killer's eyes when the victim is in its frame and unhidden at the kill, a Toric camera's
otherwise; the first-person camera is the player's eye wherever the game puts it (never pulled,
held or moved by the level), and says through whose eyes it is on the wire."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from camdirector.geometry.inside import LevelInterior
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import quat_rotate
from camdirector.pipeline.match.first_person import (
    EYE_ABOVE_FEET_M,
    EYE_HEIGHT_FRACTION,
    FirstPersonCamera,
    eyes_camera,
    through_eyes,
)
from camdirector.pipeline.match.frame import Replay, ShotChoice, ShotKind
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.look_along import look_along
from camdirector.pipeline.match.program_camera import ProgramCamera
from camdirector.pipeline.match.program_shot import Shot
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import PairWindow, StaticCamera, ToricCamera
from camdirector.pipeline.match.stand import shot_moments
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.worker.codec import shot_msg
from tests.pipeline.match.scenes import BareRig, Match, facing, kill
from tests.pipeline.match.test_match_places import block
from tests.pipeline.match.test_stand import _room_and_panel

KILL_S = 2.5
CUT_S = 0.5


def approach(t: float, a_looks_at_b: bool = True):
    """a walks toward b along +z (from z = 0 to z = 3 over 3 s), facing b or turned away from it;
    b waits at z = 8, facing a."""
    z = min(t, 3.0)
    a_yaw = facing((0, z), (0, 8)) if a_looks_at_b else facing((0, z), (0, -8))
    return {"a": ((0.0, z), a_yaw), "b": ((0.0, 8.0), facing((0, 8), (0, z)))}


def _planned_kill(players=approach, walls=(), settings: MatchSettings = MatchSettings()):
    """The shot our director builds at CUT_S for a's kill of b at KILL_S (4 s buffered)."""
    rig = BareRig(Match({"a": 1, "b": 2}, players, delay_s=4.0, walls=list(walls)), settings)
    rig.run(4.0)
    r = rig.rig
    choice = ShotChoice(("a", "b"), ShotKind.DUEL, "planned kill")
    cut = r.buffer.at(CUT_S)
    shot, _ = r.builder.build(choice, (0, 1), cut, [r.buffer.at(KILL_S)], None, None, CUT_S, None, (KILL_S,), r.buffer)
    assert shot is not None
    return rig, shot


def test_a_kill_is_shown_through_the_killers_eyes_when_it_looks_at_its_victim():
    rig, shot = _planned_kill()
    assert isinstance(shot.camera, FirstPersonCamera) and shot.camera.player == 0
    assert shot.choice.eyes_id == "a" and shot.choice.reason.endswith("through a's eyes")
    moment = rig.rig.buffer.at(KILL_S)
    pose = shot.camera.pose(moment)
    body_m = rig.rig.builder.body_heights_m[0]
    assert np.allclose(pose.position_world, moment.feet_world[0] + [0.0, EYE_HEIGHT_FRACTION * body_m, 0.0])
    # the picture names a alone away from the kill, the pair around it (the Toric pair window's rule)
    assert shot.framed(CUT_S) == (0,) and shot.framed(KILL_S) == (0, 1)


@pytest.mark.parametrize(
    "players, walls",
    [
        (lambda t: approach(t, a_looks_at_b=False), ()),  # b behind a's back at the kill
        (approach, [block((0.0, 1.5, 5.5), (6.0, 3.0, 0.3))]),  # a wall between them
    ],
)
def test_a_kill_the_killers_eyes_would_not_show_gets_a_toric_camera(players, walls):
    _, shot = _planned_kill(players, walls)
    assert isinstance(shot.camera, ToricCamera) and shot.choice.eyes_id == ""


@pytest.mark.parametrize("turns_s, eyes", [(0.05, True), (-0.05, False)], ids=["after the judged frame", "before the kill"])
def test_a_kill_is_through_the_killers_eyes_where_they_show_it_at_the_frame_eval_match_judges(turns_s, eyes):
    """a looks at b through the kill and the frame eval-match judges it at (the first at or after
    it; at 30 Hz the kill's own), then turns away 0.05 s after: the eyes show the kill. Judged a
    fixed 0.1 s after it, a had turned away there and the kill went to a Toric camera (on the real
    2on2 one that cut through walls four times in 2 s). Turned away before the kill, the Toric
    camera's as before."""
    _, shot = _planned_kill(lambda t: approach(t, a_looks_at_b=t < KILL_S + turns_s))
    assert isinstance(shot.camera, FirstPersonCamera) == eyes
    assert (shot.choice.eyes_id == "a") == eyes


@pytest.mark.parametrize(
    "settings",
    [
        MatchSettings(first_person=False),
        # b 5.5 m from a's eye at the kill fills 0.21 of its frame: too small for a floor of 0.3
        MatchSettings(eyes_shown_height_min=0.3),
    ],
)
def test_without_first_person_or_with_the_victim_too_far_to_read_a_kill_gets_a_toric_camera(settings):
    _, shot = _planned_kill(settings=settings)
    assert isinstance(shot.camera, ToricCamera) and shot.choice.eyes_id == ""


def test_a_discretionary_follow_of_one_player_is_through_its_eyes():
    rig = BareRig(Match({"a": 1, "b": 2}, approach, delay_s=4.0), MatchSettings())
    rig.run(4.0)
    r = rig.rig
    moment = r.buffer.at(CUT_S)
    shot, _ = r.builder.build(ShotChoice(("b",), ShotKind.FOLLOW, "fighter"), (1,), moment, [moment], None, None, CUT_S)
    assert isinstance(shot.camera, FirstPersonCamera) and shot.camera.player == 1 and shot.choice.eyes_id == "b"


def running_away(t: float):
    """b runs away from a along +z at 2 m/s, facing its run: a, standing at the origin, is behind b's back."""
    z = 8.0 + 2.0 * min(t, 3.5)
    return {"a": ((0.0, 0.0), facing((0, 0), (0, z))), "b": ((0.0, z), facing((0, z), (0, z + 8)))}


def _follow_of_b(walls=(), events=(), events_s=()):
    """The FOLLOW of b our director builds at CUT_S, placed for it and 1-3 s on (planned.py
    OPTION_COVER_S), with the buffer: discretionary, or planned for events at events_s, s."""
    rig = BareRig(Match({"a": 1, "b": 2}, running_away, list(events), delay_s=4.0, walls=list(walls)), MatchSettings())
    rig.run(4.0)
    r = rig.rig
    cover = [r.buffer.at(CUT_S + dt) for dt in (0.0, 1.0, 2.0, 3.0)]
    choice = ShotChoice(("b",), ShotKind.FOLLOW, "objective" if events_s else "fighter")
    shot, _ = r.builder.build(choice, (1,), cover[0], cover, None, None, CUT_S, None, tuple(events_s), r.buffer)
    assert shot is not None
    return r, shot, cover


def _panel_across_the_way(camera: ToricCamera, cover):
    """A panel across the way the Toric camera goes between 1 and 2 s on: its place would pass through it."""
    start, end = (camera.positions(m, [camera.place_at(m.time_s)])[0] for m in cover[1:3])
    assert np.linalg.norm(end - start) > 1.0  # the camera moves with b
    along = np.abs(end - start) / np.linalg.norm(end - start)
    across = np.abs(np.cross(along, [0.0, 1.0, 0.0]))
    return block((start + end) / 2.0, across / np.linalg.norm(across) * 2.0 + along * 0.1 + [0.0, 4.0, 0.0])


@pytest.mark.parametrize("events_s", [(), (3.0,)], ids=["discretionary", "planned for b's objective"])
def test_a_follow_whose_eyes_show_nobody_is_its_toric_cameras_where_that_meets_no_wall_else_the_eyes(events_s):
    """A planned shot of one player (an objective taken, a suicide) as a discretionary FOLLOW:
    through its eyes the viewer would not see who takes the objective."""
    _, shot, cover = _follow_of_b(events_s=events_s)
    assert isinstance(shot.camera, ToricCamera) and shot.choice.eyes_id == ""  # b's eyes show nobody; open ground
    _, walled, _ = _follow_of_b([_panel_across_the_way(shot.camera, cover)], events_s=events_s)
    assert isinstance(walled.camera, FirstPersonCamera) and walled.camera.player == 1 and walled.choice.eyes_id == "b"


def test_a_follow_whose_player_kills_in_the_buffered_future_stays_in_its_eyes():
    """Its planned shot of the kill will likely be through the same eyes: the picture goes on uncut (rig.py)."""
    _, shot, _ = _follow_of_b(events=[kill("b", "a", 3.5)])
    assert isinstance(shot.camera, FirstPersonCamera) and shot.camera.player == 1


@pytest.mark.parametrize(
    "players, eyes",
    [
        (approach, True),  # b in front of a at the cut and 1-3 s on
        (lambda t: approach(t, a_looks_at_b=t < 2.0), False),  # a turns its back on b 1.5 s after the cut
    ],
)
def test_a_discretionary_fight_is_through_the_eyes_that_show_the_other_at_every_moment_it_is_placed_for(players, eyes):
    rig = BareRig(Match({"a": 1, "b": 2}, players, delay_s=4.0), MatchSettings())
    rig.run(4.0)
    r = rig.rig
    cover = [r.buffer.at(CUT_S + dt) for dt in (0.0, 1.0, 2.0, 3.0)]  # planned.py OPTION_COVER_S
    shot, _ = r.builder.build(ShotChoice(("a", "b"), ShotKind.DUEL, "fight"), (0, 1), cover[0], cover, None, None, CUT_S)
    assert shot is not None
    if eyes:
        assert isinstance(shot.camera, FirstPersonCamera) and shot.camera.player == 0 and shot.choice.eyes_id == "a"
    else:
        assert isinstance(shot.camera, ToricCamera) and shot.choice.eyes_id == ""


def test_a_first_person_camera_goes_where_its_player_goes_through_walls_and_all():
    """A Toric camera's 6 m move through a wall is held when a cut would be short (test_stand.py);
    an eye is where the game put it: never pulled in, held or moved inside, so a teleport is a cut
    (the rig's sweep through a wall), not a held picture."""
    level = _room_and_panel(block((0.0, 2.0, 9.0), (12.0, 8.0, 0.3)))
    rig = BareRig(Match({"a": 1, "b": 2}, approach, delay_s=4.0, walls=[level]), MatchSettings())
    rig.run(4.0)
    r = rig.rig
    moment = r.buffer.at(KILL_S)
    in_level = InLevel(LevelInterior(level), np.zeros((0, 3)), MatchSettings().pull_margin_m)
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    camera = eyes_camera(0, float(r.builder.body_heights_m[0]), r.lens, r.settings)
    _, shot = _planned_kill()
    eye = camera.pose(moment)
    last = look_along(eye.position_world + [0.0, 0.0, 12.0], [0.0, 0.0, -1.0], 50.0)  # across the wall
    assert in_level.crossed(last.position_world, eye.position_world)
    for cut_short in (False, True):
        pose, flags = program.step(moment, 1 / 30, camera, shot, 0.5, last, cut_short)
        assert flags == [] and np.array_equal(pose.position_world, eye.position_world)
        assert np.array_equal(pose.rotation_xyzw, eye.rotation_xyzw)


def test_the_eye_stands_at_quakes_height_over_the_body_and_looks_along_its_facing():
    settings = MatchSettings()
    rig = BareRig(Match({"a": 1, "b": 2}, approach, delay_s=0.0), settings)
    rig.run(1.0)
    moment = rig.rig.buffer.moments[-1]
    camera = eyes_camera(0, 1.75, rig.rig.lens, settings)
    assert camera.eye_above_feet_m == pytest.approx(EYE_ABOVE_FEET_M)  # a 1.75-m player is Quake's
    assert camera.lens.vertical_fov_deg == settings.eyes_fov_deg and camera.lens.aspect == rig.rig.lens.aspect
    pose = camera.pose(moment)
    forward = quat_rotate(pose.rotation_xyzw, np.array([0.0, 0.0, -1.0]))  # a camera looks down its -z
    assert math.isclose(forward[1], 0.0, abs_tol=1e-9)  # the horizon level
    assert np.allclose(forward, moment.forward_world[0], atol=1e-9)


def test_a_dead_players_eye_looks_at_its_living_killer_and_the_games_own_view_along_its_body():
    """Our director's eye of a corpse (eyes_camera) turns to its killer, level and from the
    corpse's eye, while the killer lives; the autotrack's (FirstPersonCamera's default) keeps the
    body's facing, as the game shows it; a suicide, or a killer dead too, leaves the facing."""
    rig = BareRig(Match({"a": 1, "b": 2}, turning_away, [kill("b", "a", KILL_S)], delay_s=0.0), MatchSettings())
    rig.run(KILL_S + 0.5)
    dead = rig.rig.buffer.moments[-1]
    assert not dead.alive[0] and dead.killers is not None and dead.killers.tolist() == [1, -1]
    ours = eyes_camera(0, 1.75, rig.rig.lens, rig.rig.settings)
    games = FirstPersonCamera(0, ours.lens, ours.eye_above_feet_m, ours.corpse_eye_above_feet_m)

    def forward(camera: FirstPersonCamera, moment) -> np.ndarray:
        return quat_rotate(camera.pose(moment).rotation_xyzw, np.array([0.0, 0.0, -1.0]))

    eye = ours.pose(dead).position_world
    assert eye[1] == pytest.approx(dead.feet_world[0, 1] + ours.corpse_eye_above_feet_m)
    at_killer = (dead.aims_world[1] - eye) / np.linalg.norm(dead.aims_world[1] - eye)
    np.testing.assert_allclose(forward(ours, dead), at_killer, atol=1e-9)
    np.testing.assert_allclose(forward(games, dead), dead.forward_world[0], atol=1e-9)  # a turns away from b: not at b
    assert forward(games, dead) @ at_killer < 0.0
    for killers, alive in (([-1, -1], [False, True]), ([1, -1], [False, False])):  # a suicide; the killer dead too
        other = dataclasses.replace(dead, killers=np.array(killers), alive=np.array(alive))
        np.testing.assert_allclose(forward(ours, other), dead.forward_world[0], atol=1e-9)


def test_the_wire_names_the_player_through_whose_eyes_the_picture_is():
    _, shot = _planned_kill()
    assert shot_msg(shot.choice).eyes_id == "a"
    assert shot_msg(ShotChoice(("a",), ShotKind.FOLLOW, "toric")).eyes_id == ""


@pytest.mark.parametrize("fov_deg, seen", [(1.0, 0.5), (170.0, 0.5), (73.74, -0.1), (73.74, 1.1), (math.nan, 0.5)])
def test_first_person_settings_out_of_their_limits_are_refused(fov_deg, seen):
    with pytest.raises(ValueError, match="eyes_"):
        MatchSettings(eyes_fov_deg=fov_deg, eyes_seen=seen)


def test_two_kills_by_one_player_seen_through_its_eyes_are_one_shot():
    """a kills b, then c 4 s later, both in front of it (d and e face off far away before): the
    second kill's shot is through a's eyes as the first's, so the program goes on with the same
    picture, uncut; the shot names each kill's pair around it."""
    first_s, second_s = 15.0, 19.0

    def players(t: float):
        return {
            "a": ((0.0, 0.0), 0.0 if t >= first_s - 3.0 else math.pi),  # turns to face b and c 3 s before
            "b": ((-1.0, 8.0), math.pi),  # turned away: no fight until a turns
            "c": ((1.5, 10.0), math.pi),
            "d": ((40.0, 0.0), facing((40, 0), (40, 6))),
            "e": ((40.0, 6.0), facing((40, 6), (40, 0))),
        }

    events = [kill("a", "b", first_s), kill("a", "c", second_s)]
    teams = {"a": 1, "b": 2, "c": 2, "d": 1, "e": 2}
    states = BareRig(Match(teams, players, events, delay_s=10.0), MatchSettings()).run(30.0)
    shown = [s for s in states if not s.match.buffering and first_s - 0.5 <= s.time_s <= second_s + 0.2]
    assert all(s.match.shot.eyes_id == "a" for s in shown)
    assert not any(s.cut for s in shown)
    assert "same_eyes_no_cut" in {f for s in shown for f in s.flags}
    at = {round(s.time_s, 2): s for s in shown}
    assert set(at[first_s].match.shot.subject_ids) == {"a", "b"} and set(at[second_s].match.shot.subject_ids) == {"a", "c"}


def turning_away(t: float):
    """approach, but a turns its back on b from 0.3 s before the kill (KILL_S) on."""
    return approach(t, a_looks_at_b=t < KILL_S - 0.3)


def _turning_away_with_walls(hide_the_kill_from_the_toric_place: bool):
    """turning_away's kill, its DUEL's Toric camera, and a visibility with a thin panel across that
    camera's longest step between two of the shot's moments (a cut within the shot), and another
    between the camera's place at the kill and b where asked; with a check that a still sees b
    past them 0.5 s before the kill."""
    settings = MatchSettings()
    rig = BareRig(Match({"a": 1, "b": 2}, turning_away, delay_s=4.0), settings)
    rig.run(4.0)
    r = rig.rig
    cut = r.buffer.at(CUT_S)
    toric = r.builder.cameras(ShotKind.DUEL, (0, 1), cut, default=True)[0][0]
    toric.pair = PairWindow(0, (KILL_S,), settings.pair_before_s, settings.pair_after_s, settings.reframe_s)
    moments, _ = shot_moments(toric, r.buffer, CUT_S, (KILL_S,), settings)
    path = np.array([toric.positions(m, [toric.place_at(m.time_s)])[0] for m in sorted(moments, key=lambda m: m.time_s)])
    step = int(np.argmax(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    axis = int(np.argmax(np.abs(path[step + 1] - path[step])))
    size = np.full(3, 1.0)
    size[axis] = 0.1
    panels = [block(0.5 * (path[step] + path[step + 1]), size)]
    at_kill = r.buffer.at(KILL_S)
    if hide_the_kill_from_the_toric_place:
        place = toric.positions(at_kill, [toric.place_at(KILL_S)])[0]
        panels.append(block(place + 0.3 * (at_kill.aims_world[1] - place), np.full(3, 0.6)))
    walled = SubjectVisibility(
        RayScene(panels), [t.mesh for t in rig.scene.targets], settings.samples_per_player, np.random.default_rng(0)
    )
    lead = r.buffer.at(KILL_S - 0.5)
    assert not walled.ray_scene.occluded(lead.aims_world[0], lead.aims_world[1][None])[0]  # a still sees b past them

    def eyes(visibility, s=settings):
        return through_eyes(toric, (0, 1), r.buffer, cut, (KILL_S,), visibility, r.builder.body_heights_m, s)

    return eyes, r.visibility, walled


def test_where_its_toric_camera_would_meet_a_wall_a_kill_seen_just_before_goes_through_the_eyes():
    """From a's eyes b is not in the frame at the kill (a turned away), so the kill alone does not
    take them; but a wall across the Toric camera's way (a cut within the shot) does, as long as
    a saw b within eyes_lead_s before it and the Toric camera's place does not see the kill either."""
    eyes, open_level, walled = _turning_away_with_walls(hide_the_kill_from_the_toric_place=True)
    assert eyes(open_level) is None  # no wall: its Toric camera shows the kill
    camera = eyes(walled)
    assert isinstance(camera, FirstPersonCamera) and camera.player == 0
    assert eyes(walled, dataclasses.replace(MatchSettings(), eyes_lead_s=0.0)) is None  # it is the lead that admits it


def test_a_kill_the_eyes_do_not_see_and_the_toric_place_does_is_the_toric_cameras_walls_and_all():
    """The same wall across the Toric camera's way, but from its place at the kill the pair is in
    view: the eyes, turned away at the kill, would miss it (the real 2on2 missed 5 kills so)."""
    eyes, _, walled = _turning_away_with_walls(hide_the_kill_from_the_toric_place=False)
    assert eyes(walled) is None


def test_an_eye_inside_solid_is_not_shown_the_last_picture_stays():
    """A demo interpolates a teleport's frames through a wall: an eye inside solid is never the
    program's pose (issue 41: none in solid); the last one stays until the eye is out."""
    rig = BareRig(Match({"a": 1, "b": 2}, approach, delay_s=4.0), MatchSettings())
    rig.run(4.0)
    r = rig.rig
    moment = r.buffer.at(KILL_S)
    camera = eyes_camera(0, float(r.builder.body_heights_m[0]), r.lens, r.settings)
    eye = camera.pose(moment)
    level = _room_and_panel(block(eye.position_world, (1.0, 1.0, 1.0)))  # a solid block round a's eye
    in_level = InLevel(LevelInterior(level), np.zeros((0, 3)), MatchSettings().pull_margin_m)
    assert not in_level.inside(eye.position_world)
    program = ProgramCamera(r.settings, r.visibility, r.ray_scene, r.lens, in_level, r.builder.grammar, lambda time_s: None)
    _, shot = _planned_kill()
    last = look_along(eye.position_world - [0.0, 0.0, 2.0], [0.0, 0.0, 1.0], 50.0)
    pose, flags = program.step(moment, 1 / 30, camera, shot, 0.5, last)
    assert pose is last and flags == ["eye_outside_level_held"]


@pytest.mark.parametrize("previous_world, eyes", [((0.0, 1.6, -3.0), False), ((6.0, 1.6, 4.0), True)])
def test_a_cut_to_the_eyes_keeps_the_30_degree_rule(previous_world, eyes):
    """Cutting within the pair's window (both framed), from over a's shoulder a's eyes look at the
    pair from nearly the same side: a jump cut, so the kill gets a Toric camera; from beside the
    pair, the eyes are a new view."""
    rig = BareRig(Match({"a": 1, "b": 2}, approach, delay_s=4.0), MatchSettings())
    rig.run(4.0)
    r = rig.rig
    cut_s = KILL_S - 0.5
    cut = r.buffer.at(cut_s)
    assert np.allclose(cut.feet_world[0][[0, 2]], [0.0, cut_s], atol=0.05)  # a walks up +z toward b: behind it is -z
    centre = cut.aims_world.mean(axis=0)
    previous_pose = look_along(np.array(previous_world), centre - previous_world, 50.0)
    previous = Shot(ShotChoice(("a", "b"), ShotKind.DUEL, "before"), (0, 1), StaticCamera(previous_pose), 0.0)
    choice = ShotChoice(("a", "b"), ShotKind.DUEL, "planned kill")
    shot, _ = r.builder.build(
        choice, (0, 1), cut, [r.buffer.at(KILL_S)], previous, previous_pose, cut_s, None, (KILL_S,), r.buffer
    )
    assert shot is not None and shot.framed(cut_s) == (0, 1)
    assert isinstance(shot.camera, FirstPersonCamera) == eyes


def test_a_replay_through_the_eyes_on_air_is_a_cut_in_time():
    """The program goes on uncut into a new shot through the eyes on air (the same picture), but not
    into or out of a replay through them: its picture is of another moment (the real 2on2 jumped
    7.8 m uncut into one)."""
    rig, shot = _planned_kill()
    r = rig.rig
    r.shot = shot
    again = dataclasses.replace(shot, choice=dataclasses.replace(shot.choice, reason="chosen again"))
    replay = dataclasses.replace(shot, choice=dataclasses.replace(shot.choice, replay=Replay(KILL_S, KILL_S - 2.0, KILL_S + 1.0)))
    assert r._same_eyes(again) and not r._same_eyes(replay)
    r.shot = replay
    assert not r._same_eyes(shot)


def test_a_fight_held_through_one_players_eyes_is_not_chosen_again_at_every_tick():
    """a and b face off 6 m apart for 30 s (near enough that b reads in a's eyes: a FOLLOW of a is
    through them): the director's max-shot-length cut finds the same eyes best, and the picture
    goes on; its clock restarts with each choice (rig.py), so the choice is made once per
    max_shot_s, not at every planning tick (160 of 781 frames before)."""

    def face_off(t: float):
        return {"a": ((0.0, 0.0), facing((0, 0), (0, 6))), "b": ((0.0, 6.0), facing((0, 6), (0, 0)))}

    states = BareRig(Match({"a": 1, "b": 2}, face_off, delay_s=4.0), MatchSettings()).run(30.0)
    shown = [s for s in states if not s.match.buffering]
    assert all(s.match.shot.eyes_id == "a" for s in shown) and sum(s.cut for s in shown) == 1
    chosen_again = sum("same_eyes_no_cut" in s.flags for s in shown)
    assert 1 <= chosen_again <= 30.0 / 4.0  # no more often than every 4 s (the style's max_shot_s is 8)
