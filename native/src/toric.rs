//! Toric space (Lino & Christie 2012/2015; shared/papers/toric-space-primer.md sections 1-5): the
//! twin of src/camdirector/geometry/toric.py, whose module docstring fixes the angles (alpha,
//! theta in (0, 2 (pi - alpha)), phi in (-pi, pi]) and the closed form used here. Plain Rust on
//! `[f64; 3]`; the Python binding is toric_py.rs. Each step keeps the Python's operation order;
//! sin, cos, atan2, acos are libm's (the same bits on every x86-64 machine).
//!
//! Conventions: right-handed world, +Y up, metres, radians; the camera looks down its local -Z
//! with +Y up; normalised screen x right, y up, in [-1, 1].

use std::f64::consts::{PI, TAU};

use crate::rotation::{level_rotation, level_rotation_batched, matrix_to_quat, Mat3, Vec3};

pub const MIN_AB_DISTANCE_M: f64 = 1e-6;
pub const MIN_ALPHA_RAD: f64 = 1e-4; // alpha must lie in [MIN_ALPHA_RAD, pi - MIN_ALPHA_RAD]
pub const PARALLEL_SIN_EPS: f64 = 1e-6; // |sin(AB, up)| below this uses the fallback reference direction
pub const THETA_MARGIN_RAD: f64 = 1e-6; // torus_angles keeps theta this far inside its open range

/// The lens as the Toric math reads it (camera.Lens): tangents of the half fields of view.
#[derive(Clone, Copy, Debug)]
pub struct Lens {
    pub tan_half_fov_x: f64,
    pub tan_half_fov_y: f64,
}

impl Lens {
    /// From the full vertical field of view, degrees, and the aspect (width / height), as
    /// camera.Lens's properties compute them (math.radians is x * (pi / 180)).
    pub fn new(vertical_fov_deg: f64, aspect: f64) -> Lens {
        let tan_half_fov_y = libm::tan(vertical_fov_deg * (PI / 180.0) / 2.0);
        Lens {
            tan_half_fov_x: tan_half_fov_y * aspect,
            tan_half_fov_y,
        }
    }
}

/// The torus of camera centres framing A and B at angle alpha (toric.Torus; primer section 2).
/// Vectors in metres, world frame; `basis` rows axis, ref, side: local -> world by local @ basis.
#[derive(Clone, Debug)]
pub struct Torus {
    pub a_world: Vec3,
    pub b_world: Vec3,
    pub alpha: f64,
    pub basis: Mat3,
    pub length_ab_m: f64,
    pub arc_radius_m: f64,
    pub mid_world: Vec3,
    pub center_offset_m: f64,
}

/// Why make_torus refuses its input (Python's DegenerateTorus messages).
#[derive(Debug)]
pub struct Degenerate(pub String);

