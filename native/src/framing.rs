//! The TORIC rig's FRAMING stage: the twin of src/camdirector/pipeline/toric/framing.py (class
//! Framing), whose module docstring says what A, B, the gaze-room point and the heading are.
//! Plain Rust; the Python binding is stages_py.rs. Python's operation order, libm's
//! transcendentals (atan2, exp, sin, cos, remainder, hypot).

use std::f64::consts::TAU;

use crate::rotation::{quat_to_matrix, Vec3};
use crate::toric::{self, Lens, Torus};

/// framing.FramingSettings.
#[derive(Clone, Copy, Debug)]
pub struct FramingSettings {
    pub heading_time_constant_s: f64,
    pub heading_min_speed_m_s: f64,
    pub min_ab_distance_m: f64,
}

/// The style fields FRAMING reads (pipeline/style.py's Style): the screen points of A and B and
/// the one-target gaze room, metres.
#[derive(Clone, Copy, Debug)]
pub struct FramingStyle {
    pub screen_a: [f64; 2],
    pub screen_b: [f64; 2],
    pub gaze_room_m: f64,
}

/// One frame's framing (frame.ToricFrame's points and torus, and what degraded).
pub struct Framed {
    pub a_world: Vec3,
    pub b_world: Vec3,
    pub b_is_gaze_point: bool,
    pub torus: Option<Torus>, // None: degenerate ("degenerate_torus" in flags)
    pub flags: Vec<&'static str>,
}

/// Keeps the one-target heading between frames and frames each frame (framing.Framing).
pub struct Framing {
    pub settings: FramingSettings,
    pub lens: Lens,
    pub style: FramingStyle,
    pub alpha: f64,
    pub heading_rad: f64,
    pub last_aim: Option<Vec3>,
}

impl Framing {
    /// The heading starts as the target's facing: its local +Z turned by initial_rotation_xyzw,
    /// 0 when that points (nearly) straight up or down.
    pub fn new(
        lens: Lens,
        style: FramingStyle,
        initial_rotation_xyzw: &[f64; 4],
        settings: FramingSettings,
    ) -> Framing {
        let m = quat_to_matrix(initial_rotation_xyzw);
        let forward = [m[0][2], m[1][2], m[2][2]]; // (0, 0, 1) @ M^T: the third column
        let heading_rad = if libm::hypot(forward[0], forward[2]) > 1e-6 {
            libm::atan2(forward[0], forward[2])
        } else {
            0.0
        };
        Framing {
            settings,
            lens,
            alpha: toric::composition_angle(&style.screen_a, &style.screen_b, &lens),
            style,
            heading_rad,
            last_aim: None,
        }
    }

    pub fn set_style(&mut self, style: FramingStyle) {
        self.alpha = toric::composition_angle(&style.screen_a, &style.screen_b, &self.lens);
        self.style = style;
    }

    /// The gaze-room point ahead of aim along the smoothed horizontal heading; updates the heading.
    fn gaze_point(&mut self, aim: &Vec3, dt_s: f64) -> Vec3 {
        if let Some(last) = self.last_aim {
            if dt_s > 0.0 {
                let (vx, vz) = ((aim[0] - last[0]) / dt_s, (aim[2] - last[2]) / dt_s);
                if libm::hypot(vx, vz) > self.settings.heading_min_speed_m_s {
                    let error = libm::remainder(libm::atan2(vx, vz) - self.heading_rad, TAU);
                    self.heading_rad +=
                        error * (1.0 - libm::exp(-dt_s / self.settings.heading_time_constant_s));
                }
            }
        }
        self.last_aim = Some(*aim);
        let g = self.style.gaze_room_m;
        let (s, c) = libm::sincos(self.heading_rad);
        [aim[0] + g * s, aim[1] + 0.0, aim[2] + g * c] // + 0.0 as numpy adds it: -0.0 becomes 0.0
    }

    /// A, B and the torus of a frame's aim points (one or two targets; (3,) metres each).
    pub fn run(&mut self, aims: &[Vec3], dt_s: f64) -> Framed {
        let a = aims[0];
        let mut flags = Vec::new();
        let (b, b_is_gaze_point) = if aims.len() == 2 {
            let b = aims[1];
            let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() < self.settings.min_ab_distance_m {
                flags.push("targets_coincide");
                (self.gaze_point(&a, dt_s), true)
            } else {
                (b, false)
            }
        } else {
            (self.gaze_point(&a, dt_s), true)
        };
        let torus = toric::make_torus(&a, &b, self.alpha, &[0.0, 1.0, 0.0]).ok();
        if torus.is_none() {
            flags.push("degenerate_torus");
        }
        Framed {
            a_world: a,
            b_world: b,
            b_is_gaze_point,
            torus,
            flags,
        }
    }

    /// framing.Framing.error: the largest per-axis distance, normalised screen units, of A (and
    /// of B when it is a target) from the style's screen points, seen from the pose (position
    /// metres, camera-to-world rotation xyzw); NaN when a point is behind the camera.
    pub fn error(
        &self,
        position: &Vec3,
        rotation_xyzw: &[f64; 4],
        a: &Vec3,
        b: &Vec3,
        b_is_gaze_point: bool,
    ) -> f64 {
        let m = quat_to_matrix(rotation_xyzw);
        let column = |j: usize| [m[0][j], m[1][j], m[2][j]];
        let (right, up, back) = (column(0), column(1), column(2));
        let dot = |d: &Vec3, axis: &Vec3| d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2];
        let mut worst = f64::NEG_INFINITY;
        let mut any_nan = false;
        let framed: &[(&Vec3, &[f64; 2])] = if b_is_gaze_point {
            &[(a, &self.style.screen_a)]
        } else {
            &[(a, &self.style.screen_a), (b, &self.style.screen_b)]
        };
        for (point, goal) in framed {
            let d = [
                point[0] - position[0],
                point[1] - position[1],
                point[2] - position[2],
            ];
            let depth = -dot(&d, &back);
            if depth <= 0.0 || depth.is_nan() {
                // project_to_screen's NaN behind the camera; numpy's max propagates it
                any_nan = true;
                continue;
            }
            let x = dot(&d, &right) / (depth * self.lens.tan_half_fov_x);
            let y = dot(&d, &up) / (depth * self.lens.tan_half_fov_y);
            for e in [(x - goal[0]).abs(), (y - goal[1]).abs()] {
                any_nan |= e.is_nan();
                worst = worst.max(e);
            }
        }
        if any_nan {
            f64::NAN
        } else {
            worst
        }
    }
}
