"""The collector and the frame path: what a process keeps from its start is left out of every
full collection.

A full (generation 2) collection walks every tracked object of the process. The front's heap after
start (FastAPI's routes and models, gRPC, protobuf descriptors, the settings) is large enough that
one walk took about 70 ms on a 2-core machine, and requests that allocate a lot (a burst of refused
uploads: load_tests/oversize.py) trigger one every few seconds; every session's frame waited for
it. gc.freeze() moves the objects alive at the end of start into a permanent generation the
collector never walks, so a later full collection walks only what came after.
"""

from __future__ import annotations

import gc


def freeze_startup_heap() -> None:
    """Collects once, then freezes what is left: call at the end of a long-lived process's start,
    before it answers frames. What start made and dropped is collected first, so only what lives on
    is frozen (never collected later; a cycle among start objects that becomes garbage would stay)."""
    gc.collect()
    gc.freeze()
