"""LoopWatch: how late the front's loop ran, from a clock it is given."""

from __future__ import annotations

import asyncio

from prometheus_client import CollectorRegistry, Histogram

from camdirector.front import loop_watch
from camdirector.front.loop_watch import LoopWatch


def test_a_late_wake_up_is_the_lag_shown_until_it_leaves_the_window():
    now = [100.0]
    histogram = Histogram("lag", "lag", registry=CollectorRegistry())
    watch = LoopWatch(histogram, clock=lambda: now[0])

    async def run() -> list[float]:
        watch.start()
        await asyncio.sleep(0)  # the watch asks to wake at 100 + PERIOD_S
        now[0] += 0.3  # and wakes 0.3 s on: 0.3 - PERIOD_S late
        await asyncio.sleep(loop_watch.PERIOD_S * 3)
        shown = [watch.recent_max_ms()]
        now[0] += loop_watch.WINDOW_S + 1.0
        shown.append(watch.recent_max_ms())
        watch.stop()
        return shown

    late_ms, later_ms = asyncio.run(run())
    assert late_ms == (0.3 - loop_watch.PERIOD_S) * 1e3
    assert later_ms == 0.0  # out of the window
    assert histogram.collect()[0].samples[-1].value >= 0.3 - loop_watch.PERIOD_S  # the sum of the lags observed
