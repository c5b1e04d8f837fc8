//! REACTIVE's MOTION post-stage compiled: pipeline/toric/reactive.py's `Deoccluder` (Cinemachine's
//! Deoccluder, "pull camera forward": a sampled sphere cast from A toward the rig's camera, the
//! camera put in front of the obstacle nearest A, the correction damped), in the Python's order of
//! operations. Its ray casts go through the session's `Scene`; its transcendentals are the libm
//! crate's, so a REACTIVE frame has the same bits on every x86-64 machine.

use std::f64::consts::TAU;

use crate::bvh::Stack;
use crate::rotation::{matrix_to_quat, quat_to_matrix, Mat3, Vec3};
use crate::scene::Scene;
use crate::search::{add, cross, div, dot, norm, scale, sub};

const EPSILON: f64 = 1e-4; // Cinemachine's UnityVectorExtensions.Epsilon
const RING_RAYS: usize = 8; // rays per ring of the sampled sphere cast

/// reactive.ReactiveSettings (Cinemachine 3's defaults), checked there.
#[derive(Clone, Copy, Debug)]
pub struct DeoccluderSettings {
    pub minimum_distance_m: f64,
    pub camera_radius_m: f64,
    pub damping_s: f64,
    pub damping_when_occluded_s: f64,
}

/// The part of an amount applied over dt_s with a damping time (reactive.damp): the factor the
/// amount is multiplied by (1 when damp_time_s is ~0, 0 when dt_s is ~0).
fn damp_factor(damp_time_s: f64, dt_s: f64) -> f64 {
    if damp_time_s < EPSILON {
        return 1.0;
    }
    if dt_s < EPSILON {
        return 0.0;
    }
    1.0 - libm::exp(-libm::log(100.0) / damp_time_s * dt_s)
}

fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, value) in row.iter_mut().enumerate() {
            *value = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    m
}

/// (offsets perpendicular to `direction`, depth ahead of the sphere's centre at each) of the
/// sampled sphere cast (reactive._ring_offsets): the axis, and rings at radius and radius / sqrt 2.
fn ring_offsets(direction: &Vec3, radius_m: f64) -> (Vec<Vec3>, Vec<f64>) {
    let helper = if direction[1].abs() < 0.9 {
        [0.0, 1.0, 0.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let u = cross(direction, &helper);
    let u = div(&u, norm(&u));
    let v = cross(direction, &u);
    let ring: Vec<Vec3> = (0..RING_RAYS)
        .map(|k| {
            let angle = k as f64 * (TAU / RING_RAYS as f64);
            add(&scale(&u, libm::cos(angle)), &scale(&v, libm::sin(angle)))
        })
        .collect();
    let inner_m = radius_m / 2.0_f64.sqrt();
    let mut offsets = vec![[0.0; 3]];
    offsets.extend(ring.iter().map(|r| scale(r, radius_m)));
    offsets.extend(ring.iter().map(|r| scale(r, inner_m)));
    let mut depth = vec![radius_m];
    depth.extend([0.0; RING_RAYS]);
    depth.extend([inner_m; RING_RAYS]);
    (offsets, depth)
}

/// The camera rotation turned by the least rotation taking A's direction seen from A + from_offset
/// to the direction seen from A + to_offset (reactive._turn_toward): A keeps its place on screen.
fn turn_toward(rotation_xyzw: &[f64; 4], from_offset: &Vec3, to_offset: &Vec3) -> [f64; 4] {
    let a = div(&scale(from_offset, -1.0), norm(from_offset));
    let b = div(&scale(to_offset, -1.0), norm(to_offset));
    let axis = cross(&a, &b);
    let (sin, cos) = (norm(&axis), dot(&a, &b));
    if sin < 1e-12 {
        return *rotation_xyzw;
    }
    let k = div(&axis, sin);
    let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
    let kx2 = mat_mul(&kx, &kx);
    let mut turn = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let identity = if i == j { 1.0 } else { 0.0 };
            turn[i][j] = identity + sin * kx[i][j] + (1.0 - cos) * kx2[i][j];
        }
    }
    matrix_to_quat(&mat_mul(&turn, &quat_to_matrix(rotation_xyzw)))
}

