//! Rotations the Toric rig needs: twins of geometry/transforms.py's `matrix_to_quat` and
//! geometry/camera.py's `level_rotation` / `level_rotations`, in the same operation order so the
//! results agree with Python's to the last bits but for libm's transcendental kernels.
//!
//! Conventions (as in Python): quaternions (x, y, z, w) camera-to-world; matrices row-major
//! `[[f64; 3]; 3]`, `m[row][column]`, the camera's axes in the columns.

use std::f64::consts::{PI, TAU};

pub type Vec3 = [f64; 3];
pub type Mat3 = [[f64; 3]; 3];

/// Unit quaternion (x, y, z, w), w >= 0, of a rotation matrix (transforms.matrix_to_quat):
/// Shepperd's method, branching on the largest diagonal term so no square root of a small
/// number is taken, then normalised and turned to w >= 0 (transforms.quat_normalize).
pub fn matrix_to_quat(m: &Mat3) -> [f64; 4] {
    let trace = m[0][0] + m[1][1] + m[2][2];
    let q = if trace > 0.0 {
        let s = 2.0 * (1.0 + trace).sqrt();
        [
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
            0.25 * s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = 2.0 * (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt();
        [
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[2][1] - m[1][2]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = 2.0 * (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt();
        [
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
            (m[0][2] - m[2][0]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt();
        [
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
            (m[1][0] - m[0][1]) / s,
        ]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let sign = if q[3] / n < 0.0 { -1.0 } else { 1.0 };
    q.map(|c| sign * (c / n))
}

/// The yaw-about-+Y-after-pitch-about-x rotation R = Ry(yaw) Rx(pitch) (camera.level_rotations),
/// from its pitch and yaw in radians: camera-to-world, no roll.
fn yaw_pitch_matrix(yaw: f64, pitch: f64) -> Mat3 {
    let (sp, cp) = libm::sincos(pitch);
    let (sw, cw) = libm::sincos(yaw);
    [
        [cw, sw * sp, sw * cp],
        [0.0, cp, -sp],
        [-sw, cw * sp, cw * cp],
    ]
}

/// The two pitches (radians) that bring the unit camera-space direction `camera_dir` to the
/// elevation of the unit world direction `world_dir`, and camera_dir's (rho, delta) about x.
fn pitches(world_dir: &Vec3, camera_dir: &Vec3) -> (f64, f64) {
    let (dy, dz) = (camera_dir[1], camera_dir[2]);
    let rho = libm::hypot(dy, dz);
    let delta = libm::atan2(dz, dy);
    let base = libm::acos((world_dir[1] / rho).clamp(-1.0, 1.0));
    (base - delta, -base - delta)
}

/// Yaw (radians) that turns camera_dir, pitched by `pitch`, onto world_dir's azimuth.
fn yaw_for(world_dir: &Vec3, camera_dir: &Vec3, pitch: f64) -> f64 {
    let (sp, cp) = libm::sincos(pitch);
    libm::atan2(world_dir[0], world_dir[2])
        - libm::atan2(camera_dir[0], camera_dir[1] * sp + camera_dir[2] * cp)
}

/// (3, 3) camera-to-world rotation with no roll turning the unit camera-space direction
/// camera_dir onto the unit world direction world_dir (camera.level_rotation, the scalar form):
/// of the two pitches the one nearer level, by IEEE remainder (Python's math.remainder).
pub fn level_rotation(world_dir: &Vec3, camera_dir: &Vec3) -> Mat3 {
    let (up, down) = pitches(world_dir, camera_dir);
    // Python's min(..., key=...) keeps the first on a tie.
    let pitch = if libm::remainder(down, TAU).abs() < libm::remainder(up, TAU).abs() {
        down
    } else {
        up
    };
    yaw_pitch_matrix(yaw_for(world_dir, camera_dir, pitch), pitch)
}

/// numpy's remainder (np.remainder, Python's float %): the result takes the divisor's sign.
pub fn floor_mod(a: f64, b: f64) -> f64 {
    let m = libm::fmod(a, b);
    if m == 0.0 {
        0.0f64.copysign(b)
    } else if (b < 0.0) != (m < 0.0) {
        m + b
    } else {
        m
    }
}

/// One row of camera.level_rotations (the batched form): its pitch choice wraps with numpy's
/// floored remainder; a NaN world direction gives an all-NaN matrix.
pub fn level_rotation_batched(world_dir: &Vec3, camera_dir: &Vec3) -> Mat3 {
    let (up, down) = pitches(world_dir, camera_dir);
    let wrap = |p: f64| (floor_mod(p + PI, TAU) - PI).abs();
    let pitch = if wrap(up) <= wrap(down) { up } else { down };
    if pitch.is_nan() {
        return [[f64::NAN; 3]; 3];
    }
    yaw_pitch_matrix(yaw_for(world_dir, camera_dir, pitch), pitch)
}

/// Rotation matrix of the quaternion q (x, y, z, w) (transforms.quat_to_matrix, its per-frame
/// scalar form; q need not be unit): camera-to-world for a camera's rotation, its axes in the
/// columns.
pub fn quat_to_matrix(q: &[f64; 4]) -> Mat3 {
    let [x, y, z, w] = *q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The rotation vector (axis times angle, radians, world frame) of the turn from `before` to `now`,
/// quaternions (x, y, z, w) of any nonzero length: scipy's `(Rotation.from_quat(now) *
/// Rotation.from_quat(before).inv()).as_rotvec()` (each quaternion normalised, the turn
/// now * conj(before), taken with w >= 0, then 2 atan2(|v|, w) about v; the same series below 1e-3
/// rad), its numbers within rounding, its bits the libm crate's on every machine. None for a zero
/// quaternion, which from_quat refuses.
pub fn turn_rotvec(before: &[f64; 4], now: &[f64; 4]) -> Option<Vec3> {
    let unit = |q: &[f64; 4]| {
        let norm = libm::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        (norm > 0.0 && norm.is_finite()).then(|| q.map(|c| c / norm))
    };
    let [ax, ay, az, aw] = unit(now)?;
    let [bx, by, bz, bw] = unit(before)?.map(|c| -c); // the inverse's vector part, negated below for w
    let bw = -bw;
    // Hamilton product now * conj(before): (aw b + bw a + a x b, aw bw - a . b), b the conjugate's vector
    let mut turn = [
        aw * bx + bw * ax + (ay * bz - az * by),
        aw * by + bw * ay + (az * bx - ax * bz),
        aw * bz + bw * az + (ax * by - ay * bx),
        aw * bw - (ax * bx + ay * by + az * bz),
    ];
    if turn[3] < 0.0 {
        turn = turn.map(|c| -c);
    }
    let sine = libm::sqrt(turn[0] * turn[0] + turn[1] * turn[1] + turn[2] * turn[2]);
    let angle = 2.0 * libm::atan2(sine, turn[3]);
    let scale = if angle <= 1e-3 {
        let angle2 = angle * angle;
        2.0 + angle2 / 12.0 + 7.0 * angle2 * angle2 / 2880.0
    } else {
        angle / libm::sin(angle / 2.0)
    };
    Some([scale * turn[0], scale * turn[1], scale * turn[2]])
}
