"""Instant replays (replays.py) on tiny hand-built matches: a kill with room is shown again from
another angle at the replayed moments while the program's own time goes on, kills close together
get none between them, a replay never covers a live kill, the candidate and the take of a REPLAY,
the kill cam (a replay through the killer's eyes), a replay moved past a teleport in its build-up,
and the same program on two runs."""

from __future__ import annotations

import types

import numpy as np

from camdirector.geometry.camera import project_to_screen
from camdirector.geometry.meshes import TriMesh, box
from camdirector.pipeline.match.camera_ahead import CameraStep
from camdirector.pipeline.match.first_person import FirstPersonCamera
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.grammar import view_turn_deg
from camdirector.pipeline.match.replays import AFTER_KILL_S, Replays
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import ToricCamera
from camdirector.pipeline.session import Session
from camdirector.pipeline.state import FrameState
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
)

TEAMS = {"a1": 1, "b1": 2, "a2": 1, "b2": 2}
KILL_S = 25.0
WALK_M_S = 0.2  # a2 walks along x: the replayed moment's positions differ from the live one's


def two_fronts(t: float):
    """a1 and b1 face each other 8 m apart; a2 walks slowly 15 m from b2 (it kills b2 at KILL_S)."""
    return {
        "a1": ((0.0, 0.0), facing((0, 0), (0, 8))),
        "b1": ((0.0, 8.0), facing((0, 8), (0, 0))),
        "a2": ((40.0 + WALK_M_S * t, 0.0), 0.0),
        "b2": ((40.0, 15.0), 0.0),
    }


def run_with_views(match: Match, duration_s: float) -> tuple[Session, list[FrameState], list[np.ndarray]]:
    """The session's answers and, per answer, a2's position where the monitors see it (view_target_transforms)."""
    session = Session("s", match.scene())
    states, a2 = [], []
    for update in match.frames(duration_s):
        states.append(session.frame(update))
        a2.append(session.view_target_transforms()[2].position_world.copy())
    return session, states, a2


def replays(states: list[FrameState]) -> list[list[FrameState]]:
    """The program's REPLAY shots, each as its states in order."""
    out: list[list[FrameState]] = []
    for s in states:
        if s.match.buffering or s.match.shot is None or s.match.shot.kind != ShotKind.REPLAY:
            continue
        if not out or s.cut or out[-1][-1].frame != s.frame - 1:
            out.append([])
        out[-1].append(s)
    return out


def test_a_kill_with_room_is_replayed_from_another_angle_at_the_replayed_moments():
    settings = MatchSettings()
    match = Match(TEAMS, two_fronts, [kill("a2", "b2", KILL_S)], delay_s=10.0)
    _, states, a2 = run_with_views(match, 40.0)
    shown = replays(states)
    assert len(shown) == 1
    replay = shown[0]
    first = replay[0]
    assert first.cut and first.match.shot.replay.kill_time_s == KILL_S
    # a place sees both over the build-up (open ground): it frames and names the pair throughout
    assert all(s.match.shot.subject_ids == ("a2", "b2") and s.match.shot.kind == ShotKind.REPLAY for s in replay)
    # after the live shot held its kill and followed the survivor a moment, and before the next could come
    assert KILL_S + settings.replay_after_s <= first.time_s <= KILL_S + settings.replay_within_s
    assert at_time(states, KILL_S).match.shot.kind == ShotKind.DUEL  # the kill itself was live
    # the program's own time goes on frame by frame; the picture shows the kill's moments again
    frames = [s.frame for s in replay]
    assert frames == list(range(frames[0], frames[0] + len(frames)))
    replayed = np.array([s.match.replay_of.time_s for s in replay])
    assert abs(replayed[0] - (KILL_S - settings.replay_pre_s)) <= 1.0 / 30 + 1e-9
    assert np.all(np.diff(replayed) > 0) and replayed[-1] >= KILL_S + settings.replay_post_s - 1.0 / 30 - 1e-9
    assert abs(len(replay) / 30.0 - settings.replay_length_s) <= 0.15  # its length, to a planning tick
    # the monitors see the replayed moment's players, not the live one's
    index = [i for i, s in enumerate(states) if s in replay]
    for i, s in zip(index, replay):
        assert abs(a2[i][0] - (40.0 + WALK_M_S * s.match.replay_of.time_s)) < 1e-9
    # at the replayed kill both are on screen, from a view turned past the 30-degree rule from the live one
    at_kill = min(replay, key=lambda s: abs(s.match.replay_of.time_s - KILL_S))
    aims = np.array([[40.0 + WALK_M_S * KILL_S, EYE_M, 0.0], [40.0, EYE_M, 15.0]])
    assert np.all(np.abs(on_screen(at_kill, aims)) <= 1.0) and at_kill.visibility > 0.5
    live = at_time(states, KILL_S).pose.position_world
    assert view_turn_deg(live, at_kill.pose.position_world, aims.mean(axis=0))[0] >= settings.jump_cut_deg
    # and the program is live again after it
    after = states[states.index(replay[-1]) + 1]
    assert after.cut and after.match.shot.kind != ShotKind.REPLAY and after.match.replay_of is None


