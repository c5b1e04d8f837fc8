"""The collector and the frame path: what a process keeps from its start is left out of every
full collection.

A full (generation 2) collection walks every tracked object of the process. The front's heap after
start (FastAPI's routes and models, gRPC, protobuf descriptors, the settings) is large enough that
one walk took about 70 ms on a 2-core machine, and requests that allocate a lot (a burst of refused
uploads: load_tests/oversize.py) trigger one every few seconds; every session's frame waited for
it. gc.freeze() moves the objects alive at the end of start into a permanent generation the
collector never walks, so a later full collection walks only what came after.

What comes after still triggers collections at a count of allocations, so inside whichever frame
crosses it: on the paced real 2on2 (issue 41's compute bar, p99 at most 5 ms) its worker's
collections took 0.5-3.4 ms (generation 0, 84 in 3 minutes), up to 17.6 ms (generation 1, 19) and
37 ms (generation 2, 3), in frames whose stages otherwise take 1.5 ms. The worker, when no request
waits, runs the collection the next trigger would run (`collect_ahead`), so the trigger falls in
idle time rather than in a frame.
"""

from __future__ import annotations

import gc


def freeze_startup_heap() -> None:
    """Collects once, then freezes what is left: call at the end of a long-lived process's start,
    before it answers frames. What start made and dropped is collected first, so only what lives on
    is frozen (never collected later; a cycle among start objects that becomes garbage would stay)."""
    gc.collect()
    gc.freeze()


def collect_ahead() -> None:
    """Runs now the collection the collector's next trigger would run, or nothing while the young
    generation is under half of its threshold; for idle time, between frames. The trigger (CPython's
    gc, when the young count passes its threshold) collects the oldest generation whose count is
    over its threshold, each judged on its own; of the oldest it skips the collections whose
    long-lived survivors are few, which Python does not show: run here, such a collection walks
    them in idle time."""
    counts, thresholds = gc.get_count(), gc.get_threshold()
    if counts[0] < thresholds[0] // 2:
        return
    gc.collect(next((g for g in (2, 1) if counts[g] > thresholds[g]), 0))
