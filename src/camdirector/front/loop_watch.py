"""How late the front's event loop runs: the loop that answers every frame of the node (gRPC,
ZeroMQ, HTTP). A task asks to wake every PERIOD_S and notes how much later it woke; /healthz shows
the largest lag of the last WINDOW_S, and /metrics the distribution (`camdirector_loop_lag_seconds`).
The balancer's checks are answered by a thread of the node's own (front/live_check.py), which
reads `last_wake_s` and answers "stalled" once the loop has not woken for seconds; the lag says how
close a node came to that, and a records database or a Redis that is slow does not show in it
(their calls are made off the loop: access/guard.py, worker/checkpoint_writer.py).
"""

from __future__ import annotations

import asyncio
import collections
import time
from collections.abc import Callable

from prometheus_client import Histogram

PERIOD_S = 0.05  # the watch's wake-up interval, s
WINDOW_S = 10.0  # /healthz's lag is the largest of this last stretch, s


class LoopWatch:
    """The lag of the running loop (module docstring); `histogram` gets every measure, s."""

    def __init__(self, histogram: Histogram, clock: Callable[[], float] = time.monotonic) -> None:
        self._histogram = histogram
        self._clock = clock
        self._recent: collections.deque[tuple[float, float]] = collections.deque()  # (when, lag), s
        self._task: asyncio.Task | None = None
        # when the loop last woke, s on `clock`'s time line; read by another thread (one float: atomic)
        self.last_wake_s = clock()

    def start(self) -> None:
        self._task = asyncio.create_task(self._watch())

    def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()

    def recent_max_ms(self) -> float:
        """The largest lag of the last WINDOW_S, ms (0 before the first measure)."""
        horizon = self._clock() - WINDOW_S
        return max((lag for when, lag in self._recent if when >= horizon), default=0.0) * 1e3

    async def _watch(self) -> None:
        while True:
            due = self._clock() + PERIOD_S
            await asyncio.sleep(PERIOD_S)
            now = self._clock()
            self.last_wake_s = now
            lag = max(0.0, now - due)
            self._histogram.observe(lag)
            self._recent.append((now, lag))
            while self._recent and self._recent[0][0] < now - WINDOW_S:
                self._recent.popleft()
