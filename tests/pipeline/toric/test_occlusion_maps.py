"""OcclusionMaps moves its occluder scene only for the updates that build maps, to the poses of the
frame that drew the update, with velocities by finite differences between that frame and the one
before it; an amortized update's maps are computed apart (do_deferred_work, the scene's move with
them) and applied apply_after_frames frames later, a refill's at once."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import box, capsule
from camdirector.geometry.toric import composition_angle, make_torus
from camdirector.geometry.transforms import RigidTransform
from camdirector.infra.stage_clock import StageClock
from camdirector.pipeline.style import MapBackendChoice, Style, VisibilityMode
from camdirector.pipeline.toric.occlusion_maps import OcclusionMaps
from camdirector.pipeline.toric.target_sampling import TargetSampler

DT_S = 1.0 / 60.0
ALPHA = composition_angle((-1.0 / 3.0, 0.0), (1.0 / 3.0, 0.0), Lens())


def _pose(x: float, yaw_rad: float = 0.0) -> RigidTransform:
    return RigidTransform(np.array([x, 1.0, 2.0]), Rotation.from_euler("y", yaw_rad).as_quat())


@pytest.fixture
def maps():
    rng = np.random.default_rng(0)
    dynamic = {name: (box((0.5, 0.5, 0.5)), _pose(0.0)) for name in ("spinner", "slider", "still", "stopper")}
    made = OcclusionMaps(
        [box((20.0, 0.1, 20.0))],
        dynamic,
        TargetSampler([capsule(0.3, 1.8)], rng),
        Style(visibility=VisibilityMode.ANTICIPATION, map_resolution=16, map_backend=MapBackendChoice.EMBREE),
        rng,
    )
    yield made
    made.close()


def _update(maps: OcclusionMaps, time_s: float) -> dict[str, float]:
    """The stage timings of one update (PROJECTION and AMAP: maps computed in it)."""
    actor = RigidTransform(np.array([0.0, 0.9, 0.0]))
    torus = make_torus(actor.position_world, actor.position_world + [2.5, 0.0, 0.0], ALPHA)
    timings: dict[str, float] = {}
    maps.update(torus, 1.8, 1.2, time_s, [actor], ["actor"], StageClock(timings_ms=timings))
    return timings


def _drawn(maps: OcclusionMaps, time_s: float, compute: bool = True) -> bool:
    """Whether the update at time_s was due (its maps deferred); with `compute` its maps are
    computed then, the scene moved for them, as an idle moment would."""
    _update(maps, time_s)
    drawn = maps.has_deferred_work
    if drawn and compute:
        maps.do_deferred_work(whole=False)
    return drawn


def test_scene_moves_on_map_builds_only_with_the_last_step_as_velocity(maps):
    assert "projection" in _update(maps, 0.0)  # the first update builds every map
    for frame in range(1, 4):
        time_s = frame * DT_S
        moved = [("slider", _pose(0.6 * frame)), ("spinner", _pose(0.0, 0.3 * frame)), ("actor", _pose(9.0))]
        if frame < 3:
            moved.append(("stopper", _pose(0.2 * frame)))  # stops after frame 2
        maps.ingest(moved, time_s)
        built = _drawn(maps, time_s)
        slider = maps.scene.dynamic["slider"]
        # between builds the scene keeps the poses of the last build
        assert built or slider.transform.position_world[0] == 0.0
    built = False
    while not built:  # on to the next build, nothing moving
        time_s += DT_S
        maps.ingest([], time_s)
        built = _drawn(maps, time_s)
    scene = maps.scene.dynamic
    np.testing.assert_allclose(scene["slider"].transform.position_world, [1.8, 1.0, 2.0])
    np.testing.assert_allclose(scene["stopper"].transform.position_world, [0.4, 1.0, 2.0])
    assert not any(o.linear_velocity_m_s.any() or o.angular_velocity_rad_s.any() for o in scene.values())


def test_velocity_of_the_latest_step_reaches_the_scene(maps):
    _update(maps, 0.0)
    time_s, frame, built = 0.0, 0, False
    while not built:
        frame += 1
        time_s = frame * DT_S
        maps.ingest(
            [("slider", _pose(0.6 * frame)), ("spinner", _pose(0.0, 0.3 * frame))]
            + ([("stopper", _pose(0.2 * frame))] if frame == 1 else []),
            time_s,
        )
        built = _drawn(maps, time_s, compute=False)
    assert frame > 1  # maps are built one frame in several
    scene = maps.scene.dynamic
    assert scene["slider"].transform.position_world[0] == 0.0  # drawn, not computed: the scene has not moved
    maps.ingest([("slider", _pose(-5.0)), ("spinner", _pose(0.0, -1.0))], time_s + DT_S)  # a later frame
    assert maps.do_deferred_work(whole=False)  # the maps, the scene moved for them: to the drawing frame's poses
    np.testing.assert_allclose(scene["slider"].transform.position_world, [0.6 * frame, 1.0, 2.0])
    np.testing.assert_allclose(scene["slider"].linear_velocity_m_s, [0.6 / DT_S, 0.0, 0.0], rtol=1e-9)
    np.testing.assert_allclose(scene["spinner"].angular_velocity_rad_s, [0.0, 0.3 / DT_S, 0.0], rtol=1e-9)
    np.testing.assert_allclose(scene["stopper"].transform.position_world, [0.2, 1.0, 2.0])
    assert not scene["stopper"].linear_velocity_m_s.any() and not scene["still"].linear_velocity_m_s.any()


def test_an_amortized_update_is_computed_apart_and_applied_on_a_later_frame_a_refill_at_once(maps):
    first = _update(maps, 0.0)
    assert "projection" in first and "amap" in first and not maps.has_deferred_work  # the refill: every map now
    a_map = maps.amap.a_map.copy()
    time_s = 0.0
    while not maps.has_deferred_work:
        time_s += DT_S
        assert "projection" not in _update(maps, time_s)
    drawn_s = time_s
    assert maps.do_deferred_work(whole=False) and maps.has_deferred_work  # its maps: A_s still to do
    assert maps.do_deferred_work(whole=False) and maps.has_deferred_work  # A_s: the aggregate still to do
    assert maps.do_deferred_work(whole=False) and not maps.has_deferred_work  # the aggregate, made ahead
    assert not maps.do_deferred_work()
    for _ in range(maps.amap.settings.apply_after_frames - 1):  # computed, not yet the search's
        time_s += DT_S
        assert _update(maps, time_s) == {}
        np.testing.assert_array_equal(maps.amap.a_map, a_map)
    time_s += DT_S
    timings = _update(maps, time_s)
    assert "amap" in timings and "projection" not in timings  # applied on its frame, computed before
    assert not np.array_equal(maps.amap.a_map, a_map)
    made_at = maps.amap.computed_at_s  # one target: one slot refreshed, stamped with the time it was due at
    assert sorted(made_at) == [0.0] * (len(made_at) - 1) + [drawn_s]


def test_a_deferred_update_nobody_computed_is_computed_on_its_frame(maps):
    _update(maps, 0.0)
    time_s = 0.0
    while not maps.has_deferred_work:
        time_s += DT_S
        _update(maps, time_s)
    for _ in range(maps.amap.settings.apply_after_frames - 1):
        time_s += DT_S
        assert _update(maps, time_s) == {}
    timings = _update(maps, time_s + DT_S)
    assert "projection" in timings and "amap" in timings and not maps.has_deferred_work
