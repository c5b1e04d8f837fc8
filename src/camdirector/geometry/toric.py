"""Toric space: every camera centre that frames two world points A, B at two given screen points.

Math: toric-space-primer.md sections 1-5 (Lino & Christie 2012/2015). Conventions are those of
geometry.camera: right-handed world, +Y up, metres, radians; the camera looks down its local -Z with
+Y up; normalised screen x right, y up, in [-1, 1].

Angles, fixed project-wide:

- alpha: the angle between the view rays d(sA), d(sB); set by the screen points and the lens alone.
- theta in (0, 2 (pi - alpha)): where on the arc. beta = theta / 2 is the angle at B between B->A and
  B->C, so theta -> 0 puts C at A and theta -> 2 (pi - alpha) puts C at B. By the inscribed-angle
  theorem theta is also the central angle of the arc's circle from A to C, so arc length is
  r * theta: the camera's speed along theta is uniform in metres.
- phi in (-pi, pi]: the rotation of the arc's half-plane about the axis `axis_world` = unit(B - A).
  phi = 0 is the reference half-plane, on the side of the component of world up orthogonal to AB
  (the camera is above the axis). Positive phi turns the half-plane by the right-hand rule about
  unit(B - A), so phi = +pi/2 is on the side of unit(cross(B - A, up)) and phi = +-pi is below the axis.
  Seen from phi = +pi/2 with AB level, A is on the camera's left: a composition with sA left of sB
  is upright there and upside down at phi = -pi/2.
- When |sin(angle(AB, up))| < PARALLEL_SIN_EPS, the reference direction is world -Z projected
  orthogonal to AB (world +X if up itself is along Z). phi is continuous only away from that case.

In the arc's half-plane, with origin the midpoint M of AB, x along AB and y away from the axis, the
arc's circle has radius r = |AB| / (2 sin alpha) and centre (0, r cos alpha), and the camera is at
    x = -r sin(alpha + theta),    y = r (cos alpha - cos(alpha + theta)).
This closed form equals the primer's law-of-sines construction and inverts with a single atan2.

Orientation: `look_rotation` is the exact composition, A at sA and B at sB (the TORIC rig's),
rolling the camera whenever that demands it (over a shoulder from above the A-B
axis it rolls by tens of degrees: up to 85 in the MATCH rig's programs). `level_pair_rotation`
(and `level_pair_matrices`) is the broadcast one: no roll, the bisector of the rays to A and B on
the bisector of the screen points' rays, equal to look_rotation whenever that has no roll.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose, Lens, level_rotation, level_rotations
from camdirector.geometry.transforms import matrix_to_quat

MIN_AB_DISTANCE_M = 1e-6
MIN_ALPHA_RAD = 1e-4  # alpha must lie in [MIN_ALPHA_RAD, pi - MIN_ALPHA_RAD]
PARALLEL_SIN_EPS = 1e-6  # |sin(AB, up)| below this uses the fallback reference direction
THETA_MARGIN_RAD = 1e-6  # torus_angles keeps theta this far inside its open range


class DegenerateTorus(ValueError):
    """A, B and alpha name no usable torus (A and B coincide, alpha near 0 or pi, non-finite input)."""


@dataclass(frozen=True, eq=False)  # eq=False: identity equality, numpy fields cannot be compared with ==
class Torus:
    """The torus of camera centres framing A and B at angle alpha. Build it with make_torus.

    a_world, b_world: (3,) metres. alpha: radians. axis_world: (3,) unit(B - A). ref_world: (3,) unit,
    orthogonal to the axis, the phi = 0 direction. side_world: (3,) unit, cross(axis, ref), the
    phi = +pi/2 direction. length_ab_m: |AB|. arc_radius_m: |AB| / (2 sin alpha).
    Arrays are read-only.
    """

    a_world: npt.NDArray[np.float64]
    b_world: npt.NDArray[np.float64]
    alpha: float
    axis_world: npt.NDArray[np.float64]
    ref_world: npt.NDArray[np.float64]
    side_world: npt.NDArray[np.float64]
    length_ab_m: float
    arc_radius_m: float
    mid_world: npt.NDArray[np.float64] = field(repr=False)  # (3,) midpoint of AB, the origin of the closed form
    basis: npt.NDArray[np.float64] = field(repr=False)  # (3, 3) rows axis, ref, side: local -> world by @ basis
    center_offset_m: float = field(repr=False)  # r cos(alpha): distance of the arc's centre off the axis


def _read_only(v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    v.setflags(write=False)
    return v


def _floats3(v: npt.ArrayLike, name: str) -> list[float]:
    out = np.asarray(v, dtype=np.float64).reshape(-1)
    if out.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {np.shape(v)}")
    return out.tolist()


def _cross(u: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
    return u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]


def _unit_tuple(x: float, y: float, z: float) -> tuple[float, float, float]:
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


def make_torus(a_world: npt.ArrayLike, b_world: npt.ArrayLike, alpha: float, up_world: npt.ArrayLike = (0.0, 1.0, 0.0)) -> Torus:
    """Torus of the camera centres C with angle(A - C, B - C) = alpha.

    a_world, b_world, up_world: (3,) metres (up: any length). alpha: radians.
    Raises DegenerateTorus if |AB| < MIN_AB_DISTANCE_M, alpha is outside
    [MIN_ALPHA_RAD, pi - MIN_ALPHA_RAD], or an input is not finite or up is zero;
    ValueError if a shape is wrong.
    """
    # Python floats, not numpy: this runs every frame and 3-vector ufuncs cost more than the math.
    a = _floats3(a_world, "a_world")
    b = _floats3(b_world, "b_world")
    up = _floats3(up_world, "up_world")
    alpha = float(alpha)
    if not all(map(math.isfinite, a + b + up)):
        raise DegenerateTorus("make_torus: non-finite input")
    length = math.dist(a, b)
    if length < MIN_AB_DISTANCE_M:
        raise DegenerateTorus(f"make_torus: |AB| = {length:.3g} m < {MIN_AB_DISTANCE_M} m")
    if not MIN_ALPHA_RAD <= alpha <= math.pi - MIN_ALPHA_RAD:  # also rejects NaN
        raise DegenerateTorus(f"make_torus: alpha = {alpha!r} rad outside [{MIN_ALPHA_RAD}, pi - {MIN_ALPHA_RAD}]")
    up_norm = math.hypot(*up)
    if up_norm == 0.0:
        raise DegenerateTorus("make_torus: up_world is zero")
    axis = tuple((q - p) / length for p, q in zip(a, b))
    # side = unit(axis x up), ref = side x axis: the projection of up orthogonal to AB, built with
    # cross products so the basis stays orthonormal to rounding even when AB is nearly vertical.
    side = _cross(axis, up)
    if math.hypot(*side) < PARALLEL_SIN_EPS * up_norm:
        side = _cross(axis, (0.0, 0.0, -1.0))
        if math.hypot(*side) < PARALLEL_SIN_EPS:  # only when up itself is along Z
            side = _cross(axis, (1.0, 0.0, 0.0))
    side = _unit_tuple(*side)
    basis = np.array((axis, _cross(side, axis), side))
    basis.setflags(write=False)  # the rows below are views of it, read-only too
    radius = length / (2.0 * math.sin(alpha))
    return Torus(
        a_world=_read_only(np.array(a)),
        b_world=_read_only(np.array(b)),
        alpha=alpha,
        axis_world=basis[0],
        ref_world=basis[1],
        side_world=basis[2],
        length_ab_m=length,
        arc_radius_m=radius,
        mid_world=_read_only(np.array([0.5 * (p + q) for p, q in zip(a, b)])),
        basis=basis,
        center_offset_m=radius * math.cos(alpha),
    )


def theta_max(alpha: float) -> float:
    """Upper end 2 (pi - alpha) of theta's open range (0, theta_max), radians; C is at B there."""
    return 2.0 * (math.pi - alpha)


