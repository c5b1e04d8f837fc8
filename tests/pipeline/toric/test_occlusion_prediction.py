"""The per-sample occlusion prediction (pipeline/toric/occlusion_prediction.py): fast A_s against the
numpy reference, the uncertainty function, and what the prediction does."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector.geometry.toric_maps import MapWindow
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.occlusion_prediction import (
    KernelBank,
    angle_falloff,
    anticipation_reference,
    length_falloff,
    predict_occlusion,
    snap_travel,
    uncertainty,
)

FAST = settings(max_examples=60, derandomize=True, deadline=None, database=None)
DEFAULTS = AnticipationSettings()


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
    np.testing.assert_allclose(
        predict_occlusion(shadow, velocity, window, DEFAULTS, warm),
        predict_occlusion(shadow, velocity, window, DEFAULTS),
        atol=1e-6,
    )
    bins, snapped = snap_travel(np.array([[3.0, 4.0], [0.1, 0.0], [100.0, 0.0]]), DEFAULTS)
    assert bins[1] == 0 and np.all(snapped[1] == 0.0)  # under half a texel: still
    assert abs(np.hypot(*snapped[0]) - 5.0) / 5.0 < 0.05  # length within half a bin
    assert np.hypot(*snapped[2]) <= DEFAULTS.max_travel_texels * 1.0001  # clamped


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
    across = [float(uncertainty(travel, 6.0 * np.array([math.cos(a), math.sin(a)]), 0.6, 0.5)) for a in (0.0, 0.2, 0.4, 0.6)]
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
    velocity[10, 20] = _velocity_for_travel([8.0, 0.0], window)  # 8 texels toward +theta
    a = predict_occlusion(shadow, velocity, window)
    assert math.isclose(float(a.sum()), 1.0, rel_tol=1e-5)
    rows, cols = np.nonzero(a)
    assert rows.min() > 10 and a[10, 20] == 0.0  # nothing behind or in place
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
    np.testing.assert_allclose(a[15:30, 20:30], 1.0, atol=1e-5)  # inside, after the shift
    assert a[31, 25] > 0.3 and a[5, 25] < 0.5  # ahead filled, trailing edge freed


def test_every_kernel_sums_to_one():
    bank = KernelBank(DEFAULTS)
    for bin_id in np.random.default_rng(2).integers(0, 1 + DEFAULTS.length_bins * DEFAULTS.direction_bins, 50):
        di, dj, w = bank.kernel(int(bin_id))
        assert math.isclose(float(w.sum()), 1.0, rel_tol=1e-9) and np.all(w > 0)
        assert np.all(np.hypot(di, dj) <= bank.max_radius)
