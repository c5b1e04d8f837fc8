"""camdirector._native.carry (native/src/carry.rs), RigidTransform.apply's twin: the same points
within rounding over random transforms (turned, scaled, far from the origin), a point (3,) as
well as rows (n, 3), known answers exactly, and bad input refused.

That it gives the same bits on other kinds of machine, where apply does not, is shown by the
compiled recordings (tests/worker/test_recordings_across_machines.py)."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector._native import carry
from camdirector.geometry.transforms import RigidTransform

RTOL = 1e-14  # of the points' magnitude: apply's product and carry's sums round differently


def test_carry_agrees_with_apply_on_random_transforms():
    rng = np.random.default_rng(3)
    for _ in range(500):
        q, scale = rng.normal(size=4), rng.uniform(0.1, 5.0, 3) * rng.choice([-1, 1], 3)
        transform = RigidTransform(rng.normal(size=3) * 1e3, q / np.linalg.norm(q), scale)
        points = rng.normal(size=(16, 3)) * 2.0
        want = transform.apply(points)
        got = carry(points, transform)
        assert got.shape == (16, 3) and got.dtype == np.float64
        np.testing.assert_allclose(got, want, rtol=0, atol=RTOL * np.abs(want).max())
        np.testing.assert_array_equal(carry(points[3], transform), got[3])  # one point, the same bits


def test_known_answers_exactly():
    quarter_turn_about_y = np.array([0.0, np.sqrt(0.5), 0.0, np.sqrt(0.5)])
    transform = RigidTransform(np.array([1.0, 2.0, 3.0]), quarter_turn_about_y, np.array([2.0, 1.0, 1.0]))
    got = carry(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), transform)
    # x scaled by 2 then turned a quarter about +y goes to -z; y stays
    np.testing.assert_allclose(got, [[1.0, 2.0, 1.0], [1.0, 3.0, 3.0]], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(carry(np.zeros((0, 3)), transform), np.zeros((0, 3)))


def test_bad_input_is_refused():
    transform = RigidTransform()
    with pytest.raises(ValueError, match="points_local has NaN"):
        carry(np.array([[np.nan, 0.0, 0.0]]), transform)
    with pytest.raises(ValueError, match=r"points_local must be \(n, 3\)"):
        carry(np.zeros((2, 2)), transform)
    with pytest.raises(ValueError, match="transform.scale has a zero"):
        carry(np.zeros((1, 3)), RigidTransform(scale=np.array([1.0, 0.0, 1.0])))
