"""Quaternions and rigid transforms (geometry/transforms.py): round trips and agreement with matrices."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from camdirector.geometry.transforms import (
    RigidTransform,
    matrix_to_quat,
    quat_normalize,
    quat_rotate,
    quat_to_matrix,
)

FAST = settings(max_examples=200, derandomize=True, deadline=None, database=None)

component = st.floats(-1.0, 1.0)
raw_quats = st.tuples(component, component, component, component).map(np.array)
vectors = st.tuples(st.floats(-100.0, 100.0), st.floats(-100.0, 100.0), st.floats(-100.0, 100.0)).map(np.array)


@st.composite
def unit_quats(draw):
    q = draw(raw_quats)
    assume(np.linalg.norm(q) > 0.1)
    return quat_normalize(q)


def same_rotation(q1: np.ndarray, q2: np.ndarray, atol: float) -> bool:
    """q and -q name the same rotation."""
    return np.allclose(q1, q2, atol=atol) or np.allclose(q1, -q2, atol=atol)


@FAST
@given(unit_quats())
def test_quat_to_matrix_is_a_rotation(q):
    m = quat_to_matrix(q)
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m) == pytest.approx(1.0, abs=1e-12)


@FAST
@given(unit_quats())
def test_quat_matrix_quat_round_trip(q):
    back = matrix_to_quat(quat_to_matrix(q))
    assert back[3] >= 0.0
    assert abs(np.linalg.norm(back) - 1.0) < 1e-12
    # w = 0 leaves the sign free, so compare up to sign.
    assert same_rotation(back, q, atol=1e-12)


@FAST
@given(unit_quats())
def test_matrix_quat_matrix_round_trip(q):
    m = quat_to_matrix(q)
    np.testing.assert_allclose(quat_to_matrix(matrix_to_quat(m)), m, atol=1e-12)


@FAST
@given(unit_quats(), vectors)
def test_quat_rotate_matches_matrix(q, v):
    np.testing.assert_allclose(quat_rotate(q, v), quat_to_matrix(q) @ v, atol=1e-12)
    assert np.linalg.norm(quat_rotate(q, v)) == pytest.approx(np.linalg.norm(v), abs=1e-12)


@FAST
@given(unit_quats(), unit_quats(), vectors)
def test_quat_rotate_matches_hamilton_product(q1, q2, v):
    """Rotating by q1 q2 is rotating by q2 then by q1 (Hamilton product, xyzw)."""
    x1, y1, z1, w1 = q1
    x2, y2, z2, w2 = q2
    q12 = np.array(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ]
    )
    np.testing.assert_allclose(quat_rotate(q12, v), quat_rotate(q1, quat_rotate(q2, v)), atol=1e-10)


@FAST
@given(st.floats(-math.pi, math.pi), vectors)
def test_axis_angle_about_y_is_right_handed(angle, v):
    q = np.array([0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2)])
    c, s = math.cos(angle), math.sin(angle)
    expected = np.array([c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]])
    np.testing.assert_allclose(quat_rotate(q, v), expected, atol=1e-12)


def test_quat_to_matrix_batches():
    qs = quat_normalize(np.array([[0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0]]))
    ms = quat_to_matrix(qs)
    assert ms.shape == (3, 3, 3)
    for q, m in zip(qs, ms):
        np.testing.assert_allclose(m, quat_to_matrix(q), atol=0)


@FAST
@given(unit_quats(), vectors, vectors)
def test_rigid_transform_apply_matches_matrix(q, position, local):
    t = RigidTransform(position_world=position, rotation_xyzw=q, scale=np.array([1.0, 2.0, 0.5]))
    expected = (t.matrix() @ np.append(local, 1.0))[:3]
    np.testing.assert_allclose(t.apply(local[None, :])[0], expected, atol=1e-10)