HUT_Z_M = 12.0  # the centre of a closed 3 m hut that hides b2 from every place until it steps out
HUT_OUT_S = (KILL_S - 0.9, KILL_S - 0.6)  # b2 walks out of it over these times, s


def from_the_hut(t: float):
    """two_fronts, but a2 stands still facing b2's hut, and b2 is inside it through the kill's
    build-up, stepping out 2.5 m toward a2 just before the kill."""
    out = min(max((t - HUT_OUT_S[0]) / (HUT_OUT_S[1] - HUT_OUT_S[0]), 0.0), 1.0)
    return two_fronts(t) | {
        "a2": ((40.0, 0.0), facing((40, 0), (40, HUT_Z_M))),
        "b2": ((40.0, HUT_Z_M - 2.5 * out), facing((40, HUT_Z_M), (40, 0))),
    }


def test_a_kill_whose_victim_is_hidden_in_the_build_up_is_replayed_with_the_killer_alone_before_it():
    """No place sees b2 in the build-up (the hut is closed), so no place sees the pair throughout
    with min_visible; framed as the live DUEL, the killer alone before the kill, one does: the
    replay names and shows a2 alone in the build-up, both at the replayed kill."""
    hut = TriMesh(box((3.0, 3.0, 3.0)).vertices + np.array([40.0, 1.5, HUT_Z_M]), box((3.0, 3.0, 3.0)).faces)
    match = Match(TEAMS, from_the_hut, [kill("a2", "b2", KILL_S)], delay_s=10.0, walls=[hut])
    _, states = run_session(match, 40.0)
    shown = replays(states)
    assert len(shown) == 1 and shown[0][0].match.shot.replay.kill_time_s == KILL_S
    build_up = [s for s in shown[0] if s.match.replay_of.time_s < HUT_OUT_S[0]]
    assert build_up and all(s.match.shot.subject_ids == ("a2",) and s.visibility >= 0.75 for s in build_up)
    at_kill = min(shown[0], key=lambda s: abs(s.match.replay_of.time_s - KILL_S))
    aims = np.array([[40.0, EYE_M, 0.0], [40.0, EYE_M, HUT_Z_M - 2.5]])
    assert at_kill.match.shot.subject_ids == ("a2", "b2") and np.all(np.abs(on_screen(at_kill, aims)) <= 1.0)


TELEPORT_S = KILL_S - 1.1  # a2 is back from behind the wall then, 1.1 s before its kill
# walls 200 m wide and 100 m tall, clear of a1 and b1: no camera sees over or round them
SOUTH_WALL = TriMesh(box((200.0, 100.0, 0.2)).vertices + np.array([40.0, 50.0, -7.0]), box((200.0, 100.0, 0.2)).faces)
NORTH_WALL = TriMesh(box((200.0, 100.0, 0.2)).vertices + np.array([40.0, 50.0, 25.0]), box((200.0, 100.0, 0.2)).faces)
RESPAWN_S = KILL_S + 1.2  # b2 comes back to life behind the north wall
# the most a replay's camera moves in a frame here without a jump: its pair window's reframe swings it
# up to 2.6 m a frame; following a2 through its teleport it moved 21 m in one, m
SWING_MAX_M = 3.0


