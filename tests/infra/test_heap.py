"""freeze_startup_heap: what lives on is frozen, what start dropped is collected first;
collect_ahead: the collection the collector would run next, run now, or none while the young
generation is under half of its threshold."""

from __future__ import annotations

import gc
import weakref

import pytest

from camdirector.infra.heap import collect_ahead, freeze_startup_heap


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


YOUNG = 100_000  # the young generation's threshold in the test: far over what it allocates, so the collector never runs by itself


@pytest.mark.parametrize(
    ("young_made", "gen1_count", "gen2_count", "expected"),
    [
        (YOUNG // 4, 0, 0, None),  # under half the threshold: nothing yet
        (YOUNG // 2 + 1000, 0, 0, 0),
        (YOUNG // 2 + 1000, 3, 0, 0),  # at its threshold, not over it: not yet
        (YOUNG // 2 + 1000, 4, 0, 1),
        (YOUNG // 2 + 1000, 4, 4, 2),
        (YOUNG // 2 + 1000, 0, 4, 2),  # each generation judged on its own, as the collector does
    ],
)
def test_collect_ahead_runs_the_collection_the_next_trigger_would(young_made, gen1_count, gen2_count, expected):
    collected: list[int] = []

    def seen(phase: str, info: dict) -> None:
        if phase == "start":
            collected.append(info["generation"])

    thresholds = gc.get_threshold()
    gc.set_threshold(YOUNG, 3, 3)
    try:
        gc.collect()
        for _ in range(gen2_count):  # each collection of generation 1 counts one toward generation 2
            gc.collect(1)
        for _ in range(gen1_count):  # each of generation 0 counts one toward generation 1
            gc.collect(0)
        made = [[] for _ in range(young_made)]  # containers the collector tracks
        assert gc.get_count()[1:] == (gen1_count, gen2_count)
        gc.callbacks.append(seen)
        collect_ahead()
    finally:
        if seen in gc.callbacks:
            gc.callbacks.remove(seen)
        gc.set_threshold(*thresholds)
    assert collected == ([] if expected is None else [expected])
    del made
