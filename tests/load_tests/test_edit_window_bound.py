"""The edit window's offline bound (load_tests/edit_window_bound.py): its repair of short shots on
a hand-built program, with a judge that says which neighbour shows the subjects."""

from __future__ import annotations

import numpy as np

from camdirector.evaluation.match.measure import Program
from load_tests.edit_window_bound import repaired


def program(cuts: list[int], replay: list[int] = ()) -> Program:
    """Ten moments 1 s apart, cut at `cuts`; subjects name the shot (s0, s1, ...); positions x = row."""
    n = 10
    cut = np.zeros(n, dtype=bool)
    cut[cuts] = True
    shot = np.cumsum(cut)
    return Program(
        index=np.arange(n),
        time_s=np.arange(n, dtype=float),
        position=np.stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)], axis=1),
        rotation=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
        vertical_fov_deg=np.full(n, 50.0),
        cut=cut,
        shot_id=shot,
        subjects=[(f"s{k}",) for k in shot],
        overview=np.zeros(n, dtype=bool),
        shown_index=np.arange(n),
        replay=np.isin(np.arange(n), list(replay)),
    )


def judge_preferring(side: str):
    """A judge that finds the given neighbour ('before' or 'after') showing all, the other none;
    its poses are the neighbour's own, held."""

    def judge(p: Program, rows: np.ndarray, row: int):
        before = row < rows[0]
        shows = 1.0 if before == (side == "before") else 0.0
        k = len(rows)
        return shows, (np.repeat(p.position[row][None], k, 0), np.repeat(p.rotation[row][None], k, 0), np.full(k, 50.0))

    return judge


def test_a_short_shot_goes_to_the_shot_before_that_shows_its_subjects():
    p = program([3, 4, 8])  # shots [0, 3), [3, 4) (1 s), [4, 8), [8, 10)
    fixed, counts = repaired(p, judge_preferring("before"), 2.0)
    assert counts == {"to_the_shot_before": 1, "to_the_shot_after": 0, "left": 0}
    assert np.flatnonzero(fixed.cut).tolist() == [4, 8]
    assert fixed.subjects[3] == ("s0",) and fixed.position[3].tolist() == [2.0, 0.0, 0.0]
    assert p.cut[3] and p.subjects[3] == ("s1",)  # the program given is left as it was


def test_a_short_shot_goes_to_the_shot_after_when_that_shows_more():
    fixed, counts = repaired(program([3, 4, 8]), judge_preferring("after"), 2.0)
    assert counts["to_the_shot_after"] == 1
    assert np.flatnonzero(fixed.cut).tolist() == [3, 8]
    assert fixed.subjects[3] == ("s2",) and fixed.position[3].tolist() == [4.0, 0.0, 0.0]


def test_repairs_go_on_until_no_shot_is_short():
    # [3, 4) and [4, 5) both 1 s: the first given to the one before makes [0, 4), and [4, 5) is still short
    fixed, counts = repaired(program([3, 4, 5, 8]), judge_preferring("before"), 2.0)
    assert counts["to_the_shot_before"] == 2
    assert np.flatnonzero(fixed.cut).tolist() == [5, 8]


def test_a_live_short_shot_goes_only_to_a_live_neighbour():
    # [3, 4) live, [4, 8) a replay: the judge would take the replay, the live shot before gets it
    fixed, counts = repaired(program([3, 4, 8], replay=[4, 5, 6, 7]), judge_preferring("after"), 2.0)
    assert counts == {"to_the_shot_before": 1, "to_the_shot_after": 0, "left": 0}
    assert np.flatnonzero(fixed.cut).tolist() == [4, 8]


def test_a_replays_piece_goes_to_the_same_replay_going_on_and_no_other():
    p = program([3, 4, 8], replay=[3, 4, 5, 6, 7])  # a replay cut within at 4 (its frames go on)
    p.shown_index[3:8] = np.arange(100, 105)
    fixed, counts = repaired(p, judge_preferring("before"), 2.0)  # before it, live: not its kind
    assert counts == {"to_the_shot_before": 0, "to_the_shot_after": 1, "left": 0}
    assert np.flatnonzero(fixed.cut).tolist() == [3, 8]
    other = program([3, 4, 8], replay=[3, 4, 5, 6, 7])
    other.shown_index[3:8] = [100, 200, 201, 202, 203]  # [4, 8) replays another kill
    assert repaired(other, judge_preferring("before"), 2.0)[1] == {"to_the_shot_before": 0, "to_the_shot_after": 0, "left": 1}
