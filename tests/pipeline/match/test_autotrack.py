"""AUTOTRACK, ezQuake's mvd_autotrack: ranking by stats (armor, weapon, powerups, frags), the value
list chosen by the player count, the switch-moment rule, the first-person camera at the eye, the
stats seen at the program moment under a delay, and the frags-from-kills fallback without stats."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from camdirector.geometry.camera import project_to_screen
from camdirector.geometry.quake_frame import M_PER_UNIT, view_rotation
from camdirector.geometry.transforms import RigidTransform, quat_rotate
from camdirector.pipeline.inputs import PlayerStats
from camdirector.pipeline.match.autotrack import (
    IT_ARMOR1,
    IT_ARMOR2,
    IT_ARMOR3,
    IT_AXE,
    IT_INVULNERABILITY,
    IT_LIGHTNING,
    IT_QUAD,
    IT_ROCKET_LAUNCHER,
    IT_SHOTGUN,
    NO_STATS_FLAG,
    AutotrackDirector,
    AutotrackSettings,
    FirstPersonCamera,
)
from camdirector.pipeline.match.moments import MomentBuffer
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.session import Session
from camdirector.pipeline.style import Rig, Style
from tests.pipeline.match.scenes import LENS, Match, kill, run_session

START = IT_AXE | IT_SHOTGUN  # what a QuakeWorld player respawns with
AUTOTRACK = Style(rig=Rig.MATCH, match_director="autotrack")


def stats(player: str, items: int = START, armor: int = 0, frags: int = 0, health: int = 100) -> PlayerStats:
    return PlayerStats(player, health, armor, items, frags)


def director(count: int, table: dict[str, PlayerStats], **settings) -> AutotrackDirector:
    players = [f"p{i}" for i in range(count)]
    return AutotrackDirector(players, np.arange(count), LENS, table, AutotrackSettings(**settings))


def best_of(d: AutotrackDirector) -> str:
    return d.players[d.best(d.values([]), 0, np.ones(len(d.players), dtype=bool))]


def standing(count: int) -> dict:
    """Players 3 m apart on the x axis, all facing +Z."""
    return {f"p{i}": ((3.0 * i, 0.0), 0.0) for i in range(count)}


# -- ranking -------------------------------------------------------------------------------------
def test_rocket_launcher_and_red_armor_outrank_a_shotgun():
    d = director(2, {"p0": stats("p0"), "p1": stats("p1", START | IT_ROCKET_LAUNCHER | IT_ARMOR3, armor=200)})
    values = d.values([])
    assert values[0] == 50 * 2  # %W: the shotgun's 2; no armor
    assert values[1] == 200 * 3 + 50 * 8  # red armor 3 per point, the rocket launcher's 8
    assert best_of(d) == "p1"


def test_armor_type_and_best_weapon_follow_ezquake_order():
    d = director(
        2,
        {
            "p0": stats("p0", START | IT_LIGHTNING | IT_ROCKET_LAUNCHER | IT_ARMOR1 | IT_ARMOR3, armor=50),
            "p1": stats("p1", START | IT_ARMOR2, armor=100),
        },
    )
    values = d.values([])
    assert values[0] == 50 * 1 + 50 * 8  # green armor is tested first; tp_weapon_order "78654321": the RL first
    assert values[1] == 100 * 2 + 50 * 2


def test_quad_outranks_in_team_modes():
    base = START | IT_ROCKET_LAUNCHER | IT_ARMOR2
    table = {f"p{i}": stats(f"p{i}", base, armor=100) for i in range(4)}
    table["p2"] = stats("p2", base | IT_QUAD, armor=100)
    d = director(4, table)
    assert d.values([])[2] - d.values([])[0] == 900  # 2on2's quad value
    assert best_of(d) == "p2"


def test_the_value_list_is_chosen_by_player_count():
    settings = AutotrackSettings()
    assert [settings.mode(n)[0] for n in (2, 3, 4, 6, 8, 10)] == ["1on1", "4on4", "2on2", "4on4", "4on4", "4on4"]
    assert AutotrackSettings(mvd_autotrack=2).mode(2)[0] == "custom"
    quad = stats("p0", START | IT_ROCKET_LAUNCHER | IT_QUAD)
    armored = stats("p1", START | IT_ROCKET_LAUNCHER | IT_ARMOR2, armor=100)
    # 1on1 values give powerups nothing: the armored player leads a duel...
    assert best_of(director(2, {"p0": quad, "p1": armored})) == "p1"
    # ...and the quad leads once there are four players (2on2: quad 900)
    assert best_of(director(4, {"p0": quad, "p1": armored})) == "p0"
    # 4on4: the rocket launcher is worth 10 (1on1 and 2on2: 8)
    rl = {"p0": stats("p0", START | IT_ROCKET_LAUNCHER)}
    assert director(8, rl).values([])[0] == 500 and director(2, rl).values([])[0] == 400


def test_the_tracked_player_keeps_a_tie_and_the_first_wins_among_others():
    even = np.array([5.0, 7.0, 7.0, 7.0])
    everyone = np.ones(4, dtype=bool)
    assert AutotrackDirector.best(even, 2, everyone) == 2
    assert AutotrackDirector.best(even, 0, everyone) == 1


def test_settings_are_checked_once():
    with pytest.raises(ValueError, match="mvd_autotrack_2on2"):
        AutotrackSettings(mvd_autotrack_2on2="%a * %D")
    with pytest.raises(ValueError, match="14 finite"):
        AutotrackSettings(mvd_autotrack_1on1_values=(1.0, 2.0))
    with pytest.raises(ValueError, match="mvd_autotrack must be 1 or 2"):
        AutotrackSettings(mvd_autotrack=4)
    with pytest.raises(ValueError, match="tp_weapon_order"):
        AutotrackSettings(tp_weapon_order="79")
    assert (
        AutotrackSettings(mvd_autotrack_custom="(%h + %a) / 2 - %u", mvd_autotrack=2).mode(3)[1]({"h": 100, "a": 50, "u": 1})
        == 74.0
    )


# -- switching ---------------------------------------------------------------------------------
def test_switches_only_at_a_switch_moment():
    """p0 holds the rocket launcher; p1 gets a better ranking (RL and red armor) but that is no
    switch moment: the camera stays. p0 respawns with a shotgun at 6 s: it has no RL or LG while
    p1 has, so the next 0.5-s update switches to p1."""

    def table(t: float) -> dict[str, PlayerStats]:
        p0 = stats("p0", START | (IT_ROCKET_LAUNCHER if t < 6.0 else 0), frags=1)
        p1 = stats("p1", START | (IT_ROCKET_LAUNCHER | IT_ARMOR3 if t >= 2.0 else 0), armor=200 if t >= 2.0 else 0)
        return {"p0": p0, "p1": p1}

    match = Match({"p0": 1, "p1": 2}, lambda t: standing(2), style=AUTOTRACK)
    session = Session("s", match.scene())
    sent: dict[str, PlayerStats] = {}
    states = []
    for update in match.frames(8.0):
        now = table(update.time_s)
        update.player_stats = [s for p, s in now.items() if sent.get(p) != s]  # only what changed
        sent.update(now)
        states.append(session.frame(update))
    tracked = [(s.time_s, s.match.shot.subject_ids) for s in states]
    assert all(ids == ("p0",) for t, ids in tracked if t < 6.0)
    switch = next(t for t, ids in tracked if ids == ("p1",))
    assert 6.0 <= switch <= 6.0 + 0.5 + 0.1 + 1e-9  # the 0.5-s update, on the rig's 10-Hz planning tick
    assert all(ids == ("p1",) for t, ids in tracked if t >= switch)
    cuts = [s for s in states if s.cut]
    assert [c.match.shot.subject_ids for c in cuts] == [("p0",), ("p1",)]
    assert "no rocket launcher or lightning gun" in cuts[1].match.shot.reason
    assert cuts[1].match.shot.kind.name == "FOLLOW"


def _moments(players: list[str], seconds: float, rate_hz: float = 10.0):
    buffer = MomentBuffer(players, MatchSettings())
    for k in range(int(seconds * rate_hz) + 1):
        transforms = [RigidTransform(np.array([3.0 * i, 0.0, 0.0])) for i in range(len(players))]
        buffer.push(k, k / rate_hz, transforms, [t.position_world + [0, 1.6, 0] for t in transforms], [])
        yield buffer, buffer.program_moment(k / rate_hz)


@pytest.mark.parametrize("instant", [False, True])
def test_instant_reranks_at_every_update(instant):
    """p1 outranks the tracked p0 (both hold a rocket launcher, no powerups): only
    mvd_autotrack_instant switches."""
    table = {"p0": stats("p0", START | IT_ROCKET_LAUNCHER)}
    d = director(2, table, mvd_autotrack_instant=instant)
    shown = None
    for buffer, moment in _moments(d.players, 2.0):
        if moment.time_s >= 1.0:
            table["p1"] = stats("p1", START | IT_ROCKET_LAUNCHER | IT_ARMOR2, armor=100)
        shot = d.decide(moment, buffer, shown, None, [])
        shown = shot or shown
    assert shown.choice.subject_ids == (("p1",) if instant else ("p0",))


def test_pentagram_with_rocket_launcher_is_a_switch_moment_and_lockteam_holds_the_team():
    table = {"p0": stats("p0", START | IT_ROCKET_LAUNCHER | IT_QUAD), "p1": stats("p1"), "p2": stats("p2")}
    players = ["p0", "p1", "p2"]
    teams = np.array([1, 1, 2])  # teamplay: p0 and p1 share a team
    for lockteam, expected in ((False, "p2"), (True, "p0")):
        d = AutotrackDirector(players, teams, LENS, dict(table), AutotrackSettings(mvd_autotrack_lockteam=lockteam))
        shown = None
        for buffer, moment in _moments(players, 2.0):
            if moment.time_s >= 1.0:
                d.stats["p2"] = stats("p2", START | IT_ROCKET_LAUNCHER | IT_INVULNERABILITY)
            shown = d.decide(moment, buffer, shown, None, []) or shown
        assert shown.choice.subject_ids == (expected,), lockteam


def test_a_checkpointed_director_decides_as_the_original():
    """A session's checkpoint pickles its rig: the director (its parsed expression too) comes back
    and goes on deciding the same."""
    d = director(4, {"p0": stats("p0", START | IT_ROCKET_LAUNCHER)}, mvd_autotrack_4on4="(%a + 1) / (%h + 1) * %W")
    runs = [d, None]
    shown = [None, None]
    for buffer, moment in _moments(d.players, 2.0):
        if moment.time_s == 1.0:
            runs[1] = pickle.loads(pickle.dumps(d))
            shown[1] = shown[0]
        for r, run in enumerate(runs):
            if run is not None:
                if moment.time_s >= 1.5:
                    run.stats["p3"] = stats("p3", START | IT_LIGHTNING | IT_QUAD, armor=200)
                shown[r] = run.decide(moment, buffer, shown[r], None, []) or shown[r]
    assert shown[0].choice == shown[1].choice and shown[0].choice.subject_ids == ("p3",)


# -- the camera ----------------------------------------------------------------------------------
def test_first_person_pose_sits_at_the_eye_and_looks_along_the_view():
    pitch, yaw = 30.0, 90.0  # Quake: looking 30 deg down, toward +Y (the world's -Z)
    rotation = view_rotation(np.array(pitch), np.array(yaw))
    feet = np.array([2.0, 0.5, -1.0])
    buffer = MomentBuffer(["p0", "p1"], MatchSettings())
    transforms = [RigidTransform(feet, rotation), RigidTransform(np.array([9.0, 0.0, 0.0]))]
    buffer.push(0, 0.0, transforms, [t.position_world for t in transforms], [])
    moment = buffer.program_moment(0.0)
    pose = FirstPersonCamera(0, LENS).pose(moment)
    assert np.allclose(pose.position_world, feet + [0.0, (24 + 22) * M_PER_UNIT, 0.0])  # origin + 22 units
    view = quat_rotate(pose.rotation_xyzw, np.array([0.0, 0.0, -1.0]))  # a camera looks down its -Z
    p, y = math.radians(pitch), math.radians(yaw)
    assert np.allclose(view, [math.cos(p) * math.cos(y), -math.sin(p), -math.cos(p) * math.sin(y)], atol=1e-9)
    ahead = pose.position_world + 5.0 * view
    assert np.allclose(project_to_screen(pose, LENS, ahead[None])[0], [0.0, 0.0], atol=1e-9)
    right = quat_rotate(pose.rotation_xyzw, np.array([1.0, 0.0, 0.0]))
    assert abs(right[1]) < 1e-9  # level horizon: the camera's x axis stays horizontal
    moment.alive[0] = False
    assert np.allclose(
        FirstPersonCamera(0, LENS).pose(moment).position_world, feet + [0.0, (24 - 16) * M_PER_UNIT, 0.0]
    )  # a corpse's view height


def test_the_program_shows_the_tracked_players_first_person_view_without_a_delay_wait():
    match = Match({"p0": 1, "p1": 2}, lambda t: standing(2), style=AUTOTRACK)
    session = Session("s", match.scene())
    states = []
    for update in match.frames(1.0):
        if update.frame == 0:
            update.player_stats = [stats("p0"), stats("p1", START | IT_LIGHTNING, armor=10)]
        states.append(session.frame(update))
    assert not states[0].match.buffering and states[0].cut
    assert all(s.match.shot.subject_ids == ("p1",) for s in states)
    assert np.allclose(states[-1].pose.position_world, [3.0, (24 + 22) * M_PER_UNIT, 0.0])


def test_under_a_delay_stats_count_from_their_own_moment():
    """Stats sent with the frame of time t join the view when the program reaches t (2 s later)."""
    match = Match({"p0": 1, "p1": 2}, lambda t: standing(2), delay_s=2.0, style=AUTOTRACK)
    session = Session("s", match.scene())
    states = []
    for update in match.frames(5.0):
        if update.frame == 30:  # t = 1 s
            update.player_stats = [stats("p1", START | IT_ROCKET_LAUNCHER)]
        states.append(session.frame(update))
    shown = [s for s in states if not s.match.buffering]
    before = [s for s in shown if s.time_s < 1.0]
    assert before and all(s.match.shot.subject_ids == ("p0",) for s in before)
    switch = next(s.time_s for s in shown if s.match.shot.subject_ids == ("p1",))
    assert 1.0 <= switch <= 1.6 + 1e-9


# -- without stats ------------------------------------------------------------------------------
def test_without_stats_it_ranks_by_frags_from_kills_and_flags_it():
    kills = [
        kill("p2", "p0", 1.0),
        kill("p2", "p1", 2.0),
        kill("p1", "p1", 2.5),
        kill("p0", "p2", 4.0),
        kill("p0", "p1", 5.0),
        kill("p0", "p2", 6.0),
    ]
    session, states = run_session(Match({"p0": 1, "p1": 2, "p2": 3}, lambda t: standing(3), events=kills, style=AUTOTRACK), 7.0)
    at = {round(s.time_s, 3): s for s in states}
    assert at[0.5].match.shot.subject_ids == ("p0",)  # nobody has a frag: the first player
    assert at[3.0].match.shot.subject_ids == ("p2",)  # p2: 2 frags
    assert at[5.7].match.shot.subject_ids == ("p2",)  # p0 ties p2 at 2 (5.0 s): the tracked p2 keeps it
    assert at[7.0].match.shot.subject_ids == ("p0",)  # p0: 3 frags from 6.0 s
    assert "no stats" in at[7.0].match.shot.reason
    flagged = [s for s in states if NO_STATS_FLAG in s.flags]
    assert {int(s.time_s) for s in flagged} == set(range(7))  # at the planning ticks, all along
