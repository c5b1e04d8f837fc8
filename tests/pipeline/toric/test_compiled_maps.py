"""CompiledOcclusionMaps computes an amortized update on the process's maps thread, to the numbers
the session's own thread makes of it; the session's thread takes an update back that the maps
thread has not begun, and waits for one it has before anything the update uses changes: a cut, a
style, a snapshot, the update's own frame (which also hears its error)."""

from __future__ import annotations

import pickle
import threading
from dataclasses import replace

import numpy as np
import pytest

from camdirector.geometry.meshes import box, capsule
from camdirector.geometry.toric_maps.native import hand_updates_apart, share_texels
from camdirector.pipeline.style import MaskKind, Style, VisibilityMode
from camdirector.pipeline.toric.compiled_maps import CompiledOcclusionMaps, maps_thread
from camdirector.pipeline.toric.occlusion_maps import OcclusionMaps
from camdirector.pipeline.toric.target_sampling import TargetSampler
from tests.pipeline.toric.test_occlusion_maps import DT_S, _pose, _update

STYLE = Style(visibility=VisibilityMode.ANTICIPATION, map_resolution=32)  # 2 maps of 32 x 32: rays enough to share


class _OnItsThread(CompiledOcclusionMaps):
    """The compiled maps with every update computed on the session's thread (idle moments or its frame)."""

    _start = OcclusionMaps._start


def _made(cls: type[CompiledOcclusionMaps]) -> CompiledOcclusionMaps:
    rng = np.random.default_rng(3)
    # the walls cross the line from the actor (the origin) to the torus' B (x = 2.5) as they move
    dynamic = {name: (box((0.4, 3.0, 0.4)), _pose(0.0)) for name in ("slider", "spinner")}
    return cls([box((20.0, 0.1, 20.0))], dynamic, TargetSampler([capsule(0.3, 1.8)], rng), STYLE, rng)


def _frame(maps: CompiledOcclusionMaps, frame: int) -> dict[str, float]:
    """The frame's stage laps."""
    time_s = frame * DT_S
    maps.ingest([("slider", _pose(-1.0 + 0.05 * frame)), ("spinner", _pose(1.5 - 0.03 * frame, 0.1 * frame))], time_s)
    return _update(maps, time_s)


def _in_flight(maps: CompiledOcclusionMaps):
    """The deferred update's Future on the maps thread, else None."""
    return None if maps._deferred is None else maps._deferred.computing


@pytest.fixture
def threaded():
    hand_updates_apart(True)  # as the front's table of `serve --workers 0` says
    made = _made(CompiledOcclusionMaps)
    yield made
    made.close()
    hand_updates_apart(False)


def test_a_process_that_does_not_say_so_computes_its_updates_on_the_sessions_thread():
    made = _made(CompiledOcclusionMaps)  # a worker process's: its cores are its workers'
    try:
        for frame in range(12):
            _frame(made, frame)
            assert _in_flight(made) is None
        assert made.amap.computed_at_s.max() > 0.0  # an amortized update came and went
    finally:
        made.close()


def test_the_maps_thread_makes_the_numbers_the_sessions_thread_makes(threaded):
    own = _made(_OnItsThread)
    handed = 0
    share_texels(2)  # the session's thread shares its rays with another; the maps thread keeps to one
    try:
        for frame in range(90):
            _frame(threaded, frame)
            _frame(own, frame)
            if _in_flight(threaded) is not None:
                handed += 1
                assert own.has_deferred_work and _in_flight(own) is None
            np.testing.assert_array_equal(threaded.amap.a_map, own.amap.a_map)
            np.testing.assert_array_equal(threaded.amap.computed_at_s, own.amap.computed_at_s)
    finally:
        share_texels(1)
        own.close()
    assert handed >= 10  # every amortized update went to the thread
    assert 0.0 < float(threaded.amap.a_map.max())  # the walls were seen: the numbers compared are not all zero


def _drawn(maps: CompiledOcclusionMaps, frame: int) -> tuple[int, object]:
    """Frames on until an update is handed to the maps thread: the frame after, and its Future."""
    while _in_flight(maps) is None:
        frame += 1
        _frame(maps, frame)
    return frame, _in_flight(maps)


def test_a_snapshot_a_cut_and_a_style_wait_for_the_maps_thread(threaded):
    frame, _ = _drawn(threaded, 0)
    copy = pickle.loads(pickle.dumps(threaded))  # as a checkpoint's snapshot pickles the rig
    assert _in_flight(threaded) is None and _in_flight(copy) is None
    assert copy._deferred.aggregate is not None  # computed, ready for its frame
    np.testing.assert_array_equal(copy._deferred.aggregate.a_map, threaded._deferred.aggregate.a_map)
    copy.close()

    frame, computing = _drawn(threaded, frame)
    threaded.invalidate()
    assert computing.done() and threaded._deferred is None

    frame, computing = _drawn(threaded, frame)
    threaded.set_style(replace(STYLE, mask=MaskKind.HARD_BEHIND))
    assert computing.done() and threaded._deferred.aggregate is not None


def test_an_update_the_maps_thread_has_not_begun_is_taken_back_by_an_idle_moment(threaded):
    frame, _ = _drawn(threaded, 0)
    _frame(threaded, frame + 1)  # applied
    busy = threading.Event()
    blocker = maps_thread().submit(busy.wait)  # the maps thread on another session's update
    try:
        frame, computing = _drawn(threaded, frame + 1)
        assert threaded.has_deferred_work  # pending: this thread's idle moments may take it
        assert threaded.do_deferred_work(whole=False)  # taken back: its maps computed here
        assert computing.cancelled() and _in_flight(threaded) is None
        assert threaded.do_deferred_work(whole=False) and threaded.do_deferred_work(whole=False)  # A_s, aggregate
        assert not threaded.has_deferred_work and threaded._deferred.aggregate is not None
    finally:
        busy.set()
    blocker.result()


def test_the_updates_frame_laps_the_same_stages_whichever_thread_computed_it(threaded):
    """A frame's laps are its diagnostics: they must not depend on the threads' timing."""
    frame, computing = _drawn(threaded, 0)
    computing.exception()  # computed on the maps thread
    joined = _frame(threaded, frame + 1)
    busy = threading.Event()
    blocker = maps_thread().submit(busy.wait)
    try:
        frame, computing = _drawn(threaded, frame + 1)
        taken_back = _frame(threaded, frame + 1)  # computed on this frame
        assert computing.cancelled()
    finally:
        busy.set()
    blocker.result()
    assert set(joined) == set(taken_back) == {"amap"}


def test_an_error_on_the_maps_thread_is_raised_on_the_updates_frame_and_the_thread_goes_on(threaded, monkeypatch):
    frame, _ = _drawn(threaded, 0)
    _frame(threaded, frame + 1)  # applied
    with monkeypatch.context() as patched:
        patched.setattr(threaded.backend, "compute", _refuse)
        frame, computing = _drawn(threaded, frame + 1)
        computing.exception()  # let it fail before the patch goes
    with pytest.raises(RuntimeError, match="no rays today"):
        _frame(threaded, frame + 1)
    frame, computing = _drawn(threaded, frame + 1)  # the next update, on the same thread
    assert computing.exception() is None  # waits for it: computed there
    _frame(threaded, frame + 1)
    assert threaded._deferred is None  # applied


def _refuse(*args: object, **kwargs: object) -> None:
    raise RuntimeError("no rays today")
