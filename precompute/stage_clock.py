"""Per-stage wall time of an offline pipeline, with a progress callback after each stage."""
from __future__ import annotations

import enum
import time
from collections.abc import Callable, Mapping


class StageClock:
    """`done(stage)` records the time since the previous stage (or since construction) in
    `timings_ms[stage.value]` and reports `progress_after[stage]` (a fraction of the run)."""

    def __init__(self, progress: Callable[[float], None] | None, progress_after: Mapping[enum.Enum, float]):
        self.timings_ms: dict[str, float] = {}
        self._progress = progress
        self._progress_after = progress_after
        self._clock = time.perf_counter()

    def done(self, stage: enum.Enum) -> None:
        now = time.perf_counter()
        self.timings_ms[stage.value] = (now - self._clock) * 1e3
        self._clock = now
        if self._progress is not None:
            self._progress(self._progress_after[stage])
