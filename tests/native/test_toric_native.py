"""camdirector._native's Toric space (native/src/toric.rs) against its Python twin, geometry/toric.py:
every compiled function agrees with the Python one over random valid inputs (positions within 1e-9 m,
angles within 1e-9 rad, quaternions up to sign), refuses what the Python refuses, and gives the same
bits for the same inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from camdirector import _native as native
from camdirector.geometry import toric
from camdirector.geometry.camera import Lens

TOL = 1e-9  # metres for positions, radians for angles, unit for quaternions and matrices
FAST = settings(max_examples=150, derandomize=True, deadline=None, database=None)

coord = st.floats(-100.0, 100.0)
point = st.tuples(coord, coord, coord).map(np.array)
direction = st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)).map(np.array)
ab_distance_m = st.floats(0.03, 100.0)
screen = st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0))
lenses = st.builds(Lens, vertical_fov_deg=st.floats(10.0, 120.0), aspect=st.floats(0.5, 2.5))
alphas = st.floats(toric.MIN_ALPHA_RAD, math.pi - toric.MIN_ALPHA_RAD)
fractions = st.floats(0.0, 1.0, exclude_min=True, exclude_max=True)  # of theta's open range
phis = st.floats(-math.pi, math.pi)


@st.composite
def pairs(draw):
    """(A, B): (3,) metres, a few cm to 100 m apart."""
    a, d = draw(point), draw(direction)
    assume(np.linalg.norm(d) > 0.1)
    return a, a + draw(ab_distance_m) * d / np.linalg.norm(d)


@st.composite
def scenes(draw):
    """(A, B, screen_a, screen_b, lens, alpha): alpha = composition_angle, within make_torus's range."""
    a, b = draw(pairs())
    lens, sa, sb = draw(lenses), draw(screen), draw(screen)
    alpha = toric.composition_angle(sa, sb, lens)
    assume(toric.MIN_ALPHA_RAD <= alpha <= math.pi - toric.MIN_ALPHA_RAD)
    return a, b, sa, sb, lens, alpha


def max_diff(got, want) -> float:
    got, want = np.asarray(got, dtype=np.float64), np.asarray(want, dtype=np.float64)
    assert got.shape == want.shape
    assert np.array_equal(np.isnan(got), np.isnan(want))
    return float(np.nanmax(np.abs(got - want), initial=0.0))


def angle_diff(got: float, want: float) -> float:
    """|got - want| wrapped to [0, pi]: phi = pi and phi = -pi + 1e-17 are neighbours."""
    return abs(math.remainder(got - want, math.tau))


def quat_diff(got, want) -> float:
    """Max abs difference of two quaternions (4,), blind to the q / -q sign."""
    return min(max_diff(got, want), max_diff(-np.asarray(got), want))


def off_axis_m(p, a, b) -> float:
    """Distance of p from the line AB, metres: phi and the framing rotations are undefined on it."""
    axis = (b - a) / np.linalg.norm(b - a)
    return float(np.linalg.norm(np.cross(p - a, axis)))


def torus_fields_diff(got, want: toric.Torus) -> float:
    names = ("a_world", "b_world", "alpha", "axis_world", "ref_world", "side_world", "length_ab_m")
    names += ("arc_radius_m", "mid_world", "basis", "center_offset_m")
    return max(max_diff(getattr(got, name), getattr(want, name)) for name in names)


# --- torus ----------------------------------------------------------------------------------------


def test_the_constants_are_pythons():
    for name in ("MIN_AB_DISTANCE_M", "MIN_ALPHA_RAD", "PARALLEL_SIN_EPS", "THETA_MARGIN_RAD"):
        assert getattr(native, name) == getattr(toric, name)


@FAST
@given(pairs(), alphas, st.one_of(st.just((0.0, 1.0, 0.0)), direction))
def test_make_torus_matches(pair, alpha, up):
    a, b = pair
    assume(np.linalg.norm(up) > 0.01)
    assert torus_fields_diff(native.make_torus(a, b, alpha, up), toric.make_torus(a, b, alpha, up)) <= TOL
    assert torus_fields_diff(native.make_torus(a, b, alpha), toric.make_torus(a, b, alpha)) <= TOL


