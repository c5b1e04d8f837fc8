"""StageClock laps stages on the clock it is given, sums a stage lapped twice, and reports progress."""

from __future__ import annotations

import enum

import pytest

from camdirector.infra.stage_clock import StageClock


class _Stage(enum.Enum):
    A = "a"
    B = "b"


def _ticking(times_s):
    it = iter(times_s)
    return lambda: next(it)


def test_laps_sum_per_stage_on_the_given_clock_into_the_given_dict():
    timings = {"before": 9.0}
    clock = StageClock(clock=_ticking([10.0, 10.002, 10.005, 10.006]), timings_ms=timings)
    clock.done(_Stage.A)  # 2 ms
    clock.done(_Stage.B)  # 3 ms
    clock.done(_Stage.A)  # 1 ms more
    assert clock.timings_ms is timings
    assert timings == pytest.approx({"before": 9.0, "a": 3.0, "b": 3.0})


def test_progress_is_reported_after_each_stage_and_needs_its_fractions():
    seen = []
    clock = StageClock(seen.append, {_Stage.A: 0.25, _Stage.B: 1.0}, clock=_ticking([0.0, 1.0, 2.0]))
    clock.done(_Stage.A)
    clock.done(_Stage.B)
    assert seen == [0.25, 1.0] and clock.timings_ms == pytest.approx({"a": 1000.0, "b": 1000.0})
    with pytest.raises(ValueError, match="progress_after"):
        StageClock(seen.append)