def teleported(t: float):
    """two_fronts, but a2 stands 14 m south of its place, behind SOUTH_WALL, for 3 s until
    TELEPORT_S (a jump through it: a teleporter's, moments.py), and b2 respawns 20 m north,
    behind NORTH_WALL, at RESPAWN_S."""
    places = two_fronts(t)
    if TELEPORT_S - 3.0 <= t < TELEPORT_S:
        (x, z), yaw = places["a2"]
        places["a2"] = ((x, z - 14.0), yaw)
    if t >= RESPAWN_S:
        places["b2"] = ((40.0, 35.0), 0.0)
    return places


def _one_piece(states: list[FrameState]) -> list[FrameState]:
    """The program's one REPLAY, checked whole: as long as its replayed moments, uncut, its camera
    jumping nowhere (a hand-built scene has no level, so the rig flags no cut where the camera
    passes through a wall: the jump is what such a cut would be, rig.py)."""
    shown = replays(states)
    assert len(shown) == 1, [(r[0].time_s, len(r)) for r in shown]  # a cut within it splits it
    replay = shown[0][0].match.shot.replay
    assert replay.kill_time_s == KILL_S and len(shown[0]) >= round(replay.length_s * RATE_HZ) - 1
    steps_m = np.linalg.norm(np.diff([s.pose.position_world for s in shown[0]], axis=0), axis=1)
    assert steps_m.max() < SWING_MAX_M, (float(steps_m.max()), shown[0][int(steps_m.argmax())].time_s)
    return shown[0]


def test_a_replay_starts_after_its_killers_teleport_in_the_build_up():
    """a2 teleports through a wall 1.1 s before its kill, within the replay's usual build-up (2 s):
    every camera of the pair (a2's eyes, a Toric camera anchored on it) passes through the wall
    there, a cut within the replay. The replay shows as many moments, from just after the
    teleport, and is one shot; it still shows the kill."""
    settings = MatchSettings()
    match = Match(TEAMS, teleported, [kill("a2", "b2", KILL_S)], delay_s=10.0, walls=[SOUTH_WALL, NORTH_WALL])
    replay = _one_piece([s for s in BareRig(match, settings).run(40.0) if not s.match.buffering])
    shown = replay[0].match.shot.replay
    assert TELEPORT_S <= shown.from_s <= TELEPORT_S + 1.0 / RATE_HZ
    assert shown.length_s == settings.replay_pre_s + settings.replay_post_s
    assert any(abs(s.match.replay_of.time_s - KILL_S) <= 1.0 / RATE_HZ for s in replay)


def test_a_replay_past_its_victims_respawn_frames_the_killer_alone_by_then():
    """Moved past a2's teleport, the replay shows b2's respawn behind the north wall 1.2 s after
    the kill: a Toric camera framing the pair throughout goes on framing b2 there (pulled in
    front of the south wall, here; in a level, past the walls, a cut). The pair window's camera
    (the pair around the kill, a2 alone after it) comes first there: the replay is one shot,
    showing a2 alone, undegraded, by the respawn."""
    settings = MatchSettings(first_person=False)  # a Toric replay
    match = Match(TEAMS, teleported, [kill("a2", "b2", KILL_S)], delay_s=10.0, walls=[SOUTH_WALL, NORTH_WALL])
    replay = _one_piece([s for s in BareRig(match, settings).run(40.0) if not s.match.buffering])
    after = [s for s in replay if s.match.replay_of.time_s >= RESPAWN_S - AFTER_KILL_S]
    assert after and all(s.match.shot.subject_ids == ("a2",) for s in after)
    assert not any("pulled_in_front_of_wall" in s.flags for s in after)