@pytest.mark.parametrize(
    "ab, up",
    [
        (((1.0, 2.0, 3.0), (1.0, 7.0, 3.0)), (0.0, 1.0, 0.0)),  # AB along up: world -Z stands in
        (((1.0, 2.0, 3.0), (1.0, 2.0, -4.0)), (0.0, 0.0, 2.0)),  # AB and up along Z: world +X stands in
        (((0.0, 0.0, 0.0), (1e-9, 50.0, 0.0)), (0.0, 1.0, 0.0)),  # nearly vertical
    ],
)
def test_make_torus_matches_where_ab_is_along_up(ab, up):
    a, b = ab
    assert torus_fields_diff(native.make_torus(a, b, 0.7, up), toric.make_torus(a, b, 0.7, up)) <= TOL


@pytest.mark.parametrize(
    "a, b, alpha, up",
    [
        ((1.0, 2.0, 3.0), (1.0, 2.0, 3.0), 0.5, (0.0, 1.0, 0.0)),  # A = B
        ((1.0, 2.0, 3.0), (1.0, 2.0, 3.0 + 5e-7), 0.5, (0.0, 1.0, 0.0)),  # |AB| under 1e-6 m
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.0, (0.0, 1.0, 0.0)),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 5e-5, (0.0, 1.0, 0.0)),  # alpha below MIN_ALPHA_RAD
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), math.pi - 5e-5, (0.0, 1.0, 0.0)),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), math.pi, (0.0, 1.0, 0.0)),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), math.nan, (0.0, 1.0, 0.0)),
        ((0.0, math.nan, 0.0), (1.0, 0.0, 0.0), 0.5, (0.0, 1.0, 0.0)),
        ((0.0, 0.0, 0.0), (math.inf, 0.0, 0.0), 0.5, (0.0, 1.0, 0.0)),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.5, (0.0, -math.inf, 0.0)),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.5, (0.0, 0.0, 0.0)),  # up is zero
    ],
)
def test_degenerate_tori_raise_value_error_in_both(a, b, alpha, up):
    with pytest.raises(toric.DegenerateTorus):
        toric.make_torus(a, b, alpha, up)
    with pytest.raises(native.DegenerateTorus):
        native.make_torus(a, b, alpha, up)
    assert issubclass(native.DegenerateTorus, ValueError)


@pytest.mark.parametrize("a", [(1.0, 2.0), np.zeros(4), [[1.0, 2.0, 3.0, 4.0]]])
def test_a_wrong_shape_raises_value_error_in_both(a):
    with pytest.raises(ValueError):
        toric.make_torus(a, (5.0, 5.0, 5.0), 0.5)
    with pytest.raises(ValueError):
        native.make_torus(a, (5.0, 5.0, 5.0), 0.5)


def test_make_torus_takes_lists_tuples_and_other_dtypes_as_python_does():
    want = toric.make_torus([0, 0, 0], (1, 2, 3), 0.5, np.array([0, 1, 0], dtype=np.int32))
    assert torus_fields_diff(native.make_torus([0, 0, 0], (1, 2, 3), 0.5, np.array([0, 1, 0], dtype=np.int32)), want) == 0.0
    assert torus_fields_diff(native.make_torus(np.zeros((3, 1)), np.array([1.0, 2.0, 3.0]), 0.5), want) == 0.0


@FAST
@given(alphas)
def test_theta_max_matches(alpha):
    assert native.theta_max(alpha) == toric.theta_max(alpha)


# --- screen ---------------------------------------------------------------------------------------


@FAST
@given(screen, screen, lenses)
def test_view_direction_and_composition_angle_match(sa, sb, lens):
    assert max_diff(native.view_direction(sa, lens), toric.view_direction(sa, lens)) <= TOL
    assert abs(native.composition_angle(sa, sb, lens) - toric.composition_angle(sa, sb, lens)) <= TOL
    # the lens as a plain tuple reads the same
    assert native.composition_angle(sa, sb, (lens.vertical_fov_deg, lens.aspect)) == native.composition_angle(sa, sb, lens)


# --- positions and angles -------------------------------------------------------------------------


@FAST
@given(pairs(), alphas, fractions, phis)
def test_torus_position_matches_for_scalars(pair, alpha, fraction, phi):
    twin, torus = native.make_torus(*pair, alpha), toric.make_torus(*pair, alpha)
    theta = fraction * toric.theta_max(alpha)
    got = native.torus_position(twin, theta, phi)
    assert got.shape == (3,)
    assert max_diff(got, toric.torus_position(torus, theta, phi)) <= TOL


