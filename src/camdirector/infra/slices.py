"""Long work done in slices between requests: a computation runs in a greenlet that its owner
resumes for a few milliseconds at a time (a worker's idle moments, worker/table.py `idle_work`)
and that hands control back at its pause points once its slice is spent.

Why greenlets and not a thread: a thread computing a match session's plan (pipeline/match/rig.py)
would hold the GIL against the frames it is meant to stay out of the way of, in slices of the
interpreter's choosing; a greenlet runs only when resumed, so a frame never waits for it, and
what it computes cannot depend on how it was sliced (its inputs are fixed when it is drawn).

`pause()` is called inside long loops (shots.py `framed_seen`, one batch of ray casts). Outside a
sliced run, or inside one whose slice is not spent, it does nothing but read the clock.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Generic, TypeVar

import greenlet

T = TypeVar("T")


class _Slice(greenlet.greenlet):
    """The greenlet of one SlicedRun, carrying its deadline for `pause`."""

    deadline_s = math.inf
    clock: Callable[[], float] = staticmethod(time.perf_counter)


def pause() -> None:
    """Hands control back to whoever resumed the current sliced run once its slice is spent; a
    no-op elsewhere."""
    current = greenlet.getcurrent()
    if isinstance(current, _Slice) and current.clock() >= current.deadline_s:
        current.parent.switch()


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
        self.result = work()
        self.done = True

    def step(self, budget_s: float) -> bool:
        """Runs about budget_s more (until the first pause point past it); whether it is done."""
        if not self.done:
            self._resume(self._greenlet.clock() + budget_s)
        return self.done

    def finish(self) -> T:
        """Runs it to its end; the result."""
        if not self.done:
            self._resume(math.inf)
        return self.result

    def _resume(self, deadline_s: float) -> None:
        self._greenlet.deadline_s = deadline_s
        self._greenlet.parent = greenlet.getcurrent()  # pause() comes back here, whoever resumes it
        try:
            self._greenlet.switch()
        except BaseException:
            self.done = True  # a failed run is over: nothing to resume
            raise
