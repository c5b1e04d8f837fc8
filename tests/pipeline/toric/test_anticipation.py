"""The occlusion anticipation map (pipeline/toric/anticipation.py): fast A_s against the numpy reference, the
uncertainty function, style masks, and the amortized schedule."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import box, cylinder, sphere
from camdirector.geometry.toric import composition_angle, make_torus, torus_position
from camdirector.geometry.toric_maps import MapWindow, OccluderScene, ShadowVelocityMaps, WindowSettings
from camdirector.geometry.toric_maps.embree import EmbreeMapBackend
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.toric.anticipation import (
    AnticipationMap,
    AnticipationSettings,
    KernelBank,
    MaskKind,
    StyleMaskSettings,
    angle_falloff,
    anticipation_reference,
    apply_style_mask,
    behind_theta_rad,
    length_falloff,
    predict_occlusion,
    snap_travel,
    style_mask,
    uncertainty,
)
from camdirector.pipeline.toric.target_sampling import TargetSampler, TargetSamplingSettings

FAST = settings(max_examples=60, derandomize=True, deadline=None, database=None)
DEFAULTS = AnticipationSettings()
ALPHA = composition_angle((-1.0 / 3.0, 0.0), (1.0 / 3.0, 0.0), Lens())
TORUS = make_torus((0.0, 1.0, 0.0), (2.5, 1.0, 0.0), ALPHA)


def _window(n: int, step_theta: float = 0.02, step_phi: float = 0.02, theta0: float = 1.0, phi0: float = 0.5) -> MapWindow:
    return MapWindow(theta0, phi0, step_theta, step_phi, n)


def _velocity_for_travel(travel_texels, window: MapWindow, horizon_s: float = DEFAULTS.horizon_s) -> np.ndarray:
    """Toric rates (rad/s) that make this travel over the horizon, in texels."""
    return np.asarray(travel_texels, dtype=np.float64) * np.array([window.theta_step_rad, window.phi_step_rad]) / horizon_s


# -- fast == reference ---------------------------------------------------------------------------

@st.composite
def map_cases(draw):
    n = draw(st.integers(6, 24))
    k = draw(st.integers(1, 2))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    settings_ = AnticipationSettings(
        length_cutoff=draw(st.floats(0.2, 1.5)),
        angle_cutoff_rad=draw(st.floats(0.1, 1.5)),
        direction_bins=draw(st.sampled_from([16, 64])),
        length_bin_ratio=draw(st.sampled_from([1.05, 1.1, 1.3])),
        max_travel_texels=draw(st.floats(2.0, 10.0)),
        min_travel_texels=draw(st.sampled_from([0.25, 0.5, 1.0])),
    )
    window = _window(n, draw(st.floats(0.005, 0.05)), draw(st.floats(0.005, 0.05)))
    shadow = (rng.random((k, n, n)) < draw(st.floats(0.05, 0.7))).astype(np.float32)
    if draw(st.booleans()):  # partly covered texels (a resampled or averaged S)
        shadow *= rng.random((k, n, n)).astype(np.float32)
    if draw(st.booleans()):  # rigid-looking: one travel plus a little noise
        travel = rng.normal(size=2) * 5.0 + rng.normal(size=(k, n, n, 2)) * 0.3
    else:
        travel = rng.normal(size=(k, n, n, 2)) * draw(st.floats(0.0, 8.0))
    velocity = _velocity_for_travel(travel, window, settings_.horizon_s).astype(np.float32)
    return shadow, velocity, window, settings_


@FAST
@given(map_cases())
def test_fast_prediction_equals_the_reference(case):
    shadow, velocity, window, settings_ = case
    fast = predict_occlusion(shadow, velocity, window, settings_, KernelBank(settings_))
    assert fast.shape == shadow.shape and fast.dtype == np.float32
    for sample in range(len(shadow)):
        reference = anticipation_reference(shadow[sample], velocity[sample], window, settings_)
        np.testing.assert_allclose(fast[sample], reference, atol=1e-4, rtol=0)


def test_warm_bank_gives_the_same_answer_and_bins_are_stable():
    rng = np.random.default_rng(5)
    window = _window(32)
    shadow = (rng.random((2, 32, 32)) < 0.3).astype(np.float32)
    velocity = _velocity_for_travel(rng.normal(size=(2, 32, 32, 2)) * 6.0, window).astype(np.float32)
    warm = KernelBank(DEFAULTS)
    warm.warm()
    np.testing.assert_allclose(predict_occlusion(shadow, velocity, window, DEFAULTS, warm),
                               predict_occlusion(shadow, velocity, window, DEFAULTS), atol=1e-6)
    bins, snapped = snap_travel(np.array([[3.0, 4.0], [0.1, 0.0], [100.0, 0.0]]), DEFAULTS)
    assert bins[1] == 0 and np.all(snapped[1] == 0.0)                    # under half a texel: still
    assert abs(np.hypot(*snapped[0]) - 5.0) / 5.0 < 0.05                  # length within half a bin
    assert np.hypot(*snapped[2]) <= DEFAULTS.max_travel_texels * 1.0001   # clamped


# -- the uncertainty function ----------------------------------------------------------------------

def test_falloffs_are_the_papers_triangles():
    np.testing.assert_allclose(length_falloff([0.0, 0.3, -0.3, 0.6, 2.0], 0.6), [1.0, 0.5, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(angle_falloff([0.0, 0.25, -0.25, 0.5, 3.0], 0.5), [1.0, 0.5, 0.5, 0.0, 0.0])


vectors = st.tuples(st.floats(-20, 20), st.floats(-20, 20))


@FAST
@given(vectors, vectors)
def test_uncertainty_is_bounded_and_cut_off(travel, offset):
    t, d = np.array(travel), np.array(offset)
    u = float(uncertainty(t, d, DEFAULTS.length_cutoff, DEFAULTS.angle_cutoff_rad))
    assert 0.0 <= u <= 1.0
    mirrored = float(uncertainty(t * [1, -1], d * [1, -1], DEFAULTS.length_cutoff, DEFAULTS.angle_cutoff_rad))
    assert math.isclose(u, mirrored, abs_tol=1e-12)
    length, reach = np.hypot(*t), np.hypot(*d)
    if length > 1e-9 and reach > 1e-9:
        gamma = math.acos(max(-1.0, min(1.0, float(t @ d) / (length * reach))))
        if abs(length - reach) / length >= DEFAULTS.length_cutoff or gamma >= DEFAULTS.angle_cutoff_rad:
            assert u == 0.0


def test_uncertainty_peaks_at_the_predicted_travel_and_falls_off_along_and_across():
    travel = np.array([6.0, 0.0])
    along = [float(uncertainty(travel, [x, 0.0], 0.6, 0.5)) for x in (3.0, 4.5, 6.0, 7.5, 9.0)]
    assert along[2] == 1.0 and along[1] < 1.0 and along[3] < 1.0
    assert along[0] < along[1] and along[4] < along[3]
    across = [float(uncertainty(travel, 6.0 * np.array([math.cos(a), math.sin(a)]), 0.6, 0.5))
              for a in (0.0, 0.2, 0.4, 0.6)]
    assert across == sorted(across, reverse=True) and across[-1] == 0.0
    # A still occluder stays where it is.
    assert float(uncertainty([0.0, 0.0], [0.0, 0.0], 0.6, 0.5)) == 1.0
    assert float(uncertainty([0.0, 0.0], [1.0, 0.0], 0.6, 0.5)) == 0.0


# -- what the prediction does ------------------------------------------------------------------------

def test_still_occluders_and_no_anticipation_give_the_shadow_map():
    rng = np.random.default_rng(1)
    window = _window(24)
    shadow = (rng.random((24, 24)) < 0.4).astype(np.float32)
    still = np.zeros((24, 24, 2), np.float32)
    np.testing.assert_array_equal(predict_occlusion(shadow, still, window), shadow)
    moving = _velocity_for_travel(np.full((24, 24, 2), 5.0), window).astype(np.float32)
    off = AnticipationSettings(anticipate=False)
    np.testing.assert_array_equal(predict_occlusion(shadow, moving, window, off), shadow)
    np.testing.assert_array_equal(anticipation_reference(shadow, moving, window, off), shadow)


def test_one_moving_texel_spreads_unit_mass_ahead_of_itself():
    n = 40
    window = _window(n, 0.01, 0.03)
    shadow = np.zeros((n, n), np.float32)
    shadow[10, 20] = 1.0
    velocity = np.zeros((n, n, 2), np.float32)
    velocity[10, 20] = _velocity_for_travel([8.0, 0.0], window)          # 8 texels toward +theta
    a = predict_occlusion(shadow, velocity, window)
    assert math.isclose(float(a.sum()), 1.0, rel_tol=1e-5)
    rows, cols = np.nonzero(a)
    assert rows.min() > 10 and a[10, 20] == 0.0                          # nothing behind or in place
    centroid = (np.array(np.nonzero(a)) * a[rows, cols]).sum(axis=1)
    assert abs(centroid[0] - 18.0) < 1.5 and abs(centroid[1] - 20.0) < 0.5


def test_a_wide_occluder_moving_uniformly_is_predicted_certain_inside_and_ahead():
    n = 48
    window = _window(n)
    shadow = np.zeros((n, n), np.float32)
    shadow[5:30, 10:40] = 1.0
    velocity = np.where(shadow[..., None] > 0, _velocity_for_travel([4.0, 0.0], window), 0.0).astype(np.float32)
    a = predict_occlusion(shadow, velocity, window)
    assert np.all(a <= 1.0)
    np.testing.assert_allclose(a[15:30, 20:30], 1.0, atol=1e-5)          # inside, after the shift
    assert a[31, 25] > 0.3 and a[5, 25] < 0.5                             # ahead filled, trailing edge freed


def test_every_kernel_sums_to_one():
    bank = KernelBank(DEFAULTS)
    for bin_id in np.random.default_rng(2).integers(0, 1 + DEFAULTS.length_bins * DEFAULTS.direction_bins, 50):
        di, dj, w = bank.kernel(int(bin_id))
        assert math.isclose(float(w.sum()), 1.0, rel_tol=1e-9) and np.all(w > 0)
        assert np.all(np.hypot(di, dj) <= bank.max_radius)


# -- style masks (section 5.2) -----------------------------------------------------------------------

MASK_WINDOW = MapWindow(0.2, -math.pi, (2.0 * math.pi - 2.0 * ALPHA - 0.4) / 64, 2.0 * math.pi / 64, 64)


def test_behind_boundary_is_where_the_camera_is_level_with_a():
    theta = behind_theta_rad(ALPHA)
    for phi in (0.3, 1.5, -2.0):
        along = (torus_position(TORUS, theta, phi) - TORUS.a_world) @ TORUS.axis_world
        assert abs(along) < 1e-9
        assert (torus_position(TORUS, theta - 0.1, phi) - TORUS.a_world) @ TORUS.axis_world < 0.0


def test_masks():
    theta, phi = MASK_WINDOW.grid()
    behind = theta < behind_theta_rad(ALPHA)
    a = np.random.default_rng(0).random((64, 64)).astype(np.float32)
    empty = style_mask(StyleMaskSettings(), MASK_WINDOW, ALPHA)
    np.testing.assert_array_equal(apply_style_mask(a, empty), a)
    hard = apply_style_mask(a, style_mask(StyleMaskSettings(kind=MaskKind.HARD_BEHIND), MASK_WINDOW, ALPHA))
    assert np.all(hard[behind] == 1.0)
    np.testing.assert_array_equal(hard[~behind], a[~behind])
    soft = style_mask(StyleMaskSettings(kind=MaskKind.SOFT_BEHIND), MASK_WINDOW, ALPHA)
    assert np.all(np.diff(soft, axis=0) >= 0.0)                             # a gradient toward the back
    assert np.all(soft[~behind] == 1.0) and np.all(soft[theta < behind_theta_rad(ALPHA) - 0.6] == 0.0)
    assert 0 < np.count_nonzero((soft > 0) & (soft < 1))
    combined = style_mask(StyleMaskSettings(kind=MaskKind.AVOID_BEHIND_TOP_BOTTOM), MASK_WINDOW, ALPHA)
    front = ~behind
    abs_phi = np.abs(np.degrees(phi))
    assert np.all(combined[front & (abs_phi < 15)] == 0.0)                  # top views
    assert np.all(combined[front & (abs_phi > 150)] == 0.0)                 # bottom views
    assert np.all(combined[front & (abs_phi > 45) & (abs_phi < 120)] == 1.0)
    assert np.all((combined >= 0.0) & (combined <= 1.0))
    with pytest.raises(ValueError):
        StyleMaskSettings(top_view_phi_deg=120.0)


# -- the amortized schedule (section 6) --------------------------------------------------------------

def _maps(window: MapWindow, count: int, value: float) -> ShadowVelocityMaps:
    n = window.resolution
    shadow = np.full((count, n, n), value, np.float32)
    return ShadowVelocityMaps(window, shadow, np.zeros((count, n, n, 2), np.float32),
                              np.where(shadow > 0, 1.0, np.inf).astype(np.float32))


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
    for frame in range(1, 6 * 2 * r + 1):          # two full rounds at 60 fps
        t = frame * frame_s
        if amap.due(t):
            slots = amap.next_slots()
            refreshed.append((round(t, 4), slots))
            amap.refresh(t, slots, _maps(window, len(slots), 0.0), TORUS)
    times = [when for when, _ in refreshed]
    assert np.allclose(np.diff(times), period, atol=frame_s + 1e-9)       # one update per W / r
    assert [slots for _, slots in refreshed[:r]] == [[s, r + s] for s in range(r)]
    assert [slots for _, slots in refreshed[r:2 * r]] == [[s, r + s] for s in range(r)]
    # Every map is at most W old once the schedule runs.
    assert np.nanmax(t - amap.computed_at_s) <= SMALL.horizon_s + 1e-9


def test_schedule_recovers_from_time_going_back_long_gaps_and_cuts():
    amap = AnticipationMap(1, SMALL)
    window = _window(16)
    amap.refresh(10.0, amap.next_slots(), _maps(window, SMALL.samples_per_target, 0.0), TORUS)
    assert amap.next_slots() == [0] and not amap.due(10.05) and amap.due(10.1)
    assert amap.due(9.0)                                                  # time went back
    amap.refresh(20.0, [0], _maps(window, 1, 0.0), TORUS)                 # a long gap
    assert not amap.due(20.05) and amap.due(20.1)
    amap.invalidate()
    assert amap.due(20.01) and amap.next_slots() == list(range(SMALL.samples_per_target))


def test_aggregate_is_the_mean_of_the_predictions_with_the_mask_on_top():
    amap = AnticipationMap(2, SMALL)
    window = _window(16)
    values = np.linspace(0.0, 1.0, 2 * SMALL.samples_per_target)
    n = window.resolution
    shadow = (np.arange(n * n).reshape(n, n) % 3 == 0).astype(np.float32)
    maps = ShadowVelocityMaps(window, shadow[None].repeat(len(values), 0) * values[:, None, None].astype(np.float32),
                              np.zeros((len(values), n, n, 2), np.float32), np.zeros((len(values), n, n), np.float32))
    amap.refresh(0.0, range(len(values)), maps, TORUS)
    np.testing.assert_allclose(amap.a_map, shadow * values.mean(), atol=1e-6)   # (1 / 2r) sum of A_s
    assert np.all(amap.coverage == 1.0)
    amap.set_mask(StyleMaskSettings(kind=MaskKind.HARD_BEHIND))
    assert np.all(amap.a_map[window.grid()[0] < behind_theta_rad(TORUS.alpha)] == 1.0)


def test_older_maps_are_shifted_into_the_newest_window():
    amap = AnticipationMap(1, SMALL)
    base = _window(16)
    amap.refresh(0.0, amap.next_slots(), _maps(base, SMALL.samples_per_target, 1.0), TORUS)
    moved = MapWindow(base.theta_min_rad + 4 * base.theta_step_rad, base.phi_min_rad, base.theta_step_rad,
                      base.phi_step_rad, 16)
    amap.refresh(0.1, [0], _maps(moved, 1, 0.0), TORUS)
    assert amap.window == moved
    r = SMALL.samples_per_target
    np.testing.assert_allclose(amap.a_map[:12], (r - 1) / r, atol=1e-6)  # old maps cover the first 12 rows
    np.testing.assert_allclose(amap.a_map[12:], 0.0)                      # only the new, empty map there
    np.testing.assert_allclose(amap.coverage[:12], 1.0)
    np.testing.assert_allclose(amap.coverage[12:], 1.0 / r)
    i, j = np.meshgrid(np.arange(16), np.arange(16), indexing="ij")
    theta, phi = moved.angles(i, j)
    np.testing.assert_allclose(amap.lookup(theta, phi), amap.a_map, atol=1e-6)
    assert np.isnan(amap.lookup(moved.theta_min_rad - 1.0, phi[0, 0]))


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
    scene.add_dynamic("crate", box((0.8, 0.8, 0.8)), RigidTransform(position_world=np.array([3.0, 0.5, 1.5])),
                      linear_velocity_m_s=(-1.0, 0.0, 0.0))
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
        transforms = [RigidTransform(position_world=np.array([0.0, 1.0, 0.0]) + shift),
                      RigidTransform(position_world=np.array([2.5, 1.0, 0.0]) + shift)]
        for target_id, tf in zip(("a", "b"), transforms):
            scene.set_motion(target_id, tf, (1.0, 0.0, 0.0))
        torus = make_torus(transforms[0].position_world, transforms[1].position_world, ALPHA)
        if amap.due(time_s):
            slots = amap.next_slots()
            before = sampler.points_local[slots].copy()
            sampler.redraw(slots, rng)
            assert not np.allclose(before, sampler.points_local[slots])
            window = MapWindow.around(torus, theta, phi, settings_.window, lattice=amap.window)
            maps = backend.compute(torus, window, sampler.points_world(transforms, slots),
                                   exclude_ids=[("a", "b")[sampler.target_of(s)] for s in slots],
                                   previous_torus=previous, dt_s=dt_s if previous is not None else 0.0)
            amap.refresh(time_s, slots, maps, torus)
            updates += 1
        previous = torus
        value = amap.lookup(theta, phi)
        assert 0.0 <= float(value) <= 1.0
    assert updates == 7                              # t = 0 (all maps), then every 0.1 s up to 0.65 s
    assert 0.0 < float(amap.a_map.mean()) < 1.0 and np.all(amap.coverage > 0)
    backend.close()