@FAST
@given(pairs(), alphas, st.lists(st.floats(-0.5, 1.5), min_size=1, max_size=40), st.lists(phis, min_size=1, max_size=10))
def test_torus_position_matches_for_arrays_broadcast_together(pair, alpha, fractions_, phis_):
    """theta (n, 1) against phi (m,) -> (n, m, 3); theta past its range continues around the circle."""
    twin, torus = native.make_torus(*pair, alpha), toric.make_torus(*pair, alpha)
    thetas = np.array(fractions_)[:, None] * toric.theta_max(alpha)
    assert (
        max_diff(native.torus_position(twin, thetas, np.array(phis_)), toric.torus_position(torus, thetas, np.array(phis_)))
        <= TOL
    )
    assert (
        max_diff(native.torus_position(twin, thetas[:, 0], phis_[0]), toric.torus_position(torus, thetas[:, 0], phis_[0])) <= TOL
    )


def test_torus_position_refuses_shapes_that_do_not_broadcast():
    twin, torus = native.make_torus((0, 0, 0), (1, 0, 0), 0.5), toric.make_torus((0, 0, 0), (1, 0, 0), 0.5)
    with pytest.raises(ValueError):
        toric.torus_position(torus, np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError):
        native.torus_position(twin, np.zeros(3), np.zeros(4))


@st.composite
def positions(draw, torus: toric.Torus):
    """A point on the torus, pushed off it by up to 5 m, or anywhere in the 100 m box; not on AB."""
    if draw(st.booleans()):
        theta = draw(fractions) * toric.theta_max(torus.alpha)
        p = toric.torus_position(torus, theta, draw(phis)) + draw(st.floats(0.0, 5.0)) * draw(direction)
    else:
        p = draw(point)
    assume(off_axis_m(p, torus.a_world, torus.b_world) > 1e-2)
    return p


@FAST
@given(pairs(), alphas, st.data())
def test_torus_angles_match(pair, alpha, data):
    twin, torus = native.make_torus(*pair, alpha), toric.make_torus(*pair, alpha)
    ps = [data.draw(positions(torus)) for _ in range(5)]
    for p in ps:
        (theta, phi), (want_theta, want_phi) = native.torus_angles(twin, p), toric.torus_angles(torus, p)
        assert abs(theta - want_theta) <= TOL
        assert angle_diff(phi, want_phi) <= TOL
        assert -math.pi < phi <= math.pi
    thetas, phis_ = native.torus_angles_many(twin, np.array(ps))
    want_thetas, want_phis = toric.torus_angles_many(torus, np.array(ps))
    assert max_diff(thetas, want_thetas) <= TOL
    assert max(angle_diff(p, q) for p, q in zip(phis_, want_phis, strict=True)) <= TOL


@FAST
@given(pairs(), alphas, fractions, phis)
def test_tangent_frame_matches(pair, alpha, fraction, phi):
    twin, torus = native.make_torus(*pair, alpha), toric.make_torus(*pair, alpha)
    theta = fraction * toric.theta_max(alpha)
    for got, want in zip(native.tangent_frame(twin, theta, phi), toric.tangent_frame(torus, theta, phi), strict=True):
        assert max_diff(got, want) <= TOL


# --- orientation ----------------------------------------------------------------------------------


@st.composite
def cameras(draw, a, b, alpha):
    """A camera on the torus of A, B, alpha or anywhere in the 100 m box; off the line AB."""
    if draw(st.booleans()):
        c = toric.torus_position(toric.make_torus(a, b, alpha), draw(fractions) * toric.theta_max(alpha), draw(phis))
    else:
        c = draw(point)
    assume(off_axis_m(c, a, b) > 1e-2)
    return c


@FAST
@given(scenes(), st.data())
def test_look_and_level_pair_rotations_match(scene, data):
    a, b, sa, sb, lens, alpha = scene
    c = data.draw(cameras(a, b, alpha))
    assert quat_diff(native.look_rotation(c, a, b, sa, sb, lens), toric.look_rotation(c, a, b, sa, sb, lens)) <= TOL
    assert quat_diff(native.level_pair_rotation(c, a, b, sa, sb, lens), toric.level_pair_rotation(c, a, b, sa, sb, lens)) <= TOL


