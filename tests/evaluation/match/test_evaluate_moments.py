"""eval-match keeps one reply per program moment: the last one, which stayed on air, cutting if any
reply of that moment cut (evaluate.py `_one_row_per_moment`); and says where its short shots and
its moments of nobody are, with the flags the replies gave there (`_short_shots`, `_runs_of`)."""

from __future__ import annotations

import numpy as np

from camdirector.evaluation.match.evaluate import _one_row_per_moment, _runs_of, _short_shots
from camdirector.evaluation.match.measure import Program


def reply(frame: int, x: float, cut: bool) -> tuple:
    return (frame, frame / 30.0, (x, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 50.0, cut, 0, (), 1.0, ())


def test_a_moment_answered_twice_keeps_its_last_pose_and_any_cut():
    rows = [reply(1, 0.0, True), reply(2, 1.0, False), reply(2, 9.0, True), reply(3, 9.5, False), reply(2, 5.0, False)]
    kept = _one_row_per_moment(rows)
    assert [(r[0], r[2][0], r[5]) for r in kept] == [(1, 0.0, True), (2, 9.0, True), (3, 9.5, False)]
    again = _one_row_per_moment([reply(1, 0.0, True), reply(2, 1.0, True), reply(2, 1.5, False)])
    assert [(r[0], r[2][0], r[5]) for r in again] == [(1, 0.0, True), (2, 1.5, True)]


def program_cut_at(times_s: list[float], cut_times_s: list[float]) -> Program:
    """A program with a moment at each of times_s and a cut at each of cut_times_s (and the first)."""
    n = len(times_s)
    time_s = np.array(times_s)
    cut = np.isin(time_s, cut_times_s)
    cut[0] = True
    subjects = [("a",) if t < 3.0 else ("b",) for t in times_s]
    return Program(
        index=np.arange(n),
        time_s=time_s,
        position=np.zeros((n, 3)),
        rotation=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
        vertical_fov_deg=np.full(n, 50.0),
        cut=cut,
        shot_id=np.cumsum(cut),
        subjects=subjects,
        overview=np.zeros(n, dtype=bool),
        shown_index=np.arange(n),
        replay=np.zeros(n, dtype=bool),
    )


def test_each_short_shot_is_named_with_the_flags_at_the_cuts_that_start_and_end_it():
    times = [0.5 * k for k in range(12)]  # 0 .. 5.5 s
    program = program_cut_at(times, [3.0, 4.5])  # shots 0-3 s, 3-4.5 s (short), 4.5- (the last, left out)
    flags = [()] * 12
    flags[6], flags[9] = ("moved_inside_level", "cut_through_wall"), ("cut_to_seen_place",)
    assert _short_shots(program, flags) == [
        {
            "time_s": 3.0,
            "length_s": 1.5,
            "subjects": ["b"],
            "flags_at_cut": ["moved_inside_level", "cut_through_wall"],
            "flags_at_end": ["cut_to_seen_place"],
        }
    ]
    assert _short_shots(program, [])[0]["flags_at_cut"] == []  # a program file carries no flags
    assert _short_shots(program_cut_at(times, [3.0]), flags) == []


def test_moments_of_nobody_are_told_as_runs_with_how_often_each_flag_came():
    program = program_cut_at([0.5 * k for k in range(10)], [])
    flags = [("held_before_wall",), ("held_before_wall", "lens_widened"), (), (), (), ("pose_held",), (), (), (), ()]
    runs = _runs_of(program, np.array([0, 1, 5, 6]), flags)
    assert runs == [
        {"time_s": 0.0, "moments": 2, "subjects": ["a"], "flags": {"held_before_wall": 2, "lens_widened": 1}},
        {"time_s": 2.5, "moments": 2, "subjects": ["a"], "flags": {"pose_held": 1}},
    ]
    assert _runs_of(program, np.zeros(0, dtype=np.int64), flags) == []