def test_a_replay_comes_before_a_discretionary_cut_at_its_tick():
    """When the live shot would cut away from the dead victim (dead_hold_s) at the very tick the
    replay may come, the replay comes, straight from the live shot of the kill; the cut away waits
    (before, the cut came first and the replay, once its shot was min_shot_s old, after a short
    live shot). The live shot is a Toric one: through the killer's eyes, the replay's place
    search from a live camera at the killer's eye outgrew the tick's plan work (plan_late), and
    the replay came a tick later."""
    settings = MatchSettings(dead_hold_s=MatchSettings().replay_after_s, first_person=False)
    states = BareRig(Match(TEAMS, two_fronts, [kill("a2", "b2", KILL_S)], delay_s=10.0), settings).run(40.0)
    shown = replays(states)
    assert len(shown) == 1
    first = shown[0][0]
    assert first.time_s <= KILL_S + settings.replay_after_s + settings.plan_interval_s + 1e-9
    live = states[states.index(at_time(states, KILL_S)) : states.index(first)]
    assert live and not any(s.cut for s in live[1:]) and live[0].match.shot.subject_ids == ("a2", "b2")


def test_kills_close_together_get_no_replay_between_them():
    """Kills 3 s apart leave no room (replay_after_s + its length + the next beat's lead_s) between
    them; the second, with room after it, is replayed."""
    second_s = KILL_S + 3.0
    match = Match(TEAMS, two_fronts, [kill("a1", "b1", KILL_S), kill("a2", "b2", second_s)], delay_s=10.0)
    _, states = run_session(match, 45.0)
    shown = replays(states)
    assert [r[0].match.shot.replay.kill_time_s for r in shown] == [second_s]
    assert shown[0][0].time_s > second_s


def test_a_replay_never_covers_a_live_kill_and_kills_with_room_get_one():
    match = melee(seed=4, duration_s=60.0, delay_s=10.0, kill_every_s=7.0)
    _, states = run_session(match, 60.0)
    shown = replays(states)
    replay_frames = {s.frame for r in shown for s in r}
    end_s = max(s.time_s for s in states if not s.match.buffering)
    kill_times = [e.time_s for e in match.events if e.time_s <= end_s]
    assert all(at_time(states, t).frame not in replay_frames for t in kill_times)  # every kill live
    assert len(shown) >= len(kill_times) // 2  # 7 s apart, every kill leaves room


def test_the_same_match_gives_the_same_replays_pose_for_pose():
    runs = [run_session(melee(seed=4, duration_s=40.0, delay_s=10.0, kill_every_s=7.0), 40.0)[1] for _ in range(2)]
    poses = [np.array([s.pose.position_world for s in states if s.pose is not None]) for states in runs]
    assert np.array_equal(poses[0], poses[1])
    shots = [[(s.frame, s.match.shot, s.match.replay_of) for s in states if s.match.shot] for states in runs]
    assert shots[0] == shots[1] and any(shot.kind == ShotKind.REPLAY for _, shot, _ in shots[0])


def test_a_replay_candidate_is_offered_with_its_kill_moment_after_the_kill_is_shown():
    """The director has no room to replay the first of two kills 3 s apart: a human is offered it,
    from replay_after_s after it until the next kill, its monitor at the kill."""
    settings = MatchSettings()
    match = Match(TEAMS, two_fronts, [kill("a1", "b1", KILL_S), kill("a2", "b2", KILL_S + 3.0)], delay_s=10.0)
    _, states = run_session(match, 10.0 + KILL_S + 2.9)
    offered = [(s, c) for s in states if not s.match.buffering for c in s.match.candidates if c.shot.kind == ShotKind.REPLAY]
    assert offered and all(s.time_s >= KILL_S + settings.replay_after_s for s, _ in offered)
    assert all(c.shot.subject_ids == ("a1", "b1") and abs(c.replay_of.time_s - KILL_S) < 1.0 / 30 + 1e-9 for _, c in offered)
    assert all(len(s.match.candidates) <= settings.candidates for s, _ in offered)