@FAST
@given(scenes(), st.data())
def test_level_pair_matrices_match_with_their_nan_rows(scene, data):
    a, b, sa, sb, lens, alpha = scene
    cs = np.array([data.draw(cameras(a, b, alpha)) for _ in range(6)] + [a, b, 0.5 * (a + b)])
    got = native.level_pair_matrices(cs, a, b, sa, sb, lens)
    assert max_diff(got, toric.level_pair_matrices(cs, a, b, sa, sb, lens)) <= TOL
    assert np.isnan(got[-3:]).all() and not np.isnan(got[:-3]).any()
    assert (
        max_diff(native.level_pair_matrices(cs[0], a, b, sa, sb, lens), toric.level_pair_matrices(cs[0], a, b, sa, sb, lens))
        <= TOL
    )


@pytest.mark.parametrize("where", ["at A", "at B", "between A and B", "in line beyond B"])
def test_cameras_on_the_line_ab_raise_value_error_in_both(where):
    a, b, lens = np.array([1.0, 2.0, 3.0]), np.array([4.0, 0.0, 7.0]), Lens()
    c = {"at A": a, "at B": b, "between A and B": 0.5 * (a + b), "in line beyond B": b + 2.0 * (b - a)}[where]
    sa, sb = (-0.3, 0.1), (0.4, -0.2)
    rotations = [(native.look_rotation, toric.look_rotation)]
    if where != "in line beyond B":  # the level pair frames a pair in line with the view, one above the other
        rotations.append((native.level_pair_rotation, toric.level_pair_rotation))
    for twin, python in rotations:
        with pytest.raises(ValueError):
            python(c, a, b, sa, sb, lens)
        with pytest.raises(ValueError):
            twin(c, a, b, sa, sb, lens)


@FAST
@given(scenes(), fractions, phis)
def test_compose_pose_matches(scene, fraction, phi):
    a, b, sa, sb, lens, alpha = scene
    twin, torus = native.make_torus(a, b, alpha), toric.make_torus(a, b, alpha)
    theta = fraction * toric.theta_max(alpha)
    # near the arc's ends the camera is at A or B, where a rounding's worth of position turns the view
    assume(off_axis_m(toric.torus_position(torus, theta, phi), a, b) > 1e-2)
    position, rotation, vertical_fov_deg = native.compose_pose(twin, theta, phi, sa, sb, lens)
    want = toric.compose_pose(torus, theta, phi, sa, sb, lens)
    assert max_diff(position, want.position_world) <= TOL
    assert quat_diff(rotation, want.rotation_xyzw) <= TOL
    assert vertical_fov_deg == want.vertical_fov_deg


# --- determinism ----------------------------------------------------------------------------------


def test_the_same_inputs_give_the_same_bits():
    rng = np.random.default_rng(43)
    a, b, lens, sa, sb = rng.normal(size=3) * 30, rng.normal(size=3) * 30, Lens(55.0, 1.6), (-0.4, 0.2), (0.3, -0.1)
    alpha = native.composition_angle(sa, sb, lens)
    thetas, phis_ = rng.uniform(0.0, native.theta_max(alpha), 390), rng.uniform(-math.pi, math.pi, 390)

    def run():
        torus = native.make_torus(a, b, alpha)
        places = native.torus_position(torus, thetas, phis_)
        outputs = [torus.basis, torus.mid_world, np.array([torus.arc_radius_m, torus.center_offset_m]), places]
        outputs += [*native.torus_angles_many(torus, places + 0.5), np.array(native.torus_angles(torus, places[7] + 0.5))]
        outputs += [*native.tangent_frame(torus, 0.4, 2.0), native.level_pair_matrices(places, a, b, sa, sb, lens)]
        outputs += [
            native.look_rotation(places[3], a, b, sa, sb, lens),
            native.level_pair_rotation(places[3], a, b, sa, sb, lens),
        ]
        outputs += list(native.compose_pose(torus, thetas[5], phis_[5], sa, sb, lens)[:2])
        return [np.asarray(o, dtype=np.float64).tobytes() for o in outputs]

    assert run() == run()
