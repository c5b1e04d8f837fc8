"""Path energy terms (energy.py) and the annealer's hard constraints (annealing.py)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector.precompute.overview.annealing import SidePrior
from camdirector.precompute.overview.energy import EnergyWeights, energy_below, internal_terms

W = EnergyWeights(
    c1=10,
    c2=10,
    c3=5,
    c4=5,
    c5=2,
    max_speed_m_s=0.3,
    max_angular_speed_rad_s=np.radians(20.0),
    friction_speed_m_s=0.09,
    dt_s=1.0 / 15.0,
)


def test_resting_camera_on_a_resting_target_has_no_internal_energy():
    n = 30
    path = np.tile([3.0, 1.5, 0.0], (n, 1))
    look_at = np.tile([0.0, 1.0, 0.0], (n, 1))
    np.testing.assert_array_equal(internal_terms(path, look_at, W), 0.0)


def test_friction_rises_to_c5_at_the_friction_speed_and_stays():
    n = 5
    look_at = np.tile([0.0, 0.0, 100.0], (n, 1))  # far ahead: no angular terms to speak of
    t = np.arange(n)[:, None]
    step = W.friction_speed_m_s * W.dt_s
    for fraction, expected in ((0.5, 0.25 * W.c5), (1.0, W.c5), (2.0, W.c5)):
        path = t * np.array([0.0, 0.0, fraction * step])
        np.testing.assert_allclose(internal_terms(path, look_at, W), expected, rtol=1e-3)


@settings(max_examples=30, deadline=None)
@given(st.integers(3, 17), st.integers(0, 2**31 - 1))
def test_a_cut_never_raises_the_internal_energy(cut, seed):
    # The paper: "by splitting the shot into two different shots, we reduce the internal energy".
    rng = np.random.default_rng(seed)
    path = np.cumsum(rng.normal(scale=0.02, size=(20, 3)), axis=0) + [4.0, 1.0, 0.0]
    look_at = rng.normal(scale=0.1, size=(20, 3))
    whole = internal_terms(path, look_at, W).sum()
    split = internal_terms(path[:cut], look_at[:cut], W).sum() + internal_terms(path[cut:], look_at[cut:], W).sum()
    assert split <= whole + 1e-12


def test_many_static_cameras_at_once_match_one_at_a_time():
    rng = np.random.default_rng(5)
    look_at = np.cumsum(rng.normal(scale=0.05, size=(25, 3)), axis=0)
    nodes = rng.uniform(-4.0, 4.0, size=(7, 3)) + [0.0, 0.0, 6.0]
    together = internal_terms(np.broadcast_to(nodes, (25, 7, 3)), look_at, W)
    assert together.shape == (23, 7)
    for k, node in enumerate(nodes):
        np.testing.assert_allclose(together[:, k], internal_terms(np.tile(node, (25, 1)), look_at, W))


def test_speed_term_is_zero_under_the_limit_and_quartic_above():
    n = 10
    look_at = np.zeros((n, 3))
    t = np.arange(n)[:, None]
    slow = np.array([5.0, 0, 0]) + t * np.array([0, 0, 0.5 * W.max_speed_m_s * W.dt_s])
    fast = np.array([5.0, 0, 0]) + t * np.array([0, 0, 2.0 * W.max_speed_m_s * W.dt_s])
    # constant velocity: no acceleration; above the friction speed: friction is c5
    slow_terms = internal_terms(slow, look_at, W)
    fast_terms = internal_terms(fast, look_at, W)
    assert np.all(slow_terms < W.c5 + 1.0)
    # 2x the limit adds c2 * 2^4 = 160 per frame on top of friction and small angular terms
    assert np.all(np.abs(fast_terms - W.c2 * 2.0**4 - W.c5) < 1.0)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=3, max_size=3))
def test_internal_energy_is_translation_invariant(shift):
    rng = np.random.default_rng(3)
    path = np.cumsum(rng.normal(scale=0.01, size=(20, 3)), axis=0) + [4.0, 1.0, 0.0]
    look_at = rng.normal(scale=0.1, size=(20, 3))
    np.testing.assert_allclose(internal_terms(path + shift, look_at + shift, W), internal_terms(path, look_at, W), atol=1e-9)


def test_side_prior_sides():
    prior = SidePrior(frame=0, point_xz=np.zeros(2), direction_xz=np.array([0.0, 1.0]), side=1)
    # moving along +Z (xz direction (0, 1)); cross(d, rel) = d_x rel_z - d_z rel_x > 0 for x < 0
    assert prior.holds(np.array([-1.0, 0.0, 0.0]))
    assert not prior.holds(np.array([1.0, 0.0, 0.0]))
    np.testing.assert_array_equal(prior.holds_for_nodes(np.array([[-1.0, 0, 0], [1.0, 0, 0]])), [True, False])


def test_energy_below_treats_rounding_as_a_tie():
    assert not energy_below(-202.69100000000003, -202.691)
    assert not energy_below(-202.691, -202.69100000000003)
    assert energy_below(-202.7, -202.691)
    assert not energy_below(0.0, 0.0) and energy_below(-1e-6, 0.0)