def test_a_take_of_a_replay_plays_the_pairs_latest_kill_then_gives_the_program_back():
    settings = MatchSettings()
    match = Match(TEAMS, two_fronts, [kill("a2", "b2", KILL_S)], delay_s=10.0)
    frames = list(match.frames(45.0))
    session = Session("s", match.scene())
    taken_at = next(i for i, u in enumerate(frames) if u.time_s >= KILL_S + 10.0 + 0.5)  # the kill is 0.5 s past on air
    before = [session.frame(u) for u in frames[:taken_at]]
    assert not any(s.match.shot is not None and s.match.shot.kind == ShotKind.REPLAY for s in before)
    choice = session.rig.take(["b2", "a2"], ShotKind.REPLAY, release=False)
    assert choice.kind == ShotKind.REPLAY and choice.held
    after = [session.frame(u) for u in frames[taken_at:]]
    playing = [s for s in after if s.match.shot.kind == ShotKind.REPLAY]
    assert playing[0] is after[0] and playing[0].cut and all(s.match.shot.held for s in playing)
    assert playing[0].match.shot.replay.kill_time_s == KILL_S
    assert abs(len(playing) / 30.0 - settings.replay_length_s) <= 0.15
    back = after[len(playing)]
    assert back.cut and not back.match.shot.held and back.match.shot.kind != ShotKind.REPLAY


def test_a_take_of_a_replay_with_no_kill_to_show_is_refused():
    match = Match(TEAMS, two_fronts, [], delay_s=10.0)
    frames = list(match.frames(14.0))
    session = Session("s", match.scene())
    for u in frames[:390]:
        session.frame(u)
    session.rig.take(["a1", "b1"], ShotKind.REPLAY, release=False)
    state = session.frame(frames[390])
    assert "take_replay_refused" in state.flags and state.match.shot.kind != ShotKind.REPLAY


def test_a_replay_worked_out_ahead_answers_as_one_computed_in_the_frame(monkeypatch):
    """The camera worked out ahead in the idle moments (camera_ahead.py) steps a replay's camera at
    its replayed moment, as the frame does: the same program with or without the idle work, and
    replay frames took their step from it."""
    worked_out: list[tuple[bool, bool]] = []  # (the frame's step was worked out ahead, it was a replay's)
    holds = CameraStep.holds

    def counted(step: CameraStep, moment, dt_s, shot, style, last_pose, cut_short) -> bool:
        worked_out.append((holds(step, moment, dt_s, shot, style, last_pose, cut_short), shot.choice.replay is not None))
        return worked_out[-1][0]

    monkeypatch.setattr(CameraStep, "holds", counted)
    programs = []
    for idle in (False, True):
        match = melee(seed=4, duration_s=40.0, delay_s=10.0, kill_every_s=7.0)
        session = Session("s", match.scene())
        program = []
        for update in match.frames(40.0):
            state = session.frame(update)
            if state.pose is not None:
                candidates = [(c.shot, c.pose.position_world.tolist(), c.replay_of) for c in state.match.candidates]
                program.append((state.pose.position_world.tolist(), state.visibility, state.match.replay_of, candidates))
            if idle:
                session.do_deferred_work()
        programs.append(program)
    assert programs[0] == programs[1]
    assert any(replay_of is not None for _, _, replay_of, _ in programs[0])
    assert any(ahead and replay for ahead, replay in worked_out)


def face_to_face(t: float):
    """two_fronts, but a2 stands 6 m from b2 looking at it: its eyes show b2 at the kill."""
    return two_fronts(t) | {"a2": ((40.0, 9.0), facing((40, 9), (40, 15))), "b2": ((40.0, 15.0), facing((40, 15), (40, 9)))}


