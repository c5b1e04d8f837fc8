"""Per-stage wall time by laps: of an offline pipeline (with a progress callback after each stage),
and of one director frame (on the session's injected clock, into `FrameState.stage_ms`)."""

from __future__ import annotations

import enum
import time
from collections.abc import Callable, Mapping


class StageClock:
    """`done(stage)` adds the time since the previous `done` (or since construction) to
    `timings_ms[stage.value]`, in ms, and reports `progress_after[stage]` (a fraction of the run)
    when a progress callback is given.

    A stage that another interrupts (a frame's MOTION around its map stages) is lapped once per
    piece and sums them; the code between two laps belongs to the second. clock: seconds, any
    origin (the session's injected clock in the frame loop). timings_ms: the dict to fill (a
    frame's `stage_ms`), a new one when None.
    """

    def __init__(
        self,
        progress: Callable[[float], None] | None = None,
        progress_after: Mapping[enum.Enum, float] | None = None,
        *,
        clock: Callable[[], float] = time.perf_counter,
        timings_ms: dict[str, float] | None = None,
    ):
        if progress is not None and progress_after is None:
            raise ValueError("StageClock: a progress callback needs progress_after")
        self.timings_ms: dict[str, float] = {} if timings_ms is None else timings_ms
        self._progress = progress
        self._progress_after = progress_after
        self._now = clock
        self._last_s = clock()

    @property
    def last_s(self) -> float:
        """The clock's reading at the last `done` (or at construction), s: where the next lap starts."""
        return self._last_s

    def done(self, stage: enum.Enum) -> None:
        now_s = self._now()
        self.timings_ms[stage.value] = self.timings_ms.get(stage.value, 0.0) + (now_s - self._last_s) * 1e3
        self._last_s = now_s
        if self._progress is not None:
            assert self._progress_after is not None  # __init__ refuses a progress callback without it
            self._progress(self._progress_after[stage])