def _view_dir(screen_xy: Sequence[float], lens: Lens) -> tuple[float, float, float]:
    return _unit_tuple(float(screen_xy[0]) * lens.tan_half_fov_x, float(screen_xy[1]) * lens.tan_half_fov_y, -1.0)


def view_direction(screen_xy: Sequence[float], lens: Lens) -> npt.NDArray[np.float64]:
    """Unit camera-space direction (3,) through the normalised screen point screen_xy (2,)."""
    return np.array(_view_dir(screen_xy, lens))


def composition_angle(screen_a: Sequence[float], screen_b: Sequence[float], lens: Lens) -> float:
    """alpha: angle in radians between the view rays through screen_a (2,) and screen_b (2,)."""
    ax, ay, az = _view_dir(screen_a, lens)
    bx, by, bz = _view_dir(screen_b, lens)
    # atan2(|a x b|, a.b) stays accurate near 0 and pi where acos(a.b) does not.
    cross = math.sqrt((ay * bz - az * by) ** 2 + (az * bx - ax * bz) ** 2 + (ax * by - ay * bx) ** 2)
    return math.atan2(cross, ax * bx + ay * by + az * bz)


def torus_position(
    torus: Torus, theta: float | npt.NDArray[np.float64], phi: float | npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Camera centre, metres, at (theta, phi) radians.

    Scalars give (3,); arrays broadcast together, shape (...,) -> (..., 3). A theta outside its open
    range continues around the arc's circle into the opposite half-plane.
    """
    r = torus.arc_radius_m
    if np.ndim(theta) == 0 and np.ndim(phi) == 0:
        # Per-frame path: math on floats is an order of magnitude cheaper than ufuncs on 0-d arrays.
        t = torus.alpha + float(theta)
        phi_rad = float(phi)
        radial = torus.center_offset_m - r * math.cos(t)
        local: npt.NDArray[np.float64] = np.array((-r * math.sin(t), radial * math.cos(phi_rad), radial * math.sin(phi_rad)))
    else:
        ts = torus.alpha + np.asarray(theta, dtype=np.float64)
        phis = np.asarray(phi, dtype=np.float64)
        radials = torus.center_offset_m - r * np.cos(ts)
        local = np.stack(np.broadcast_arrays(-r * np.sin(ts), radials * np.cos(phis), radials * np.sin(phis)), axis=-1)
    return local @ torus.basis + torus.mid_world


def torus_angles(torus: Torus, position_world: npt.ArrayLike) -> tuple[float, float]:
    """(theta, phi) radians of the torus point for position_world (3,) metres.

    A point off the torus is first brought onto it: phi is kept from the point's half-plane about
    AB (phi = 0 for a point on the axis), then the point goes to the nearest point of the arc's circle
    in that half-plane. If that lands on the part of the circle outside the arc (it belongs to the
    opposite half-plane), theta goes to the nearer end of the arc. theta is clamped to
    [THETA_MARGIN_RAD, theta_max - THETA_MARGIN_RAD]. Exact inverse of torus_position on the torus.
    """
    x, y_ref, y_side = (torus.basis @ (np.asarray(position_world, dtype=np.float64) - torus.mid_world)).tolist()
    phi = math.atan2(y_side, y_ref)
    if phi == -math.pi:  # keep phi in (-pi, pi]
        phi = math.pi
    radial = math.hypot(y_ref, y_side)
    # From the closed form: -x = r sin(alpha + theta), offset - radial = r cos(alpha + theta).
    theta = (math.atan2(-x, torus.center_offset_m - radial) - torus.alpha) % math.tau
    hi = theta_max(torus.alpha)
    if theta > hi:  # the circle's other part spans (hi, 2 pi): snap to the nearer arc end
        theta = hi if theta - hi < math.tau - theta else 0.0
    return min(max(theta, THETA_MARGIN_RAD), hi - THETA_MARGIN_RAD), phi


def torus_angles_many(torus: Torus, positions_world: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """torus_angles for (n, 3) points at once: (theta (n,), phi (n,)) radians, same rules."""
    local = (np.asarray(positions_world, dtype=np.float64) - torus.mid_world) @ torus.basis.T
    x, y_ref, y_side = local[:, 0], local[:, 1], local[:, 2]
    phi = np.arctan2(y_side, y_ref)
    phi[phi == -math.pi] = math.pi
    radial = np.hypot(y_ref, y_side)
    theta = (np.arctan2(-x, torus.center_offset_m - radial) - torus.alpha) % math.tau
    hi = theta_max(torus.alpha)
    outside = theta > hi
    theta[outside] = np.where(theta[outside] - hi < math.tau - theta[outside], hi, 0.0)
    return np.clip(theta, THETA_MARGIN_RAD, hi - THETA_MARGIN_RAD), phi


def tangent_frame(
    torus: Torus, theta: float, phi: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(d pos/d theta, d pos/d phi, outward unit normal) at (theta, phi), each (3,) world.

    The derivatives are metres per radian: |d/d theta| = arc_radius_m, |d/d phi| = the camera's
    distance to the axis. The normal points away from the arc's circle centre, the direction in which
    the angle subtended by AB falls below alpha.
    """
    r = torus.arc_radius_m
    t = torus.alpha + float(theta)
    s, c = math.sin(t), math.cos(t)
    sp, cp = math.sin(phi), math.cos(phi)
    radial = torus.center_offset_m - r * c
    local = np.array(
        (
            (-r * c, r * s * cp, r * s * sp),
            (0.0, -radial * sp, radial * cp),
            (-s, -c * cp, -c * sp),
        )
    )
    d_theta, d_phi, normal = local @ torus.basis
    return d_theta, d_phi, normal


def _frame(p: tuple[float, float, float], q: tuple[float, float, float]) -> npt.NDArray[np.float64]:
    """(3, 3) orthonormal matrix with columns p, q Gram-Schmidt against p, p x q (p, q unit)."""
    px, py, pz = p
    k = px * q[0] + py * q[1] + pz * q[2]
    ox, oy, oz = q[0] - k * px, q[1] - k * py, q[2] - k * pz
    n = math.sqrt(ox * ox + oy * oy + oz * oz)
    if n < 1e-12:
        raise ValueError("look_rotation: the two directions are parallel")
    ox, oy, oz = ox / n, oy / n, oz / n
    return np.array(
        (
            (px, ox, py * oz - pz * oy),
            (py, oy, pz * ox - px * oz),
            (pz, oz, px * oy - py * ox),
        )
    )


def _rays_to(
    camera_world: npt.ArrayLike, a_world: npt.ArrayLike, b_world: npt.ArrayLike, what: str
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Unit directions (3,) from the camera to A and to B; ValueError naming `what` if it is at one."""
    cx, cy, cz = np.asarray(camera_world, dtype=np.float64).tolist()
    ax, ay, az = np.asarray(a_world, dtype=np.float64).tolist()
    bx, by, bz = np.asarray(b_world, dtype=np.float64).tolist()
    try:
        return _unit_tuple(ax - cx, ay - cy, az - cz), _unit_tuple(bx - cx, by - cy, bz - cz)
    except ZeroDivisionError:
        raise ValueError(f"{what}: the camera is at a framed point") from None


def look_rotation(
    camera_world: npt.ArrayLike,
    a_world: npt.ArrayLike,
    b_world: npt.ArrayLike,
    screen_a: Sequence[float],
    screen_b: Sequence[float],
    lens: Lens,
) -> npt.NDArray[np.float64]:
    """Camera-to-world unit quaternion (4,) xyzw, w >= 0, that shows A at screen_a and B at screen_b.

    camera_world, a_world, b_world: (3,) metres; screen_a, screen_b: (2,). R = W D^T (primer step 4),
    D and W the frames of the camera-space and world-space direction pairs. Exact when the camera is
    on the torus of composition_angle(screen_a, screen_b, lens); otherwise A is exact and B lies in
    the right plane through the view axis. ValueError if the camera is at A or B or in line with both.
    """
    to_a, to_b = _rays_to(camera_world, a_world, b_world, "look_rotation")
    world = _frame(to_a, to_b)
    camera = _frame(_view_dir(screen_a, lens), _view_dir(screen_b, lens))
    return matrix_to_quat(world @ camera.T)


def _screen_bisector(screen_a: Sequence[float], screen_b: Sequence[float], lens: Lens) -> tuple[float, float, float]:
    """unit(d(sA) + d(sB)): the camera-space bisector of the screen points' rays."""
    u, v = _view_dir(screen_a, lens), _view_dir(screen_b, lens)
    return _unit_tuple(u[0] + v[0], u[1] + v[1], u[2] + v[2])


def level_pair_rotation(
    camera_world: npt.ArrayLike,
    a_world: npt.ArrayLike,
    b_world: npt.ArrayLike,
    screen_a: Sequence[float],
    screen_b: Sequence[float],
    lens: Lens,
) -> npt.NDArray[np.float64]:
    """Camera-to-world unit quaternion (4,) xyzw with no roll (camera x axis horizontal) that
    frames A near screen_a and B near screen_b: broadcast framing keeps the horizon level.

    camera_world, a_world, b_world: (3,) metres; screen_a, screen_b: (2,). The bisector of the view
    rays to A and B, unit(unit(A - C) + unit(B - C)), is shown where the bisector of the screen
    points' rays, unit(d(sA) + d(sB)), points, with yaw and pitch only (geometry.camera.
    level_rotation). On the torus of composition_angle(screen_a, screen_b, lens) the two pairs
    of rays make the same angle, so the exact composition (look_rotation) maps one bisector onto
    the other: this is look_rotation turned about the bisector until the horizon is level. A and
    B stay symmetric about their bisector's screen point, each off its screen point by the turn
    (the roll the exact composition would need); when that roll is 0 this equals look_rotation.
    A pair nearly in line with the view (over a shoulder from above) is shown one above the
    other; one that no longer fits the frame is left to the caller's frame test (match
    shots.framed_seen). ValueError if the camera is at A or B or between them on their line.
    """
    to_a, to_b = _rays_to(camera_world, a_world, b_world, "level_pair_rotation")
    wx, wy, wz = to_a[0] + to_b[0], to_a[1] + to_b[1], to_a[2] + to_b[2]
    length = math.sqrt(wx * wx + wy * wy + wz * wz)
    if length < 1e-12:
        raise ValueError("level_pair_rotation: the camera is between the framed points")
    return matrix_to_quat(level_rotation((wx / length, wy / length, wz / length), _screen_bisector(screen_a, screen_b, lens)))


def level_pair_matrices(
    cameras_world: npt.ArrayLike,
    a_world: npt.ArrayLike,
    b_world: npt.ArrayLike,
    screen_a: Sequence[float],
    screen_b: Sequence[float],
    lens: Lens,
) -> npt.NDArray[np.float64]:
    """(m, 3, 3) camera-to-world rotation matrices of `level_pair_rotation` for m cameras (m, 3)
    at once (a shot's place search tries hundreds); rows of NaN where a camera is at A or B or
    between them on their line."""
    cameras = np.atleast_2d(np.asarray(cameras_world, dtype=np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        to_a = np.asarray(a_world, dtype=np.float64) - cameras
        to_a /= np.linalg.norm(to_a, axis=1, keepdims=True)
        to_b = np.asarray(b_world, dtype=np.float64) - cameras
        to_b /= np.linalg.norm(to_b, axis=1, keepdims=True)
        w = to_a + to_b
        length = np.linalg.norm(w, axis=1, keepdims=True)
        w = np.where(length < 1e-12, np.nan, w / length)
        return level_rotations(w, _screen_bisector(screen_a, screen_b, lens))


def compose_pose(
    torus: Torus, theta: float, phi: float, screen_a: Sequence[float], screen_b: Sequence[float], lens: Lens
) -> CameraPose:
    """Pose at (theta, phi) radians that frames torus.a_world at screen_a (2,) and torus.b_world at
    screen_b (2,); torus must be built with alpha = composition_angle(screen_a, screen_b, lens)."""
    position = torus_position(torus, theta, phi)
    rotation = look_rotation(position, torus.a_world, torus.b_world, screen_a, screen_b, lens)
    return CameraPose(position_world=position, rotation_xyzw=rotation, vertical_fov_deg=lens.vertical_fov_deg)