def test_a_kill_the_killers_eyes_saw_is_replayed_through_them_unless_the_live_picture_was_there():
    """The kill cam: replayed through a2's eyes where they show b2 at the kill and the live camera
    was elsewhere (a Toric view from the side); where the live picture was a2's eyes already, the
    replay is a Toric camera turned past the 30-degree rule from it."""
    rig = BareRig(Match(TEAMS, face_to_face, [kill("a2", "b2", KILL_S)], delay_s=10.0), MatchSettings())
    rig.run(KILL_S + 3.0)
    replays = rig.rig.director.replays.replays
    event = next(e for e in rig.rig.buffer.events_between(KILL_S - 1.0, KILL_S + 1.0) if e.kind.name == "KILL")
    side_world = np.array([48.0, EYE_M, 12.0])  # beside the pair
    kill_cam = replays.shot(event, rig.rig.buffer, side_world, KILL_S + 2.0, "replay")
    assert kill_cam is not None and isinstance(kill_cam.camera, FirstPersonCamera) and kill_cam.camera.player == 2
    assert kill_cam.choice.eyes_id == "a2" and kill_cam.choice.kind == ShotKind.REPLAY
    assert kill_cam.choice.subject_ids == ("a2", "b2") and "through a2's eyes" in kill_cam.choice.reason
    eye_world = kill_cam.camera.pose(rig.rig.buffer.at(KILL_S)).position_world
    toric = replays.shot(event, rig.rig.buffer, eye_world, KILL_S + 2.0, "replay")
    assert toric is not None and isinstance(toric.camera, ToricCamera) and toric.choice.eyes_id == ""


ROOM_HALF_WIDTH_M = 1.5  # a closed room 3 m wide, 3 m high, 9 m long around a2 and b2: no DUEL place inside sees both


def in_a_room(t: float):
    """two_fronts, but a2 and b2 face each other 6 m apart in the closed room (room_walls)."""
    a2, b2 = (40.0, 9.5), (40.0, 15.5)
    return two_fronts(t) | {"a2": (a2, facing(a2, b2)), "b2": (b2, facing(b2, a2))}


def room_walls() -> list[TriMesh]:
    """The room's two sides, roof and two ends, 0.2 m thick, centred on x = 40, z = 12.5."""
    w = ROOM_HALF_WIDTH_M
    slabs = [
        ((0.2, 3.0, 9.0), (40.0 - w, 1.5, 12.5)),
        ((0.2, 3.0, 9.0), (40.0 + w, 1.5, 12.5)),
        ((2.0 * w, 0.2, 9.0), (40.0, 3.0, 12.5)),
        ((2.0 * w, 3.0, 0.2), (40.0, 1.5, 8.0)),
        ((2.0 * w, 3.0, 0.2), (40.0, 1.5, 17.0)),
    ]
    return [TriMesh(box(size).vertices + np.array(centre), box(size).faces) for size, centre in slabs]


def test_a_kill_no_place_sees_is_replayed_through_the_victims_eyes_where_the_killers_were_live():
    """In a closed room no DUEL place sees the pair; the live picture was a2's own eyes, so the
    kill cam would repeat it: the replay is b2's view of its killer. It names b2 alone in the
    build-up (as a kill cam names its killer), the pair at the kill, and keeps b2's eye at a
    living player's height after its death; from the side, the kill cam as before."""
    settings = MatchSettings()
    rig = BareRig(Match(TEAMS, in_a_room, [kill("a2", "b2", KILL_S)], delay_s=10.0, walls=room_walls()), settings)
    rig.run(KILL_S + 3.0)
    replays = rig.rig.director.replays.replays
    buffer = rig.rig.buffer
    event = next(e for e in buffer.events_between(KILL_S - 1.0, KILL_S + 1.0) if e.kind.name == "KILL")
    a2_eye_world = np.array([40.0, 1.44, 9.5])
    assert replays.shot(event, buffer, a2_eye_world, KILL_S + 2.0, "replay", eyes=False) is None  # no place
    shot = replays.shot(event, buffer, a2_eye_world, KILL_S + 2.0, "replay")
    assert shot is not None and isinstance(shot.camera, FirstPersonCamera) and shot.camera.player == 3
    assert shot.choice.eyes_id == "b2" and shot.choice.subject_ids == ("a2", "b2") and "through b2's eyes" in shot.choice.reason
    assert shot.camera.framed(KILL_S - 1.5) == (3,) and shot.camera.framed(KILL_S) is None
    at_kill, dead = (shot.camera.pose(buffer.at(t)) for t in (KILL_S, KILL_S + 0.4))
    assert not buffer.at(KILL_S + 0.4).alive[3]
    assert abs(dead.position_world[1] - at_kill.position_world[1]) < 1e-9 and at_kill.position_world[1] > 1.0
    aims = np.array([[40.0, EYE_M, 9.5]])  # a2 on b2's screen at the kill
    assert np.all(np.abs(project_to_screen(at_kill, shot.camera.lens, aims)) <= 1.0)
    side = replays.shot(event, buffer, np.array([39.0, 1.44, 12.5]), KILL_S + 2.0, "replay")
    assert side is not None and side.choice.eyes_id == "a2"


