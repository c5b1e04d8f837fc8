"""Long work done in slices between requests: a computation runs in a greenlet that its owner
resumes for a few milliseconds at a time (a worker's idle moments, worker/table.py `idle_work`)
and that hands control back at its pause points once its slice is spent.

Why greenlets and not a thread: a thread computing a match session's plan (pipeline/match/drawn_plan.py)
would hold the GIL against the frames it is meant to stay out of the way of, in slices of the
interpreter's choosing; a greenlet runs only when resumed, so a frame never waits for it, and
what it computes cannot depend on how it was sliced (its inputs are fixed when it is drawn).

`pause(work)` is called inside long loops (shots.py `framed_seen`, one batch of ray casts) with the
work the loop's next step will do, in the owner's units (there: camera-point pairs). Outside a
sliced run, or inside one whose slice is not spent, it does nothing but read the clock and count
the work. Besides slices of time, a run can be taken up to an amount of work (`run_until`): where
it stops then depends on its inputs alone, never on the machine's speed, so an owner may decide
from it when a result is used (pipeline/match/drawn_plan.py: a plan is applied at the tick its work allows).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Generic, TypeVar, cast

import greenlet

T = TypeVar("T")


class _Slice(greenlet.greenlet):  # type: ignore[misc]  # greenlet ships no type information
    """The greenlet of one SlicedRun, carrying its deadlines for `pause`: a clock time and an
    amount of work, and the work done so far."""

    deadline_s = math.inf
    work_limit = math.inf
    work_done = 0.0
    clock: Callable[[], float] = staticmethod(time.perf_counter)


def pause(work: float = 0.0) -> None:
    """Hands control back to whoever resumed the current sliced run once its slice is spent or
    the next step's `work` would take it past its work limit (until resumed with room for it),
    then counts that work; a no-op elsewhere."""
    current = greenlet.getcurrent()
    if not isinstance(current, _Slice):
        return
    while current.work_done + work > current.work_limit or current.clock() >= current.deadline_s:
        current.parent.switch()
    current.work_done += work


class SlicedRun(Generic[T]):
    """`work()` run in slices: `step(budget_s)` resumes it until a pause point past the budget or
    its end, `finish()` runs it to its end; `result` once `done`. An exception in the work is
    raised by the step or finish that ran into it. Use it from one thread (greenlets are per
    thread); it cannot be pickled until finished (the owner drops it then)."""

    def __init__(self, work: Callable[[], T], clock: Callable[[], float] = time.perf_counter):
        self._greenlet = _Slice(self._main)
        self._greenlet.clock = clock
        self._work: Callable[[], T] | None = work
        self.done = False
        self.result: T | None = None

    def _main(self) -> None:
        work, self._work = self._work, None
        assert work is not None  # the greenlet runs _main once, and only SlicedRun.__init__ sets _work
        self.result = work()
        self.done = True

    @property
    def work(self) -> float:
        """The work counted so far (all of it once done), in the units of `pause`'s calls."""
        return self._greenlet.work_done

    def step(self, budget_s: float) -> bool:
        """Runs about budget_s more (until the first pause point past it); whether it is done."""
        if not self.done:
            self._resume(self._greenlet.clock() + budget_s, math.inf)
        return self.done

    def run_until(self, work: float) -> bool:
        """Runs it until its end or a step that would take its work past `work`; whether it
        ended within that work. The answer depends on the work alone, not on time or on the
        slices run before (which may have run past `work`)."""
        if not self.done and self.work < work:
            self._resume(math.inf, work)
        return self.done and self.work <= work

    def finish(self) -> T:
        """Runs it to its end; the result."""
        if not self.done:
            self._resume(math.inf, math.inf)
        return cast(T, self.result)  # done: work() returned it (a failed run raised above instead)

    def _resume(self, deadline_s: float, work_limit: float) -> None:
        self._greenlet.deadline_s, self._greenlet.work_limit = deadline_s, work_limit
        self._greenlet.parent = greenlet.getcurrent()  # pause() comes back here, whoever resumes it
        try:
            self._greenlet.switch()
        except BaseException:
            self.done = True  # a failed run is over: nothing to resume
            raise