fn cross(u: &Vec3, v: &Vec3) -> Vec3 {
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

fn norm(v: &Vec3) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// v / |v|; None for the zero vector (Python's ZeroDivisionError).
fn unit(v: &Vec3) -> Option<Vec3> {
    let n = norm(v);
    (n != 0.0).then(|| [v[0] / n, v[1] / n, v[2] / n])
}

/// Torus of the camera centres C with angle(A - C, B - C) = alpha (toric.make_torus; primer
/// sections 2-3). a, b, up: metres (up: any length); alpha: radians. Degenerate if |AB| <
/// MIN_AB_DISTANCE_M, alpha is outside [MIN_ALPHA_RAD, pi - MIN_ALPHA_RAD], an input is not
/// finite or up is zero. phi = 0 is on the side of up's component orthogonal to AB; when AB is
/// along up, world -Z (world +X if up is along Z) stands in for up (primer section 3).
pub fn make_torus(a: &Vec3, b: &Vec3, alpha: f64, up: &Vec3) -> Result<Torus, Degenerate> {
    if !a.iter().chain(b).chain(up).all(|c| c.is_finite()) {
        return Err(Degenerate("make_torus: non-finite input".into()));
    }
    let length = norm(&[b[0] - a[0], b[1] - a[1], b[2] - a[2]]);
    if length < MIN_AB_DISTANCE_M {
        return Err(Degenerate(format!(
            "make_torus: |AB| = {length:.3e} m < {MIN_AB_DISTANCE_M} m"
        )));
    }
    if !(MIN_ALPHA_RAD..=PI - MIN_ALPHA_RAD).contains(&alpha) {
        // also rejects NaN
        return Err(Degenerate(format!(
            "make_torus: alpha = {alpha} rad outside [{MIN_ALPHA_RAD}, pi - {MIN_ALPHA_RAD}]"
        )));
    }
    let up_norm = norm(up);
    if up_norm == 0.0 {
        return Err(Degenerate("make_torus: up_world is zero".into()));
    }
    let axis = [
        (b[0] - a[0]) / length,
        (b[1] - a[1]) / length,
        (b[2] - a[2]) / length,
    ];
    // side = unit(axis x up), ref = side x axis: built with cross products so the basis stays
    // orthonormal to rounding even when AB is nearly vertical.
    let mut side = cross(&axis, up);
    if norm(&side) < PARALLEL_SIN_EPS * up_norm {
        side = cross(&axis, &[0.0, 0.0, -1.0]);
        if norm(&side) < PARALLEL_SIN_EPS {
            // only when up itself is along Z
            side = cross(&axis, &[1.0, 0.0, 0.0]);
        }
    }
    let side = unit(&side).expect("side is at least PARALLEL_SIN_EPS long");
    let radius = length / (2.0 * libm::sin(alpha));
    Ok(Torus {
        a_world: *a,
        b_world: *b,
        alpha,
        basis: [axis, cross(&side, &axis), side],
        length_ab_m: length,
        arc_radius_m: radius,
        mid_world: [
            0.5 * (a[0] + b[0]),
            0.5 * (a[1] + b[1]),
            0.5 * (a[2] + b[2]),
        ],
        center_offset_m: radius * libm::cos(alpha),
    })
}

/// Upper end 2 (pi - alpha) of theta's open range (0, theta_max), radians (toric.theta_max).
pub fn theta_max(alpha: f64) -> f64 {
    2.0 * (PI - alpha)
}

/// Unit camera-space direction d(s) through the normalised screen point s (primer section 1).
pub fn view_direction(screen: &[f64; 2], lens: &Lens) -> Vec3 {
    unit(&[
        screen[0] * lens.tan_half_fov_x,
        screen[1] * lens.tan_half_fov_y,
        -1.0,
    ])
    .expect("z is -1")
}

/// alpha, radians: the angle between the view rays through screen_a and screen_b (primer section
/// 1), as atan2(|a x b|, a . b), accurate near 0 and pi where acos is not.
pub fn composition_angle(screen_a: &[f64; 2], screen_b: &[f64; 2], lens: &Lens) -> f64 {
    let a = view_direction(screen_a, lens);
    let b = view_direction(screen_b, lens);
    let c = cross(&a, &b);
    libm::atan2(norm(&c), a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
}

/// local (x along AB, y_ref, y_side) @ basis + mid: torus-local metres to world.
fn to_world(torus: &Torus, local: &Vec3) -> Vec3 {
    let m = &torus.basis;
    let mut out = [0.0; 3];
    for (j, o) in out.iter_mut().enumerate() {
        *o = local[0] * m[0][j] + local[1] * m[1][j] + local[2] * m[2][j] + torus.mid_world[j];
    }
    out
}

/// Camera centre, metres, at (theta, phi) radians (toric.torus_position; primer section 3, in
/// the closed form x = -r sin(alpha + theta), y = r (cos alpha - cos(alpha + theta)) of the
/// arc's half-plane turned by phi about AB). A theta outside its open range continues around the
/// arc's circle into the opposite half-plane.
pub fn torus_position(torus: &Torus, theta: f64, phi: f64) -> Vec3 {
    torus_position_of(torus, arc_sincos(torus, theta), libm::sincos(phi))
}

/// sin and cos of alpha + theta, the arc's angle of theta: what torus_position and tangent_frame
/// read of theta (sincos: one argument reduction, the same bits as libm::sin and libm::cos).
pub fn arc_sincos(torus: &Torus, theta: f64) -> (f64, f64) {
    libm::sincos(torus.alpha + theta)
}

/// torus_position from arc_sincos(theta) and sincos(phi): a grid of (theta, phi) takes one
/// sincos per row and per column instead of two per point, for the same bits (maps.rs).
pub fn torus_position_of(torus: &Torus, (s, c): (f64, f64), (sp, cp): (f64, f64)) -> Vec3 {
    let r = torus.arc_radius_m;
    let radial = torus.center_offset_m - r * c;
    to_world(torus, &[-r * s, radial * cp, radial * sp])
}

/// theta (radians) of the torus-local point (x, radial), brought onto the arc as
/// toric.torus_angles says: the nearer arc end when it lands outside the arc, then clamped to
/// [THETA_MARGIN_RAD, theta_max - THETA_MARGIN_RAD].
fn arc_theta(torus: &Torus, x: f64, radial: f64) -> f64 {
    let mut theta = crate::rotation::floor_mod(
        libm::atan2(-x, torus.center_offset_m - radial) - torus.alpha,
        TAU,
    );
    let hi = theta_max(torus.alpha);
    if theta > hi {
        // the circle's other part spans (hi, 2 pi): snap to the nearer arc end
        theta = if theta - hi < TAU - theta { hi } else { 0.0 };
    }
    theta.max(THETA_MARGIN_RAD).min(hi - THETA_MARGIN_RAD)
}

/// (theta, phi) radians of the torus point for position (metres) (toric.torus_angles; primer
/// section 5, the inverse map): phi from the point's half-plane about AB (0 on the axis), in
/// (-pi, pi]; theta from the nearest point of the arc's circle in that half-plane. Exact
/// inverse of torus_position on the torus.
pub fn torus_angles(torus: &Torus, position: &Vec3) -> (f64, f64) {
    let d = [
        position[0] - torus.mid_world[0],
        position[1] - torus.mid_world[1],
        position[2] - torus.mid_world[2],
    ];
    let m = &torus.basis;
    let [x, y_ref, y_side] = [0, 1, 2].map(|i| m[i][0] * d[0] + m[i][1] * d[1] + m[i][2] * d[2]);
    let mut phi = libm::atan2(y_side, y_ref);
    if phi == -PI {
        // keep phi in (-pi, pi]
        phi = PI;
    }
    let radial = libm::hypot(y_ref, y_side);
    (arc_theta(torus, x, radial), phi)
}

/// (d pos/d theta, d pos/d phi, outward unit normal) at (theta, phi), world (toric.tangent_frame;
/// primer "Distortion"): metres per radian, |d/d theta| = arc_radius_m, |d/d phi| = the distance
/// to the axis; the normal points away from the arc's circle centre.
pub fn tangent_frame(torus: &Torus, theta: f64, phi: f64) -> [Vec3; 3] {
    tangent_frame_of(torus, arc_sincos(torus, theta), libm::sincos(phi))
}

/// tangent_frame from arc_sincos(theta) and sincos(phi), as torus_position_of.
pub fn tangent_frame_of(torus: &Torus, (s, c): (f64, f64), (sp, cp): (f64, f64)) -> [Vec3; 3] {
    let r = torus.arc_radius_m;
    let radial = torus.center_offset_m - r * c;
    let local = [
        [-r * c, r * s * cp, r * s * sp],
        [0.0, -radial * sp, radial * cp],
        [-s, -c * cp, -c * sp],
    ];
    let m = &torus.basis;
    local.map(|l| [0, 1, 2].map(|j| l[0] * m[0][j] + l[1] * m[1][j] + l[2] * m[2][j]))
}

/// Why a rotation cannot be built (Python's ValueError messages).
#[derive(Debug)]
pub struct NoRotation(pub String);

/// Orthonormal matrix with columns p, q Gram-Schmidt against p, p x q (p, q unit; primer step 4).
fn frame(p: &Vec3, q: &Vec3) -> Result<Mat3, NoRotation> {
    let [px, py, pz] = *p;
    let k = px * q[0] + py * q[1] + pz * q[2];
    let o = [q[0] - k * px, q[1] - k * py, q[2] - k * pz];
    let n = norm(&o);
    if n < 1e-12 {
        return Err(NoRotation(
            "look_rotation: the two directions are parallel".into(),
        ));
    }
    let [ox, oy, oz] = [o[0] / n, o[1] / n, o[2] / n];
    Ok([
        [px, ox, py * oz - pz * oy],
        [py, oy, pz * ox - px * oz],
        [pz, oz, px * oy - py * ox],
    ])
}

/// Unit directions from the camera to A and to B; an error naming `what` if it is at one.
fn rays_to(camera: &Vec3, a: &Vec3, b: &Vec3, what: &str) -> Result<(Vec3, Vec3), NoRotation> {
    let at = || NoRotation(format!("{what}: the camera is at a framed point"));
    let to_a = unit(&[a[0] - camera[0], a[1] - camera[1], a[2] - camera[2]]).ok_or_else(at)?;
    let to_b = unit(&[b[0] - camera[0], b[1] - camera[1], b[2] - camera[2]]).ok_or_else(at)?;
    Ok((to_a, to_b))
}

/// Camera-to-world unit quaternion (x, y, z, w), w >= 0, showing A at screen_a and B at
/// screen_b (toric.look_rotation; primer step 4): R = W D^T, W and D the frames of the world and
/// camera direction pairs. Exact on the torus of composition_angle(screen_a, screen_b, lens).
pub fn look_rotation(
    camera: &Vec3,
    a: &Vec3,
    b: &Vec3,
    screen_a: &[f64; 2],
    screen_b: &[f64; 2],
    lens: &Lens,
) -> Result<[f64; 4], NoRotation> {
    let (to_a, to_b) = rays_to(camera, a, b, "look_rotation")?;
    let world = frame(&to_a, &to_b)?;
    let camera_frame = frame(
        &view_direction(screen_a, lens),
        &view_direction(screen_b, lens),
    )?;
    let r = [0, 1, 2].map(|i| {
        [0, 1, 2].map(|j| {
            world[i][0] * camera_frame[j][0]
                + world[i][1] * camera_frame[j][1]
                + world[i][2] * camera_frame[j][2]
        })
    });
    Ok(matrix_to_quat(&r))
}

/// unit(d(sA) + d(sB)): the camera-space bisector of the screen points' rays.
fn screen_bisector(screen_a: &[f64; 2], screen_b: &[f64; 2], lens: &Lens) -> Vec3 {
    let (u, v) = (
        view_direction(screen_a, lens),
        view_direction(screen_b, lens),
    );
    let s = [u[0] + v[0], u[1] + v[1], u[2] + v[2]];
    let n = norm(&s);
    [s[0] / n, s[1] / n, s[2] / n]
}

/// unit(to_a + to_b), or None when the camera is between A and B on their line.
fn world_bisector(to_a: &Vec3, to_b: &Vec3) -> Option<Vec3> {
    let w = [to_a[0] + to_b[0], to_a[1] + to_b[1], to_a[2] + to_b[2]];
    let length = norm(&w);
    if length < 1e-12 {
        None
    } else {
        Some([w[0] / length, w[1] / length, w[2] / length]) // a NaN length goes on to NaN, as in Python
    }
}

/// Camera-to-world unit quaternion (x, y, z, w) with no roll framing A near screen_a and B near
/// screen_b (toric.level_pair_rotation): the bisector of the rays to A and B shown where the
/// bisector of the screen points' rays points, with yaw and pitch only (camera.level_rotation).
pub fn level_pair_rotation(
    camera: &Vec3,
    a: &Vec3,
    b: &Vec3,
    screen_a: &[f64; 2],
    screen_b: &[f64; 2],
    lens: &Lens,
) -> Result<[f64; 4], NoRotation> {
    let (to_a, to_b) = rays_to(camera, a, b, "level_pair_rotation")?;
    let w = world_bisector(&to_a, &to_b).ok_or_else(|| {
        NoRotation("level_pair_rotation: the camera is between the framed points".into())
    })?;
    Ok(matrix_to_quat(&level_rotation(
        &w,
        &screen_bisector(screen_a, screen_b, lens),
    )))
}

/// Camera-to-world rotation matrices of level_pair_rotation for many cameras
/// (toric.level_pair_matrices, by camera.level_rotations' batched rules); all NaN where a camera
/// is at A or B or between them on their line.
pub fn level_pair_matrices(
    cameras: &[Vec3],
    a: &Vec3,
    b: &Vec3,
    screen_a: &[f64; 2],
    screen_b: &[f64; 2],
    lens: &Lens,
) -> Vec<Mat3> {
    let bisector = screen_bisector(screen_a, screen_b, lens);
    cameras
        .iter()
        .map(|c| {
            // 0 / 0 = NaN where the camera is at a point, as numpy's division gives
            let ray = |p: &Vec3| {
                let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                let n = norm(&d);
                [d[0] / n, d[1] / n, d[2] / n]
            };
            let w = world_bisector(&ray(a), &ray(b)).unwrap_or([f64::NAN; 3]);
            level_rotation_batched(&w, &bisector)
        })
        .collect()
}

/// Pose (position metres, camera-to-world quaternion xyzw) at (theta, phi) radians framing
/// torus.a_world at screen_a and torus.b_world at screen_b (toric.compose_pose; primer steps 3-4);
/// the torus must be built with alpha = composition_angle(screen_a, screen_b, lens).
pub fn compose_pose(
    torus: &Torus,
    theta: f64,
    phi: f64,
    screen_a: &[f64; 2],
    screen_b: &[f64; 2],
    lens: &Lens,
) -> Result<(Vec3, [f64; 4]), NoRotation> {
    let position = torus_position(torus, theta, phi);
    let rotation = look_rotation(
        &position,
        &torus.a_world,
        &torus.b_world,
        screen_a,
        screen_b,
        lens,
    )?;
    Ok((position, rotation))
}
