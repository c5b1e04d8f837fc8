"""eval-match keeps one reply per program moment: the last one, which stayed on air, cutting if any
reply of that moment cut (evaluate.py `_one_row_per_moment`)."""

from __future__ import annotations

from camdirector.evaluation.match.evaluate import _one_row_per_moment


def reply(frame: int, x: float, cut: bool) -> tuple:
    return (frame, frame / 30.0, (x, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 50.0, cut, 0, (), 1.0, ())


def test_a_moment_answered_twice_keeps_its_last_pose_and_any_cut():
    rows = [reply(1, 0.0, True), reply(2, 1.0, False), reply(2, 9.0, True), reply(3, 9.5, False), reply(2, 5.0, False)]
    kept = _one_row_per_moment(rows)
    assert [(r[0], r[2][0], r[5]) for r in kept] == [(1, 0.0, True), (2, 9.0, True), (3, 9.5, False)]
    again = _one_row_per_moment([reply(1, 0.0, True), reply(2, 1.0, True), reply(2, 1.5, False)])
    assert [(r[0], r[2][0], r[5]) for r in again] == [(1, 0.0, True), (2, 1.5, True)]
