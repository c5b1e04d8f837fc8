"""Toric space (geometry/toric.py): composition, inverse map, continuity, world-unit steps, conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.toric import (
    THETA_MARGIN_RAD,
    DegenerateTorus,
    Torus,
    compose_pose,
    composition_angle,
    level_pair_matrices,
    level_pair_rotation,
    look_rotation,
    make_torus,
    tangent_frame,
    theta_max,
    torus_angles,
    torus_position,
    view_direction,
)
from camdirector.geometry.transforms import quat_to_matrix

FAST = settings(max_examples=150, derandomize=True, deadline=None, database=None)

coord = st.floats(-50.0, 50.0)
point = st.tuples(coord, coord, coord).map(np.array)
screen = st.tuples(st.floats(-0.9, 0.9), st.floats(-0.9, 0.9))
lenses = st.builds(Lens, vertical_fov_deg=st.floats(20.0, 100.0), aspect=st.floats(0.5, 2.5))
unit_interval = st.floats(0.05, 0.95)  # safe interior fraction of theta's range
phis = st.floats(-math.pi, math.pi)


def angle_between(u: np.ndarray, v: np.ndarray) -> float:
    return math.atan2(np.linalg.norm(np.cross(u, v)), u @ v)


def rotation_angle(q1: np.ndarray, q2: np.ndarray) -> float:
    """Angle of the rotation between two quaternions, blind to the q / -q sign."""
    return 2.0 * math.acos(min(1.0, abs(float(q1 @ q2))))


@st.composite
def scenes(draw):
    """(torus, screen_a, screen_b, lens): A, B well separated, alpha in [0.05, pi - 0.05]."""
    a, b = draw(point), draw(point)
    assume(np.linalg.norm(b - a) > 0.5)
    lens = draw(lenses)
    sa, sb = draw(screen), draw(screen)
    alpha = composition_angle(sa, sb, lens)
    assume(0.05 <= alpha <= math.pi - 0.05)
    return make_torus(a, b, alpha), sa, sb, lens


def interior(torus: Torus, fraction: float) -> float:
    return fraction * theta_max(torus.alpha)


# --- composition -------------------------------------------------------------------------------


@FAST
@given(scenes(), unit_interval, phis)
def test_pose_projects_targets_onto_their_screen_points(scene, fraction, phi):
    torus, sa, sb, lens = scene
    pose = compose_pose(torus, interior(torus, fraction), phi, sa, sb, lens)
    got = project_to_screen(pose, lens, np.stack([torus.a_world, torus.b_world]))
    np.testing.assert_allclose(got, [sa, sb], atol=1e-6, rtol=0)
    assert pose.vertical_fov_deg == lens.vertical_fov_deg


@FAST
@given(scenes(), unit_interval, phis)
def test_camera_sees_ab_under_alpha(scene, fraction, phi):
    torus, _, _, _ = scene
    c = torus_position(torus, interior(torus, fraction), phi)
    assert abs(angle_between(torus.a_world - c, torus.b_world - c) - torus.alpha) < 1e-9


@FAST
@given(screen, screen, lenses)
def test_composition_angle_matches_view_directions(sa, sb, lens):
    da, db = view_direction(sa, lens), view_direction(sb, lens)
    np.testing.assert_allclose([np.linalg.norm(da), np.linalg.norm(db)], 1.0, atol=1e-15)
    assert da[2] < 0.0  # in front of the camera
    assert composition_angle(sa, sb, lens) == pytest.approx(angle_between(da, db), abs=1e-12)


def test_hand_built_symmetric_case():
    # A, B at x = -+1, screen points at x = -+0.5, fov 90 deg, aspect 1: tan(fovx/2) = 1, so
    # tan(alpha/2) = 0.5. theta = pi - alpha is the symmetric place (equal angles at A and B), on the
    # perpendicular bisector at distance 1 / tan(alpha/2) = 2; phi = +pi/2 is cross(B - A, up) = +Z.
    # From (0, 0, 2) looking down -Z the framing needs no rotation.
    lens = Lens(vertical_fov_deg=90.0, aspect=1.0)
    sa, sb = (-0.5, 0.0), (0.5, 0.0)
    alpha = composition_angle(sa, sb, lens)
    assert alpha == pytest.approx(2.0 * math.atan(0.5), abs=1e-15)
    torus = make_torus((-1.0, 0.0, 0.0), (1.0, 0.0, 0.0), alpha)
    pose = compose_pose(torus, math.pi - alpha, math.pi / 2, sa, sb, lens)
    np.testing.assert_allclose(pose.position_world, [0.0, 0.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(pose.rotation_xyzw, [0.0, 0.0, 0.0, 1.0], atol=1e-12)
    assert torus.arc_radius_m == pytest.approx(1.0 / math.sin(alpha))


# --- conventions -------------------------------------------------------------------------------


@FAST
@given(scenes(), unit_interval)
def test_phi_sign_convention(scene, fraction):
    """phi = 0 above the axis, +pi/2 toward unit(cross(B - A, up)), -pi/2 opposite, pi below."""
    torus, _, _, _ = scene
    a, b = torus.a_world, torus.b_world
    up = np.array([0.0, 1.0, 0.0])
    assume(np.linalg.norm(np.cross(b - a, up)) > 1e-3 * np.linalg.norm(b - a))
    side = np.cross(b - a, up)
    side /= np.linalg.norm(side)
    up_perp = up - (up @ torus.axis_world) * torus.axis_world
    up_perp /= np.linalg.norm(up_perp)
    theta = interior(torus, fraction)

    def offset(phi):  # camera minus its foot on the axis
        c = torus_position(torus, theta, phi)
        return c - a - ((c - a) @ torus.axis_world) * torus.axis_world

    radial = np.linalg.norm(offset(0.0))
    np.testing.assert_allclose(offset(0.0), radial * up_perp, atol=1e-9 * (1 + radial))
    np.testing.assert_allclose(offset(math.pi / 2), radial * side, atol=1e-9 * (1 + radial))
    np.testing.assert_allclose(offset(-math.pi / 2), -radial * side, atol=1e-9 * (1 + radial))
    np.testing.assert_allclose(offset(math.pi), -radial * up_perp, atol=1e-9 * (1 + radial))
    np.testing.assert_allclose(torus.side_world, side, atol=1e-12)
    # Right-hand rule about unit(B - A): increasing phi moves the camera along axis x offset.
    _, d_phi, _ = tangent_frame(torus, theta, 0.3)
    np.testing.assert_allclose(d_phi, np.cross(torus.axis_world, offset(0.3)), atol=1e-9 * (1 + radial))


def test_phi_plus_half_pi_is_upright_for_a_left_of_b():
    lens = Lens(60.0, 16 / 9)
    sa, sb = (-0.4, 0.1), (0.4, 0.1)
    torus = make_torus((0.0, 1.0, 0.0), (2.0, 1.0, 0.5), composition_angle(sa, sb, lens))
    for phi, sign in ((math.pi / 2, 1.0), (-math.pi / 2, -1.0)):
        camera_up = quat_to_matrix(compose_pose(torus, 2.0, phi, sa, sb, lens).rotation_xyzw)[:, 1]
        assert sign * camera_up[1] > 0.9


def test_theta_ends_are_a_and_b():
    torus = make_torus((1.0, 2.0, 3.0), (4.0, 0.0, 3.5), 1.1)
    np.testing.assert_allclose(torus_position(torus, 0.0, 0.7), torus.a_world, atol=1e-12)
    at_b = torus_position(torus, theta_max(torus.alpha), 0.7)
    np.testing.assert_allclose(at_b, torus.b_world, atol=1e-12)
    assert theta_max(1.1) == pytest.approx(2.0 * (math.pi - 1.1))


@FAST
@given(scenes(), unit_interval, phis)
def test_matches_primer_law_of_sines(scene, fraction, phi):
    """beta = theta / 2 is the angle at B between B->A and B->C, |BC| = |AB| sin(alpha + beta) / sin(alpha)."""
    torus, _, _, _ = scene
    theta = interior(torus, fraction)
    c = torus_position(torus, theta, phi)
    a, b = torus.a_world, torus.b_world
    assert angle_between(a - b, c - b) == pytest.approx(theta / 2, abs=1e-9)
    expected_bc = torus.length_ab_m * math.sin(torus.alpha + theta / 2) / math.sin(torus.alpha)
    assert np.linalg.norm(c - b) == pytest.approx(expected_bc, rel=1e-9)


# --- inverse map -------------------------------------------------------------------------------


@FAST
@given(scenes(), unit_interval, phis)
def test_round_trip_position_angles_position(scene, fraction, phi):
    torus, _, _, _ = scene
    theta = interior(torus, fraction)
    c = torus_position(torus, theta, phi)
    theta2, phi2 = torus_angles(torus, c)
    assert -math.pi < phi2 <= math.pi
    assert theta2 == pytest.approx(theta, abs=1e-9)
    assert abs(math.remainder(phi2 - phi, math.tau)) < 1e-9
    np.testing.assert_allclose(torus_position(torus, theta2, phi2), c, atol=1e-9, rtol=0)


@FAST
@given(scenes(), unit_interval, phis, st.floats(-0.5, 0.5))
def test_points_off_the_torus_along_the_normal_project_back(scene, fraction, phi, push):
    torus, _, _, _ = scene
    theta = interior(torus, fraction)
    c = torus_position(torus, theta, phi)
    d_theta, d_phi, normal = tangent_frame(torus, theta, phi)
    # Stay within half the distance to the axis and to the arc's centre so the half-plane is kept.
    p = c + push * min(np.linalg.norm(d_phi), torus.arc_radius_m) * normal
    theta2, phi2 = torus_angles(torus, p)
    assert theta2 == pytest.approx(theta, abs=1e-9)
    assert abs(math.remainder(phi2 - phi, math.tau)) < 1e-9


def test_points_beyond_the_arc_snap_to_the_nearer_end():
    torus = make_torus((-1.0, 0.0, 0.0), (1.0, 0.0, 0.0), 2.0)  # alpha > pi/2: the arc's centre is below
    hi = theta_max(torus.alpha)
    # Just above the axis beyond B, then beyond A: the nearest circle point is off the arc.
    assert torus_angles(torus, (1.5, 1e-3, 0.0))[0] == pytest.approx(hi - THETA_MARGIN_RAD, abs=1e-15)
    assert torus_angles(torus, (-1.5, 1e-3, 0.0))[0] == pytest.approx(THETA_MARGIN_RAD, abs=1e-15)
    theta, phi = torus_angles(torus, (0.0, 0.0, 0.0))  # on the axis: phi = 0 by definition
    assert phi == 0.0 and THETA_MARGIN_RAD <= theta <= hi - THETA_MARGIN_RAD


def test_phi_range_is_half_open():
    torus = make_torus((-1.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0)
    assert torus_angles(torus, (0.0, -2.0, -0.0))[1] == math.pi
    assert torus_angles(torus, (0.0, -2.0, 0.0))[1] == math.pi


# --- continuity and world-unit steps -----------------------------------------------------------


def pose_change(p1, p2) -> tuple[float, float]:
    """(metres moved, radians turned) between two poses."""
    moved = float(np.linalg.norm(p1.position_world - p2.position_world))
    return moved, rotation_angle(p1.rotation_xyzw, p2.rotation_xyzw)


@FAST
@given(scenes(), unit_interval, phis, st.sampled_from([(1.0, 0.0), (0.0, 1.0), (0.6, -0.8)]))
def test_small_parameter_steps_give_small_pose_changes(scene, fraction, phi, direction):
    torus, sa, sb, lens = scene
    theta, step = interior(torus, fraction), 1e-6
    d_theta, d_phi, _ = tangent_frame(torus, theta, phi)
    p1 = compose_pose(torus, theta, phi, sa, sb, lens)
    p2 = compose_pose(torus, theta + step * direction[0], phi + step * direction[1], sa, sb, lens)
    moved, turned = pose_change(p1, p2)
    expected = np.linalg.norm(step * direction[0] * d_theta + step * direction[1] * d_phi)
    assert moved == pytest.approx(expected, rel=1e-3, abs=1e-12)
    assert turned < 1e-3


@FAST
@given(scenes(), unit_interval)
def test_no_flip_across_phi_pi(scene, fraction):
    torus, sa, sb, lens = scene
    theta, eps = interior(torus, fraction), 1e-7
    before = compose_pose(torus, theta, math.pi - eps, sa, sb, lens)
    after = compose_pose(torus, theta, -math.pi + eps, sa, sb, lens)
    moved, turned = pose_change(before, after)
    radial = np.linalg.norm(tangent_frame(torus, theta, math.pi)[1])
    assert moved == pytest.approx(2 * eps * radial, rel=1e-3, abs=1e-12)
    assert turned < 1e-4
    # The inverse map wraps too: a step across -pi reads back one small signed step away.
    _, phi_after = torus_angles(torus, after.position_world)
    assert abs(math.remainder(phi_after - math.pi, math.tau) - eps) < 1e-8


@FAST
@given(scenes(), unit_interval, phis, st.floats(0.0, math.tau))
def test_world_step_maps_to_parameter_step_of_same_length(scene, fraction, phi, heading):
    torus, _, _, _ = scene
    theta = interior(torus, fraction)
    d_theta, d_phi, _ = tangent_frame(torus, theta, phi)
    radial = np.linalg.norm(d_phi)
    direction = math.cos(heading) * d_theta / torus.arc_radius_m + math.sin(heading) * d_phi / radial
    h = 0.01 * min(torus.arc_radius_m, radial)
    c = torus_position(torus, theta, phi)
    theta2, phi2 = torus_angles(torus, c + h * direction)
    # Length of the parameter step in the torus metric, and the chord between the torus points.
    metric = math.hypot(torus.arc_radius_m * (theta2 - theta), radial * math.remainder(phi2 - phi, math.tau))
    chord = np.linalg.norm(torus_position(torus, theta2, phi2) - c)
    assert metric == pytest.approx(h, rel=0.02)
    assert chord == pytest.approx(h, rel=0.02)


@FAST
@given(scenes(), unit_interval, phis)
def test_tangent_frame_matches_finite_differences(scene, fraction, phi):
    torus, _, _, _ = scene
    theta, step = interior(torus, fraction), 1e-6
    d_theta, d_phi, normal = tangent_frame(torus, theta, phi)
    scale = torus.arc_radius_m
    fd_theta = (torus_position(torus, theta + step, phi) - torus_position(torus, theta - step, phi)) / (2 * step)
    fd_phi = (torus_position(torus, theta, phi + step) - torus_position(torus, theta, phi - step)) / (2 * step)
    np.testing.assert_allclose(d_theta, fd_theta, atol=1e-6 * scale)
    np.testing.assert_allclose(d_phi, fd_phi, atol=1e-6 * scale)
    assert np.linalg.norm(d_theta) == pytest.approx(torus.arc_radius_m, rel=1e-12)
    assert np.linalg.norm(normal) == pytest.approx(1.0, abs=1e-12)
    assert abs(normal @ d_theta) < 1e-9 * scale and abs(normal @ d_phi) < 1e-9 * scale
    # Outward: moving along the normal shrinks the angle AB subtends.
    c = torus_position(torus, theta, phi) + 1e-3 * scale * normal
    assert angle_between(torus.a_world - c, torus.b_world - c) < torus.alpha


def test_torus_position_vectorises_like_the_scalar_path():
    torus = make_torus((0.5, 1.0, -2.0), (3.0, 1.5, 1.0), 0.8)
    thetas = np.linspace(0.1, theta_max(0.8) - 0.1, 5)
    phis_ = np.linspace(-3.0, 3.0, 4)
    grid = torus_position(torus, thetas[:, None], phis_)
    assert grid.shape == (5, 4, 3)
    expected = [[torus_position(torus, float(t), float(p)) for p in phis_] for t in thetas]
    np.testing.assert_allclose(grid, expected, atol=1e-12)
    assert torus_position(torus, thetas, 0.5).shape == (5, 3)


# --- degenerate input --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "a, b, alpha",
    [
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0),
        ((1.0, 2.0, 3.0), (1.0, 2.0, 3.0 + 5e-7), 1.0),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.0),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 5e-5),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), math.pi - 5e-5),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), math.pi),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), float("nan")),
        ((0.0, float("nan"), 0.0), (1.0, 0.0, 0.0), 1.0),
    ],
)
def test_degenerate_torus_raises(a, b, alpha):
    with pytest.raises(DegenerateTorus):
        make_torus(a, b, alpha)


def test_degenerate_torus_is_a_value_error_and_limits_are_inclusive():
    assert issubclass(DegenerateTorus, ValueError)
    make_torus((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1e-4)
    make_torus((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), math.pi - 1e-4)
    with pytest.raises(DegenerateTorus):
        make_torus((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0, up_world=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="shape"):
        make_torus((0.0, 0.0), (1.0, 0.0, 0.0), 1.0)


def test_look_rotation_rejects_undefined_frames():
    lens = Lens()
    a, b = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="framed point"):
        look_rotation(a, a, b, (-0.5, 0.0), (0.5, 0.0), lens)
    with pytest.raises(ValueError, match="parallel"):
        look_rotation((2.0, 0.0, 0.0), a, b, (-0.5, 0.0), (0.5, 0.0), lens)
    with pytest.raises(ValueError, match="parallel"):
        look_rotation((0.0, 0.0, 2.0), a, b, (0.3, 0.3), (0.3, 0.3), lens)


@FAST
@given(st.sampled_from([1.0, -1.0]), st.floats(0.0, 1e-7), screen, screen, lenses, unit_interval, phis)
def test_ab_parallel_to_up_still_composes_exactly(sign, tilt, sa, sb, lens, fraction, phi):
    alpha = composition_angle(sa, sb, lens)
    assume(0.05 <= alpha <= math.pi - 0.05)
    a = np.array([1.0, 2.0, 3.0])
    torus = make_torus(a, a + np.array([tilt, sign * 4.0, 0.0]), alpha)
    # Fallback reference: world -Z orthogonal to AB, so phi = 0 puts the camera toward -Z.
    np.testing.assert_allclose(torus.ref_world, [0.0, 0.0, -1.0], atol=1e-12)
    pose = compose_pose(torus, interior(torus, fraction), phi, sa, sb, lens)
    got = project_to_screen(pose, lens, np.stack([torus.a_world, torus.b_world]))
    np.testing.assert_allclose(got, [sa, sb], atol=1e-6, rtol=0)
    theta2, phi2 = torus_angles(torus, pose.position_world)
    np.testing.assert_allclose(torus_position(torus, theta2, phi2), pose.position_world, atol=1e-9)


def test_up_along_z_with_ab_along_z_falls_back_to_x():
    torus = make_torus((0.0, 0.0, 0.0), (0.0, 0.0, 2.0), 1.0, up_world=(0.0, 0.0, 3.0))
    np.testing.assert_allclose(torus.ref_world, [1.0, 0.0, 0.0], atol=1e-12)
    basis = np.stack([torus.axis_world, torus.ref_world, torus.side_world])
    np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(basis) == pytest.approx(1.0)


def test_torus_arrays_are_read_only():
    torus = make_torus((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0)
    with pytest.raises(ValueError):
        torus.a_world[0] = 5.0
    with pytest.raises(ValueError):
        torus.side_world[0] = 5.0


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.integers(0, 2**32 - 1))
def test_torus_angles_many_matches_the_scalar_form(seed):
    from camdirector.geometry.toric import torus_angles_many

    rng = np.random.default_rng(seed)
    torus = make_torus(rng.normal(size=3), rng.normal(size=3) + [3.0, 0.0, 0.0], rng.uniform(0.2, 2.5))
    points = rng.normal(size=(40, 3)) * 4.0
    theta, phi = torus_angles_many(torus, points)
    for point, t, p in zip(points, theta, phi):
        assert (t, p) == pytest.approx(torus_angles(torus, point), abs=1e-12)


# --- level pair framing (level_pair_rotation) ---------------------------------------------------

level_screen = st.tuples(st.floats(-0.9, 0.9), st.floats(-0.5, 0.5))
wide_lenses = st.builds(Lens, vertical_fov_deg=st.floats(20.0, 100.0), aspect=st.floats(1.0, 2.5))


def level_rotation(yaw: float, pitch: float) -> np.ndarray:
    """Ry(yaw) Rx(pitch): a camera-to-world rotation with no roll."""
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    return np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]]) @ np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])


@FAST
@given(point, point, point, screen, screen, lenses)
def test_level_pair_rotation_never_rolls_and_matches_its_many_camera_form(camera, a, b, sa, sb, lens):
    to_a, to_b = a - camera, b - camera
    assume(np.linalg.norm(to_a) > 1e-3 and np.linalg.norm(to_b) > 1e-3)
    assume(np.linalg.norm(to_a / np.linalg.norm(to_a) + to_b / np.linalg.norm(to_b)) > 1e-3)  # not between A and B
    matrix = quat_to_matrix(level_pair_rotation(camera, a, b, sa, sb, lens))
    np.testing.assert_allclose(matrix @ matrix.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(matrix) == pytest.approx(1.0)
    assert abs(matrix[1, 0]) < 1e-9  # the camera's right axis is horizontal: no roll
    many = level_pair_matrices(np.stack([camera, camera + 1.0]), a, b, sa, sb, lens)
    np.testing.assert_allclose(many[0], matrix, atol=1e-9)
    assert abs(many[1, 1, 0]) < 1e-12


@FAST
@given(point, phis, st.floats(-0.9, 0.9), level_screen, level_screen, lenses, st.floats(0.5, 30.0), st.floats(0.5, 30.0))
def test_level_pair_rotation_is_the_exact_composition_when_that_has_no_roll(
    camera, yaw, pitch, sa, sb, lens, distance_a, distance_b
):
    truth = level_rotation(yaw, pitch)
    a = camera + distance_a * truth @ view_direction(sa, lens)
    b = camera + distance_b * truth @ view_direction(sb, lens)
    assume(composition_angle(sa, sb, lens) > 0.01)
    np.testing.assert_allclose(quat_to_matrix(look_rotation(camera, a, b, sa, sb, lens)), truth, atol=1e-7)
    level = level_pair_rotation(camera, a, b, sa, sb, lens)
    np.testing.assert_allclose(quat_to_matrix(level), truth, atol=1e-7)
    pose = CameraPose(camera, level, lens.vertical_fov_deg)
    np.testing.assert_allclose(project_to_screen(pose, lens, np.stack([a, b])), [sa, sb], atol=1e-6)


@FAST
@given(point, point, unit_interval, phis, st.floats(0.0, 0.9), st.floats(-0.9, 0.9), wide_lenses)
def test_a_pair_composed_about_the_centre_stays_in_frame_at_every_place_of_its_torus(a, b, fraction, phi, sx, sy, lens):
    # screen points symmetric about the centre whose rays fit inside the vertical field of view:
    # the level camera shows them turned about the centre by the exact composition's roll, on the
    # circle of angular radius alpha / 2 about the view axis, so both stay in the frame, equally
    # far from their screen points, whatever the place (even where the exact composition is upside down)
    sa, sb = (-sx, -sy), (sx, sy)
    alpha = composition_angle(sa, sb, lens)
    assume(0.05 <= alpha <= 0.999 * math.radians(lens.vertical_fov_deg))
    assume(np.linalg.norm(b - a) > 0.1)
    torus = make_torus(a, b, alpha)
    camera = torus_position(torus, interior(torus, fraction), phi)
    rotation = level_pair_rotation(camera, a, b, sa, sb, lens)
    assert abs(quat_to_matrix(rotation)[1, 0]) < 1e-9
    got = project_to_screen(CameraPose(camera, rotation, lens.vertical_fov_deg), lens, np.stack([a, b]))
    assert np.all(np.abs(got) <= 1.0 + 1e-9)
    matrix = quat_to_matrix(rotation)
    error_a = angle_between(matrix @ view_direction(sa, lens), a - camera)
    error_b = angle_between(matrix @ view_direction(sb, lens), b - camera)
    assert error_a == pytest.approx(error_b, abs=1e-7)


@FAST
@given(unit_interval, st.floats(-1.0, 1.0), st.floats(2.0, 15.0), st.floats(-1.0, 1.0), phis)
def test_a_level_pair_seen_from_beside_it_keeps_its_composition(fraction, heading, distance, rise, phi):
    # beside a level pair (phi +-90 degrees, upright side), the exact composition has no roll,
    # above it the level camera turns the pair about its bisector by less than a right angle:
    # A stays left of B wherever the exact composition is upright
    lens, sa, sb = Lens(), (-1 / 3, 0.0), (1 / 3, 0.0)
    a = np.array([0.0, 1.2, 0.0])
    b = a + np.array([distance * math.cos(heading), 0.0, distance * math.sin(heading)])
    torus = make_torus(a, b, composition_angle(sa, sb, lens))
    beside = torus_position(torus, interior(torus, fraction), math.pi / 2)
    np.testing.assert_allclose(
        quat_to_matrix(level_pair_rotation(beside, a, b, sa, sb, lens)),
        quat_to_matrix(look_rotation(beside, a, b, sa, sb, lens)),
        atol=1e-9,
    )
    b = b + np.array([0.0, rise, 0.0])
    torus = make_torus(a, b, composition_angle(sa, sb, lens))
    upright = math.copysign(max(abs(phi), 0.05), phi) if abs(phi) < math.pi - 0.05 else math.copysign(math.pi - 0.05, phi)
    camera = torus_position(torus, interior(torus, fraction), upright)
    pose = CameraPose(camera, level_pair_rotation(camera, a, b, sa, sb, lens), lens.vertical_fov_deg)
    x = project_to_screen(pose, lens, np.stack([a, b]))[:, 0]
    assert (x[0] < x[1]) == (upright > 0.0)


def test_level_pair_rotation_rejects_a_camera_at_a_framed_point_or_between_them():
    lens = Lens()
    a, b = np.array([0.0, 1.6, 0.0]), np.array([4.0, 1.6, 0.0])
    with pytest.raises(ValueError, match="framed point"):
        level_pair_rotation(a, a, b, (-1 / 3, 0.0), (1 / 3, 0.0), lens)
    with pytest.raises(ValueError, match="between"):
        level_pair_rotation((a + b) / 2.0, a, b, (-1 / 3, 0.0), (1 / 3, 0.0), lens)
    many = level_pair_matrices(np.stack([a, (a + b) / 2.0, [2.0, 4.0, 6.0]]), a, b, (-1 / 3, 0.0), (1 / 3, 0.0), lens)
    assert np.isnan(many[:2]).all() and np.isfinite(many[2]).all()
