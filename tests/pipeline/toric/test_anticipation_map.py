"""The occlusion anticipation map (pipeline/toric/anticipation_map.py): the amortized schedule, the
masked aggregate of the predictions, the settings' validation, and the documented per-frame recipe."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import box, cylinder, sphere
from camdirector.geometry.toric import composition_angle, make_torus
from camdirector.geometry.toric_maps import MapWindow, OccluderScene, ShadowVelocityMaps, WindowSettings
from camdirector.geometry.toric_maps.embree import EmbreeMapBackend
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.style import MaskKind
from camdirector.pipeline.toric.anticipation_map import AnticipationMap
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.style_masks import StyleMaskSettings, behind_theta_rad
from camdirector.pipeline.toric.target_sampling import TargetSampler, TargetSamplingSettings

ALPHA = composition_angle((-1.0 / 3.0, 0.0), (1.0 / 3.0, 0.0), Lens())
TORUS = make_torus((0.0, 1.0, 0.0), (2.5, 1.0, 0.0), ALPHA)


def _window(n: int, step_theta: float = 0.02, step_phi: float = 0.02, theta0: float = 1.0, phi0: float = 0.5) -> MapWindow:
    return MapWindow(theta0, phi0, step_theta, step_phi, n)


# -- the amortized schedule (section 6) --------------------------------------------------------------


def _maps(window: MapWindow, count: int, value: float) -> ShadowVelocityMaps:
    n = window.resolution
    shadow = np.full((count, n, n), value, np.float32)
    return ShadowVelocityMaps(
        window, shadow, np.zeros((count, n, n, 2), np.float32), np.where(shadow > 0, 1.0, np.inf).astype(np.float32)
    )


SMALL = AnticipationSettings(window=WindowSettings(resolution=16))


def test_schedule_fills_everything_first_then_one_map_per_target_every_w_over_r():
    amap = AnticipationMap(2, SMALL)
    r, period = SMALL.samples_per_target, SMALL.update_period_s
    assert period == pytest.approx(0.1)
    window = _window(16)
    assert amap.due(0.0) and amap.next_slots() == list(range(2 * r))
    amap.refresh(0.0, amap.next_slots(), _maps(window, 2 * r, 0.0), TORUS)
    refreshed, t = [], 0.0
    frame_s = 1.0 / 60.0
    for frame in range(1, 6 * 2 * r + 1):  # two full rounds at 60 fps
        t = frame * frame_s
        if amap.due(t):
            slots = amap.next_slots()
            refreshed.append((round(t, 4), slots))
            amap.refresh(t, slots, _maps(window, len(slots), 0.0), TORUS)
    times = [when for when, _ in refreshed]
    assert np.allclose(np.diff(times), period, atol=frame_s + 1e-9)  # one update per W / r
    assert [slots for _, slots in refreshed[:r]] == [[s, r + s] for s in range(r)]
    assert [slots for _, slots in refreshed[r : 2 * r]] == [[s, r + s] for s in range(r)]
    # Every map is at most W old once the schedule runs.
    assert np.nanmax(t - amap.computed_at_s) <= SMALL.horizon_s + 1e-9


def test_schedule_recovers_from_time_going_back_long_gaps_and_cuts():
    amap = AnticipationMap(1, SMALL)
    window = _window(16)
    amap.refresh(10.0, amap.next_slots(), _maps(window, SMALL.samples_per_target, 0.0), TORUS)
    assert amap.next_slots() == [0] and not amap.due(10.05) and amap.due(10.1)
    assert amap.due(9.0)  # time went back
    amap.refresh(20.0, [0], _maps(window, 1, 0.0), TORUS)  # a long gap
    assert not amap.due(20.05) and amap.due(20.1)
    amap.invalidate()
    assert amap.due(20.01) and amap.next_slots() == list(range(SMALL.samples_per_target))


def test_aggregate_is_the_mean_of_the_predictions_with_the_mask_on_top():
    amap = AnticipationMap(2, SMALL)
    window = _window(16)
    values = np.linspace(0.0, 1.0, 2 * SMALL.samples_per_target)
    n = window.resolution
    shadow = (np.arange(n * n).reshape(n, n) % 3 == 0).astype(np.float32)
    maps = ShadowVelocityMaps(
        window,
        shadow[None].repeat(len(values), 0) * values[:, None, None].astype(np.float32),
        np.zeros((len(values), n, n, 2), np.float32),
        np.zeros((len(values), n, n), np.float32),
    )
    amap.refresh(0.0, range(len(values)), maps, TORUS)
    np.testing.assert_allclose(amap.a_map, shadow * values.mean(), atol=1e-6)  # (1 / 2r) sum of A_s
    assert np.all(amap.coverage == 1.0)
    amap.set_mask(StyleMaskSettings(kind=MaskKind.HARD_BEHIND))
    assert np.all(amap.a_map[window.grid()[0] < behind_theta_rad(TORUS.alpha)] == 1.0)


def test_older_maps_are_shifted_into_the_newest_window():
    amap = AnticipationMap(1, SMALL)
    base = _window(16)
    amap.refresh(0.0, amap.next_slots(), _maps(base, SMALL.samples_per_target, 1.0), TORUS)
    moved = MapWindow(base.theta_min_rad + 4 * base.theta_step_rad, base.phi_min_rad, base.theta_step_rad, base.phi_step_rad, 16)
    amap.refresh(0.1, [0], _maps(moved, 1, 0.0), TORUS)
    assert amap.window == moved
    r = SMALL.samples_per_target
    np.testing.assert_allclose(amap.a_map[:12], (r - 1) / r, atol=1e-6)  # old maps cover the first 12 rows
    np.testing.assert_allclose(amap.a_map[12:], 0.0)  # only the new, empty map there
    np.testing.assert_allclose(amap.coverage[:12], 1.0)
    np.testing.assert_allclose(amap.coverage[12:], 1.0 / r)
    i, j = np.meshgrid(np.arange(16), np.arange(16), indexing="ij")
    theta, phi = moved.angles(i, j)
    np.testing.assert_allclose(amap.lookup(theta, phi), amap.a_map, atol=1e-6)
    assert np.isnan(amap.lookup(moved.theta_min_rad - 1.0, phi[0, 0]))


def test_an_aggregate_made_ahead_is_the_one_store_makes_and_is_dropped_once_the_map_changed():
    """`prepare` (a deferred update's aggregate, made in idle time) gives `store` the bits it would
    form itself; made before a change of the map (here its mask), it is not used."""
    base = _window(16)
    moved = MapWindow(base.theta_min_rad + 3 * base.theta_step_rad, base.phi_min_rad, base.theta_step_rad, base.phi_step_rad, 16)
    r = SMALL.samples_per_target
    rng = np.random.default_rng(5)
    first = _maps(base, r, 0.0)
    first.shadow[:] = rng.random(first.shadow.shape, dtype=np.float32)
    later = _maps(moved, 1, 0.0)
    later.shadow[:] = rng.random(later.shadow.shape, dtype=np.float32)
    ahead, inline, stale = (AnticipationMap(1, SMALL) for _ in range(3))
    for amap in (ahead, inline, stale):
        amap.refresh(0.0, amap.next_slots(), first, TORUS)
    predicted = ahead.predict(later)
    prepared = ahead.prepare([2], predicted, moved, TORUS)
    assert ahead.window == base  # the map itself unchanged
    ahead.store(0.1, [2], predicted, moved, TORUS, prepared)
    inline.store(0.1, [2], predicted, moved, TORUS)
    assert ahead.a_map.tobytes() == inline.a_map.tobytes() and ahead.coverage.tobytes() == inline.coverage.tobytes()
    assert ahead.a_map is prepared.a_map
    made_before = stale.prepare([2], predicted, moved, TORUS)
    stale.set_mask(StyleMaskSettings(kind=MaskKind.HARD_BEHIND))
    stale.store(0.1, [2], predicted, moved, TORUS, made_before)
    assert stale.a_map is not made_before.a_map and not np.array_equal(stale.a_map, made_before.a_map)
    assert np.all(stale.a_map[moved.grid()[0] < behind_theta_rad(TORUS.alpha)] == 1.0)


def test_settings_are_validated():
    with pytest.raises(ValueError):
        AnticipationSettings(samples_per_target=0)
    with pytest.raises(ValueError):
        AnticipationSettings(length_cutoff=0.0)
    with pytest.raises(ValueError):
        AnticipationMap(3)
    with pytest.raises(ValueError):
        AnticipationMap(1, SMALL).refresh(0.0, [0, 1], _maps(_window(16), 1, 0.0), TORUS)


# -- the documented per-frame recipe, end to end --------------------------------------------------


def test_per_frame_recipe_with_a_ray_cast_backend():
    """Targets walk +X past a row of posts and a crate crossing their path; the A-map follows."""
    rng = np.random.default_rng(7)
    settings_ = AnticipationSettings(window=WindowSettings(resolution=32))
    posts = [box((0.3, 3.0, 0.3))]
    posts = [type(posts[0])(posts[0].vertices + [x, 1.5, 2.0], posts[0].faces) for x in np.arange(-2.0, 8.0, 1.5)]
    scene = OccluderScene(posts)
    scene.add_dynamic(
        "crate",
        box((0.8, 0.8, 0.8)),
        RigidTransform(position_world=np.array([3.0, 0.5, 1.5])),
        linear_velocity_m_s=(-1.0, 0.0, 0.0),
    )
    bodies = [sphere(0.3), cylinder(0.25, 1.6)]
    scene.add_dynamic("a", bodies[0], RigidTransform(position_world=np.array([0.0, 1.0, 0.0])))
    scene.add_dynamic("b", bodies[1], RigidTransform(position_world=np.array([2.5, 1.0, 0.0])))
    sampler = TargetSampler(bodies, rng, TargetSamplingSettings(settings_.samples_per_target))
    amap = AnticipationMap(2, settings_)
    backend = EmbreeMapBackend(scene)
    theta, phi, previous, updates = 1.8, 1.2, None, 0
    for frame in range(40):
        time_s, dt_s = frame / 60.0, 1.0 / 60.0
        shift = np.array([time_s, 0.0, 0.0])
        transforms = [
            RigidTransform(position_world=np.array([0.0, 1.0, 0.0]) + shift),
            RigidTransform(position_world=np.array([2.5, 1.0, 0.0]) + shift),
        ]
        for target_id, tf in zip(("a", "b"), transforms):
            scene.set_motion(target_id, tf, (1.0, 0.0, 0.0))
        torus = make_torus(transforms[0].position_world, transforms[1].position_world, ALPHA)
        if amap.due(time_s):
            slots = amap.next_slots()
            before = sampler.points_local[slots].copy()
            sampler.redraw(slots, rng)
            assert not np.allclose(before, sampler.points_local[slots])
            window = MapWindow.around(torus, theta, phi, settings_.window, lattice=amap.window)
            maps = backend.compute(
                torus,
                window,
                sampler.points_world(transforms, slots),
                exclude_ids=[("a", "b")[sampler.target_of(s)] for s in slots],
                previous_torus=previous,
                dt_s=dt_s if previous is not None else 0.0,
            )
            amap.refresh(time_s, slots, maps, torus)
            updates += 1
        previous = torus
        value = amap.lookup(theta, phi)
        assert 0.0 <= float(value) <= 1.0
    assert updates == 7  # t = 0 (all maps), then every 0.1 s up to 0.65 s
    assert 0.0 < float(amap.a_map.mean()) < 1.0 and np.all(amap.coverage > 0)
    backend.close()