/// A session's Deoccluder: the last correction and damping time, kept between frames.
pub struct Deoccluder {
    pub settings: DeoccluderSettings,
    pub offset_from_a: Option<Vec3>, // last camera position - A, m (PreviousCameraOffset)
    pub displacement: Vec3,          // last correction, m (PreviousDisplacement)
    pub damp_time_s: f64,            // last damping time, s (PreviousDampTime)
    pub time_s: Option<f64>,         // when it last ran, s
    stack: Stack,
}

impl Deoccluder {
    pub fn new(settings: DeoccluderSettings) -> Deoccluder {
        Deoccluder {
            settings,
            offset_from_a: None,
            displacement: [0.0; 3],
            damp_time_s: 0.0,
            time_s: None,
            stack: Stack::new(),
        }
    }

    /// Where pull-forward puts a camera wanted at `camera` looking at `a`: `camera` itself when
    /// the line to A is clear, else just in front of the obstacle nearest A.
    pub fn clear_position(&mut self, camera: &Vec3, a: &Vec3, scene: &Scene) -> Vec3 {
        let s = self.settings;
        let offset = sub(camera, a);
        let distance = norm(&offset);
        if distance <= EPSILON {
            return *camera;
        }
        let direction = div(&offset, distance);
        if distance < s.minimum_distance_m + EPSILON {
            return add(a, &scale(&direction, s.minimum_distance_m));
        }
        let start = s.minimum_distance_m.max(s.camera_radius_m); // the sphere starts radius from A
        let length = distance - start;
        if length <= EPSILON {
            return *camera;
        }
        let (offsets, depth) = if s.camera_radius_m >= EPSILON {
            ring_offsets(&direction, s.camera_radius_m)
        } else {
            (vec![[0.0; 3]], vec![0.0])
        };
        let base = add(a, &scale(&direction, start));
        let ray = scale(&direction, length);
        let mut nearest: Option<f64> = None; // sphere centre at first contact, from start
        for (offset, depth) in offsets.iter().zip(&depth) {
            // only contacts within the segment count: the walk stops at its end (inf: none)
            let t = scene.first_hit_within(&add(&base, offset), &ray, 1.0, &mut self.stack);
            if t.is_finite() {
                let along = t * length - depth;
                nearest = Some(nearest.map_or(along, |n: f64| n.min(along)));
            }
        }
        match nearest {
            None => *camera,
            Some(along) => add(a, &scale(&direction, start + along.max(0.0))),
        }
    }

    /// reactive.Deoccluder.run: the rig's proposed pose (position, rotation) at time_s, dt_s after
    /// the previous frame, corrected to keep the line to A clear and damped; and whether the camera
    /// is not where the rig put it.
    pub fn run(
        &mut self,
        position: &Vec3,
        rotation_xyzw: &[f64; 4],
        a: &Vec3,
        time_s: f64,
        dt_s: f64,
        scene: &Scene,
    ) -> (Vec3, [f64; 4], bool) {
        let s = self.settings;
        let wanted = *position;
        let mut displacement = sub(&self.clear_position(&wanted, a, scene), &wanted);
        let mut damp_time = s.damping_when_occluded_s;
        let continuing = self
            .time_s
            .is_some_and(|last| (time_s - dt_s - last).abs() < 1e-9);
        self.time_s = Some(time_s);
        if continuing && s.damping_s + s.damping_when_occluded_s > EPSILON {
            let growing =
                dot(&displacement, &displacement) > dot(&self.displacement, &self.displacement);
            damp_time = if growing {
                s.damping_when_occluded_s
            } else {
                s.damping_s
            };
            if dot(&displacement, &displacement) < EPSILON {
                // ease the damping time itself out
                damp_time = self.damp_time_s - self.damp_time_s * damp_factor(damp_time, dt_s);
            }
            let offset_from_a = self
                .offset_from_a
                .expect("set by the run on the previous frame");
            let previous = sub(&add(a, &offset_from_a), &wanted);
            let step = scale(&sub(&displacement, &previous), damp_factor(damp_time, dt_s));
            displacement = add(&previous, &step);
        }
        let camera = add(&wanted, &displacement);
        self.displacement = displacement;
        self.offset_from_a = Some(sub(&camera, a));
        self.damp_time_s = damp_time;
        if norm(&displacement) <= 1e-3 {
            return (*position, *rotation_xyzw, false);
        }
        let rotation = turn_toward(rotation_xyzw, &sub(&wanted, a), &sub(&camera, a));
        (camera, rotation, true)
    }
}
