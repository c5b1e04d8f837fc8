"""infra/slices.py: a computation run in slices of time, or up to an amount of work."""

from __future__ import annotations

import itertools

import pytest

from camdirector.infra.slices import SlicedRun, pause


def _counting(steps: list[float], reached: list[int]):
    """Work that pauses before each step with the step's work and records how many steps it reached."""

    def work() -> str:
        for k, step in enumerate(steps):
            pause(step)
            reached.append(k)
        return "done"

    return work


def test_pause_outside_a_sliced_run_does_nothing():
    pause(1e12)  # no run to hand back to, no limit to keep


def test_run_until_stops_before_the_step_that_would_pass_the_work_and_goes_on_from_there():
    reached: list[int] = []
    run = SlicedRun(_counting([3.0, 3.0, 3.0, 3.0], reached))
    assert not run.run_until(7.0)  # 3 + 3 fit, a third would make 9
    assert reached == [0, 1] and run.work == 6.0 and not run.done
    assert not run.run_until(7.0)  # no room: nothing more runs
    assert reached == [0, 1]
    assert not run.run_until(9.5)
    assert reached == [0, 1, 2]
    assert run.run_until(100.0) and run.result == "done" and run.work == 12.0


def test_whether_run_until_reaches_the_end_does_not_depend_on_the_time_slices_before_it():
    """A clock that moves 1 a read: a time slice of 1.5 runs one step. However many slices ran
    first (none, some, all of them), the run has not ended within 9 of its 10 steps' 20, and has
    within 20."""
    ticks = itertools.count()
    for slices in (0, 2, 5, 10):
        reached: list[int] = []
        run = SlicedRun(_counting([2.0] * 10, reached), clock=lambda: float(next(ticks)))
        for _ in range(slices):
            run.step(1.5)
        assert len(reached) == slices
        assert not run.run_until(9.0)
        assert run.run_until(20.0) and run.work == 20.0 and len(reached) == 10


def test_time_slices_run_past_the_work_of_an_earlier_run_until():
    reached: list[int] = []
    run = SlicedRun(_counting([1.0] * 4, reached))
    assert not run.run_until(2.0)
    assert run.step(1.0)  # idle moments are not held to any work
    assert reached == [0, 1, 2, 3] and run.work == 4.0
    assert not run.run_until(3.0) and run.run_until(4.0)  # ended, but not within 3


def test_an_exception_in_the_work_is_raised_by_the_call_that_ran_into_it():
    def failing() -> None:
        pause(1.0)
        raise RuntimeError("boom")

    run = SlicedRun(failing)
    assert not run.run_until(0.5)
    with pytest.raises(RuntimeError, match="boom"):
        run.run_until(5.0)
    assert run.done
