//! Points carried by a rigid transform: the twin of geometry/transforms.py's
//! `RigidTransform.apply`, world = position + R(rotation) (scale * local), in plain f64 arithmetic
//! in one fixed order, so the same bits on every x86-64 machine. numpy's `@` hands the same
//! product to OpenBLAS, whose kernel (and so the last bits: FMA or not, the order of the sums)
//! depends on the CPU (tests/worker/machine_kinds.py plays other CPUs' kernels on this one).

use crate::rotation::{quat_to_matrix, Vec3};
use crate::scene::Pose;

/// Each point's ((R[i][0] s0 x + R[i][1] s1 y) + R[i][2] s2 z) + p[i], R the quaternion's matrix
/// as quat_to_matrix's scalar form makes it (the quaternion used as given, as Python does).
pub fn carry(pose: &Pose, points_local: &[Vec3]) -> Vec<Vec3> {
    let r = quat_to_matrix(&pose.rotation_xyzw);
    let (s, p) = (pose.scale, pose.position);
    points_local
        .iter()
        .map(|l| {
            let v = [l[0] * s[0], l[1] * s[1], l[2] * s[2]];
            [0, 1, 2].map(|i| v[0] * r[i][0] + v[1] * r[i][1] + v[2] * r[i][2] + p[i])
        })
        .collect()
}
