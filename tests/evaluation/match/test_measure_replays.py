"""eval-match's replays (measure.py): a replay's moments are measured against the bodies of the
moment they show, a replay showing both at the kill counts as shown, a kill followed by another
within the room leaves none, and a live kill that falls in a replay is missed and counted; a
replay in the killer's eyes showing the victim at the kill counts as shown (the kill cam), as does
one in the victim's eyes showing the killer; a replay over two kills of its pair replays each it
shows."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from camdirector.evaluation.match.match_file import MatchEvent
from camdirector.evaluation.match.measure import BodySampler, in_eyes_of, kill_coverage, measure_shown, replay_figures
from camdirector.geometry.camera import Lens
from tests.evaluation.match.test_measure import duel, first_person_of_a, floor, side_view

KILL_ROW = 20  # duel(): the kill at 2.0 s, 10 Hz
ROOM_S = 1.0


def replayed(program, rows: slice, shown_rows: np.ndarray):
    """The program with `rows` a REPLAY of the match frames shown_rows, cut into and out of."""
    program.replay[rows] = True
    program.shown_index[rows] = shown_rows
    program.cut[rows.start] = program.cut[rows.stop] = True
    program.shot_id[:] = np.cumsum(program.cut)
    return program


def test_a_replay_is_measured_at_the_moment_it_shows_and_counts_as_shown():
    match = duel()
    match.positions_world[KILL_ROW + 5 :, 1] += [100.0, 0.0, 0.0]  # b's body is carried far off after the kill
    program = replayed(side_view(match), slice(25, 35), np.arange(15, 25))
    bodies = BodySampler(match, np.random.default_rng(0))
    shown = measure_shown(program, bodies, Lens(), floor())
    assert shown[25:35, 1].min() >= 0.5 and shown[35:, 1].max() < 0.5  # b where the replayed moment has it
    assert kill_coverage(match, program, shown).covered.tolist() == [True]  # the kill itself was live
    assert replay_figures(match, program, shown, ROOM_S) == {
        "replays": 1,
        "shown": 1,
        "kills_with_room": 1,
        "kills_with_room_replayed": 1,
        "live_kills_missed_for_replay": 0,
    }
    assert program.digest() != side_view(match).digest()  # the replayed frames are in the digest
    program.cut[30] = True  # a cut within it (through a wall) goes on with the same replay
    assert replay_figures(match, program, shown, ROOM_S)["replays"] == 1


def test_a_replay_over_the_live_kill_misses_it_and_one_not_reaching_the_kill_is_not_shown():
    match = duel()
    program = replayed(side_view(match), slice(18, 28), np.arange(5, 15))  # the moments before the kill, during it
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor())
    assert kill_coverage(match, program, shown).covered.tolist() == [False]
    figures = replay_figures(match, program, shown, ROOM_S)
    assert figures["live_kills_missed_for_replay"] == 1 and figures["replays"] == 1 and figures["shown"] == 0


def test_a_kill_followed_by_another_within_the_room_leaves_none():
    match = duel()
    match = dataclasses.replace(match, events=[*match.events, MatchEvent("kill", "b", "a", 0, 2.5, "", np.zeros(3))])
    program = side_view(match)
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor())
    assert replay_figures(match, program, shown, ROOM_S)["kills_with_room"] == 1  # the second alone
    assert replay_figures(match, program, shown, 0.4)["kills_with_room"] == 2


def test_a_replay_reaching_back_over_two_kills_of_its_pair_replays_each_it_shows():
    """a kills b twice, 0.5 s apart; one replay shows both kills again: the second, with room
    (the first has none: the second follows within it), counts as replayed (the code before
    credited the replay to the first kill of its pair alone)."""
    match = duel()
    second = dataclasses.replace(match.events[0], time_s=2.5)
    match = dataclasses.replace(match, events=[*match.events, second])
    program = replayed(side_view(match), slice(26, 39), np.arange(14, 27))  # replays frames 14-26: both kills
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor())
    assert shown[26:39].min() >= 0.5
    figures = replay_figures(match, program, shown, ROOM_S)
    assert [figures[k] for k in ("replays", "shown", "kills_with_room", "kills_with_room_replayed")] == [1, 1, 1, 1]
    program = replayed(side_view(match), slice(26, 39), np.arange(10, 23))  # up to frame 22: the first kill alone
    assert replay_figures(match, program, shown, ROOM_S)["kills_with_room_replayed"] == 0


def test_a_replay_naming_its_killer_alone_before_the_kill_is_one_replay_of_its_pair():
    """A replay frames its killer alone in the build-up, then the pair (replays.py): one replay,
    of the pair's kill, shown; another pair's replay right after it is another."""
    match = duel()
    program = replayed(side_view(match), slice(25, 38), np.arange(10, 23))
    for row in range(25, 30):  # replayed rows 10-14: a alone
        program.subjects[row] = ("a",)
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor())
    figures = replay_figures(match, program, shown, ROOM_S)
    assert figures["replays"] == 1 and figures["shown"] == 1 and figures["kills_with_room_replayed"] == 1
    for row in (36, 37):  # not of its pair: a replay of its own from there
        program.subjects[row] = ("b", "c")
    assert replay_figures(match, program, shown, ROOM_S)["replays"] == 2


@pytest.mark.parametrize("killer", ["a", "b"])
def test_a_replay_in_either_ones_eyes_showing_the_other_counts_as_shown_with_the_eyes_rule(killer):
    """In a's eyes looking at b: the kill cam where a killed b, the victim's view where b killed a.
    Live, only the attacker's eyes cover the kill."""
    match = duel()  # a kills b at KILL_ROW, standing still: a's eye is the same at every moment
    victim = "b" if killer == "a" else "a"
    match.events[0] = dataclasses.replace(match.events[0], actor_id=killer, other_actor_id=victim)
    program = replayed(first_person_of_a(match), slice(25, 35), np.arange(15, 25))
    program.subjects[25:35] = [(killer, victim)] * 10  # a replay names the pair around the kill, killer first
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor())
    eyes = in_eyes_of(match, program)
    assert eyes[25:35].tolist() == [0] * 10 and shown[25:35, 1].min() >= 0.5 and shown[25:35, 0].max() < 0.5
    assert replay_figures(match, program, shown, ROOM_S)["shown"] == 0  # a's body is not in the picture
    figures = replay_figures(match, program, shown, ROOM_S, eyes)
    assert figures["shown"] == 1 and figures["kills_with_room_replayed"] == 1
    assert kill_coverage(match, program, shown, eyes).covered.tolist() == [killer == "a"]
