"""bridges/gsi_tracks.py on synthetic payloads: duplicates and late payloads never move time back,
positions interpolate between the two newest payloads, kills are read off the scoreboard as far as
GSI allows, and players are stale once payloads stop."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.bridges.gsi import GsiPayload, GsiPlayer
from camdirector.bridges.gsi_tracks import GsiTracks
from camdirector.matches.cs2_demo import source_points_to_world


def player(steamid: str, team: str, slot: int, x: float, kills: int = 0, deaths: int = 0, health: int = 100) -> GsiPlayer:
    return GsiPlayer(
        steamid, f"n{steamid}", team, slot, health, 0, False, False, kills, deaths, np.array([x, 0.0, 0.0]), np.array([1.0, 0, 0])
    )


def payload(stamp: int, *players: GsiPlayer) -> GsiPayload:
    return GsiPayload("t", stamp, "de_x", 1, players, "")


def test_positions_interpolate_between_the_two_newest_payloads_then_hold():
    tracks = GsiTracks(interp_delay_s=0.0, hold_s=5.0)
    assert tracks.offer(payload(10, player("a", "T", 1, 0.0)), b"1", 100.0) == "accepted"
    assert tracks.offer(payload(10, player("a", "T", 1, 100.0)), b"2", 101.0) == "accepted"
    half = tracks.sample(100.5).positions_world[0]
    np.testing.assert_allclose(half, source_points_to_world(np.array([50.0, 0, 0])))
    np.testing.assert_allclose(tracks.sample(103.0).positions_world[0], source_points_to_world(np.array([100.0, 0, 0])))


def test_duplicates_and_late_payloads_do_not_move_time_back():
    tracks = GsiTracks(interp_delay_s=0.0, hold_s=5.0)
    tracks.offer(payload(10, player("a", "T", 1, 0.0)), b"1", 100.0)
    tracks.offer(payload(11, player("a", "T", 1, 100.0)), b"2", 101.0)
    assert tracks.offer(payload(11, player("a", "T", 1, 100.0)), b"2", 101.5) == "duplicate"
    assert tracks.offer(payload(10, player("a", "T", 1, -500.0)), b"3", 101.6) == "out_of_order"
    np.testing.assert_allclose(tracks.sample(101.7).positions_world[0], source_points_to_world(np.array([100.0, 0, 0])))
    c = tracks.counts
    assert (c.accepted, c.duplicate, c.out_of_order) == (2, 1, 1)


def test_one_kill_and_one_death_pair_up_else_the_victim_is_unknown():
    tracks = GsiTracks(interp_delay_s=0.0, hold_s=5.0)
    tracks.offer(payload(1, player("a", "T", 1, 0), player("b", "CT", 2, 10), player("c", "CT", 3, 20)), b"1", 0.0)
    tracks.offer(
        payload(2, player("a", "T", 1, 0, kills=1), player("b", "CT", 2, 10, health=0, deaths=1), player("c", "CT", 3, 20)),
        b"2",
        1.0,
    )
    first = tracks.sample(1.0)
    assert [(e.kind, e.actor_id, e.other_id) for e in first.events] == [("kill", "p00", "p01")]
    np.testing.assert_allclose(first.events[0].position_world, source_points_to_world(np.array([10.0, 0, 0])))
    assert ("p00", 100, 0, 0, 1) in first.stats and ("p01", 0, 0, 0, 0) in first.stats
    again = tracks.sample(1.1)
    assert again.events == [] and again.stats == []  # each once
    # a grenade: two kills, two deaths in one payload; who killed whom is not in GSI
    tracks.offer(
        payload(
            3,
            player("a", "T", 1, 0, kills=3),
            player("b", "CT", 2, 10, health=0, deaths=1),
            player("c", "CT", 3, 20, health=0, deaths=1),
        ),
        b"3",
        2.0,
    )
    events = sorted((e.kind, e.actor_id, e.other_id) for e in tracks.sample(2.0).events)
    assert events == [("death", "p02", ""), ("kill_unknown", "p00", ""), ("kill_unknown", "p00", "")]


def test_players_are_stale_once_payloads_stop_for_hold_s():
    tracks = GsiTracks(interp_delay_s=0.1, hold_s=2.0)
    tracks.offer(payload(1, player("a", "T", 1, 0)), b"1", 50.0)
    assert not tracks.sample(51.9).stale
    assert tracks.sample(52.1).stale
    tracks.offer(payload(3, player("a", "T", 1, 0)), b"2", 52.2)
    assert not tracks.sample(52.3).stale


def test_the_roster_is_ordered_by_observer_slot_and_a_later_player_joins_the_next_session():
    tracks = GsiTracks(interp_delay_s=0.0, hold_s=5.0)
    tracks.offer(payload(1, player("z", "CT", 2, 0), player("y", "T", 1, 0)), b"1", 0.0)
    assert [(m.id, m.name, m.team, m.team_name) for m in tracks.roster] == [("p00", "ny", 0, "T"), ("p01", "nz", 1, "CT")]
    assert not tracks.roster_changed.is_set()
    newcomer = player("new", "T", 3, 300.0)
    tracks.offer(payload(2, player("z", "CT", 2, 0), player("y", "T", 1, 0), newcomer), b"2", 1.0)
    # he kills z: a kill naming him waits out of the open session, as he does
    tracks.offer(
        payload(3, player("z", "CT", 2, 0, deaths=1), player("y", "T", 1, 0), player("new", "T", 3, 300.0, kills=1)), b"3", 1.1
    )
    assert tracks.roster_changed.is_set() and tracks.counts.unknown == 0
    before = tracks.sample(1.2)
    assert before.ids == ["p00", "p01"] and before.positions_world.shape == (2, 3) and before.events == []
    assert [(m.id, m.name, m.team, m.team_name) for m in tracks.reopen()] == [("p02", "nnew", 0, "T")]
    assert not tracks.roster_changed.is_set() and [m.id for m in tracks.roster] == ["p00", "p01", "p02"]
    after = tracks.sample(1.3)
    assert after.ids == ["p00", "p01", "p02"]
    np.testing.assert_allclose(after.positions_world[2], source_points_to_world(np.array([300.0, 0, 0])))
    assert ("p02", 100, 0, 0, 1) in after.stats  # his scoreboard goes out with his first frame
    spectator = GsiPlayer("s", "ns", "", 9, 100, 0, False, False, 0, 0, None, None)
    tracks.offer(payload(4, player("z", "CT", 2, 0), player("y", "T", 1, 0), spectator), b"4", 2.0)
    assert tracks.counts.unknown == 1 and not tracks.roster_changed.is_set()  # no team, no place: not a player


def test_the_first_payload_is_not_sampled_before_it_is_due():
    tracks = GsiTracks(interp_delay_s=0.1, hold_s=2.0)
    tracks.offer(payload(1, player("a", "T", 1, 0.0)), b"1", 50.0)
    early = tracks.sample(50.05)
    assert not early.started and early.ids == [] and not early.stale
    tracks.offer(payload(1, player("a", "T", 1, 100.0)), b"2", 50.1)
    due = tracks.sample(50.1)
    assert due.started and due.ids == ["p00"]
    np.testing.assert_allclose(due.positions_world[0], source_points_to_world(np.array([0.0, 0, 0])))
    assert tracks.sample(50.15).positions_world[0] == pytest.approx(source_points_to_world(np.array([50.0, 0, 0])))
