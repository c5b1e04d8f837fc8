"""camdirector._native.turn_rates (native/src/move_scene_py.rs, rotation.rs `turn_rotvec`): the
angular velocities the compiled maps' scene moves its objects with, against scipy's rotation
vector of the same turns (OcclusionMaps._turn_rates, the Python path's): within 1e-12 rad/s for
random turns of every size (small angles on scipy's series, near-half turns, quaternions of any
length and sign), and every refusal."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from camdirector._native import turn_rates

TOL = 1e-12  # rad/s at dt_s 1 s: rounding, not another formula


def _scipy(before: np.ndarray, now: np.ndarray, dt_s: float) -> np.ndarray:
    return (Rotation.from_quat(now) * Rotation.from_quat(before).inv()).as_rotvec() / dt_s


def test_random_turns_agree_with_scipy():
    rng = np.random.default_rng(11)
    before = rng.normal(size=(400, 4)) * rng.uniform(0.1, 10.0, size=(400, 1))
    turns = Rotation.from_rotvec(rng.normal(size=(400, 3)) * np.logspace(-9, np.log10(3.1), 400)[:, None] / np.sqrt(3))
    now = (turns * Rotation.from_quat(before)).as_quat() * rng.choice([-1.0, 1.0], size=(400, 1))  # either sign
    got = turn_rates(before, now, 1.0)
    assert got.shape == (400, 3)
    np.testing.assert_allclose(got, _scipy(before, now, 1.0), rtol=0, atol=TOL)
    np.testing.assert_allclose(turn_rates(before, now, 1.0 / 60.0), _scipy(before, now, 1.0 / 60.0), rtol=1e-12, atol=TOL)


unit_quat = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: 0.1 < np.linalg.norm(q))


@settings(max_examples=300, deadline=None)
@given(unit_quat, unit_quat, st.floats(1e-3, 10.0))
def test_any_turn_agrees_with_scipy(before, now, dt_s):
    b, n = np.array([before]), np.array([now])
    got, want = turn_rates(b, n, dt_s), _scipy(b, n, dt_s)
    if abs(np.linalg.norm(want) * dt_s - np.pi) < 1e-9 and np.linalg.norm(got + want) < np.linalg.norm(got - want):
        want = -want  # a half turn: about v and about -v are the same turn, and rounding picks the side
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL / dt_s * 10)


def test_no_objects_no_rates():
    assert turn_rates(np.zeros((0, 4)), np.zeros((0, 4)), 0.5).shape == (0, 3)


@pytest.mark.parametrize(
    ("before", "now", "dt_s", "message"),
    [
        (np.zeros((2, 4)), np.zeros((3, 4)), 1.0, "must both be"),
        (np.zeros((2, 3)), np.zeros((2, 3)), 1.0, "must both be"),
        (np.array([[0.0, 0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 0.0, 0.0]]), 1.0, "finite and nonzero"),
        (np.array([[0.0, 0.0, 0.0, np.nan]]), np.array([[0.0, 0.0, 0.0, 1.0]]), 1.0, "finite and nonzero"),
        (np.array([[0.0, 0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 0.0, 1.0]]), 0.0, "positive"),
        (np.array([[0.0, 0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 0.0, 1.0]]), float("nan"), "positive"),
    ],
)
def test_refusals(before, now, dt_s, message):
    with pytest.raises(ValueError, match=message):
        turn_rates(before, now, dt_s)
