"""freeze_startup_heap: what lives on is frozen, what start dropped is collected first."""

from __future__ import annotations

import gc
import weakref

from camdirector.infra.heap import freeze_startup_heap


class _Node:
    def __init__(self) -> None:
        self.other: _Node | None = None


def test_garbage_is_collected_and_the_living_are_frozen():
    kept = _Node()
    dropped, partner = _Node(), _Node()
    dropped.other, partner.other = partner, dropped  # a cycle: only a collection frees it
    gone = weakref.ref(dropped)
    del dropped, partner
    before = gc.get_freeze_count()
    try:
        freeze_startup_heap()
        assert gone() is None  # collected before the freeze, not kept forever
        assert gc.get_freeze_count() > before
        # a full collection walks only what comes after: what lived on is in none of the generations
        assert not any(o is kept for generation in range(3) for o in gc.get_objects(generation=generation))
        made_after = _Node()
        assert any(o is made_after for o in gc.get_objects(generation=0))
    finally:
        gc.unfreeze()