def test_a_replay_fills_the_room_before_the_next_beat_where_a_live_shot_there_would_be_under_a_shot():
    """Its usual 2.5 s where the room leaves a live shot of min_shot_s before the next beat; all the
    room where it would leave less (a longer build-up, from no earlier than the buffer's oldest
    moment); min_shot_s where the room is shorter still."""
    settings = MatchSettings()
    replays = Replays(list(TEAMS), types.SimpleNamespace(settings=settings))  # replay() reads the settings alone
    event = kill("a2", "b2", KILL_S)
    usual = settings.replay_length_s
    assert replays.replay(event, 2.0).length_s == usual  # no beat ahead
    assert replays.replay(event, 2.0, room_s=usual + 2.0).length_s == usual  # a 2 s live shot fits after it
    filled = replays.replay(event, 2.0, room_s=usual + 1.5)
    assert abs(filled.length_s - (usual + 1.5)) < 1e-9 and filled.until_s == KILL_S + settings.replay_post_s
    oldest = KILL_S - 2.5
    capped = replays.replay(event, 2.0, room_s=usual + 1.5, oldest_s=oldest)
    assert abs(capped.from_s - oldest) < 1e-9 and capped.until_s == KILL_S + settings.replay_post_s
    assert replays.replay(event, 2.0, room_s=1.0).length_s == 2.0


def test_a_late_replay_filling_its_room_shows_a_new_moment_every_frame():
    """A replay decided 3.5 s after its kill, with room before the next beat that a 2.5 s replay
    would leave under min_shot_s, fills it with build-up, but from no earlier than the past the
    buffer keeps for its whole time on air (replay_past_s before its start): the buffer's oldest
    moment runs up to COMPACT_AFTER frames older and is dropped as the program goes on, and a
    replay from it showed the oldest kept moment still, a step every 32 frames (casts of the
    2on2: 97-160 such frames)."""
    settings = MatchSettings(replay_after_s=3.5, first_person=False)
    match = Match(TEAMS, two_fronts, [kill("a2", "b2", KILL_S), kill("a1", "b1", KILL_S + 9.5)], delay_s=10.0)
    shown = replays(BareRig(match, settings).run(KILL_S + 9.5 + 12.0))
    assert [r[0].match.shot.replay.kill_time_s for r in shown] == [KILL_S]
    replay = shown[0]
    filled = replay[0].match.shot.replay
    assert filled.length_s > settings.replay_length_s  # the room filled (so the test can fail)
    assert filled.from_s >= replay[0].time_s - settings.replay_past_s - 1e-9
    replayed = np.array([s.match.replay_of.time_s for s in replay])
    assert np.all(np.diff(replayed) > 0)


def test_a_replay_the_edit_window_starts_early_shows_the_moments_before_its_first():
    """The edit window gives a short live shot's frames to the replay after it, started early
    (edit_window.py): the replay shows the moments before its first there, one new each frame,
    as the window judged it (the code before held its first moment still: a frozen picture)."""
    settings = MatchSettings(replay_after_s=2.5, first_person=False)
    match = Match(TEAMS, two_fronts, [kill("a2", "b2", KILL_S), kill("a1", "b1", KILL_S + 8.0)], delay_s=10.0)
    shown = replays(BareRig(match, settings).run(KILL_S + 8.0 + 12.0))
    early = [r for r in shown if "edit_window_started_early" in r[0].flags]
    assert early  # so the test can fail: the window started one early
    for replay in early:
        replayed = np.array([s.match.replay_of.time_s for s in replay])
        assert replayed[0] < replay[0].match.shot.replay.from_s - 0.5
        assert np.all(np.diff(replayed) > 0)
