//! The TORIC rig's MOTION stage in the FRAMING_ONLY mode: the twin of
//! src/camdirector/pipeline/toric/camera_motion.py (ToricMotion, pose_on_torus), whose module
//! docstring says how the camera moves on the torus (projection of the last place, a critically
//! damped spring toward the style's place, acceleration and speed limited in metres). Plain
//! Rust; the Python binding is stages_py.rs. Python's operation order, libm's transcendentals.

use std::f64::consts::{PI, TAU};

use crate::rotation::{level_rotation, matrix_to_quat, quat_to_matrix, Vec3};
use crate::toric::{self, Lens, NoRotation, Torus};

/// camera_motion.MotionSettings.
#[derive(Clone, Copy, Debug)]
pub struct MotionSettings {
    pub max_substep_s: f64,
    pub max_substeps: u32,
    pub theta_margin_rad: f64,
    pub side_hysteresis: f64,
    pub side_recheck_axis_dot: f64,
    pub side_tie: f64,
}

/// The style fields MOTION reads (pipeline/style.py's Style).
#[derive(Clone, Copy, Debug)]
pub struct MotionStyle {
    pub screen_a: [f64; 2],
    pub screen_b: [f64; 2],
    pub preferred_theta_ratio: f64,
    pub preferred_phi_deg: f64,
    pub response_time_s: f64,
    pub max_speed_m_s: f64,
    pub max_accel_m_s2: f64,
}

/// A camera pose: position metres, camera-to-world quaternion xyzw (camera.CameraPose less its
/// field of view, which is the lens's).
pub type Pose = (Vec3, [f64; 4]);

/// math.radians: x * (pi / 180).
fn radians(deg: f64) -> f64 {
    deg * (PI / 180.0)
}

fn norm(v: &Vec3) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The camera's place (theta, phi) on the torus and its rates (camera_motion.ToricMotion).
pub struct Motion {
    pub settings: MotionSettings,
    pub lens: Lens,
    pub style: MotionStyle,
    pub theta: Option<f64>, // None until the first torus
    pub phi: f64,
    pub rate: [f64; 2], // (dtheta/dt, dphi/dt), rad/s
    pub position_world: Option<Vec3>,
    pub side: f64, // +1 or -1: which half of the torus is upright (0 before the first choice)
    pub side_key: Option<f64>, // axis elevation (A-B . up) the side was chosen at
}

/// One frame's place: (theta, phi) radians and the pose, None when the torus is degenerate
/// (the pose is held; "pose_held").
pub struct Placed {
    pub theta: f64,
    pub phi: f64,
    pub pose: Option<Pose>,
}

impl Motion {
    pub fn new(style: MotionStyle, lens: Lens, settings: MotionSettings) -> Motion {
        Motion {
            settings,
            lens,
            style,
            theta: None,
            phi: 0.0,
            rate: [0.0, 0.0],
            position_world: None,
            side: 0.0,
            side_key: None,
        }
    }

    pub fn set_style(&mut self, style: MotionStyle) {
        self.style = style;
        self.side_key = None;
    }

    /// +1 or -1: the side (sign of phi) where the composed camera's up is nearest world up,
    /// re-chosen when the A-B axis's elevation moves, with hysteresis (ToricMotion._upright_side).
    fn upright_side(&mut self, torus: &Torus, theta: f64) -> Result<f64, NoRotation> {
        let key = torus.basis[0][1]; // axis . (0, 1, 0)
        if let Some(old) = self.side_key {
            if (key - old).abs() < self.settings.side_recheck_axis_dot {
                return Ok(self.side);
            }
        }
        self.side_key = Some(key);
        let phi = radians(self.style.preferred_phi_deg);
        let mut ups = [0.0; 2];
        for (up, sign) in ups.iter_mut().zip([1.0, -1.0]) {
            let (_, rotation) = toric::compose_pose(
                torus,
                theta,
                sign * phi,
                &self.style.screen_a,
                &self.style.screen_b,
                &self.lens,
            )?;
            *up = quat_to_matrix(&rotation)[1][1]; // quat_rotate(rotation, UP_WORLD) @ UP_WORLD
        }
        // a tie within side_tie goes to +1: rounding (the last bit of sin and cos) never chooses
        let best = if ups[0] >= ups[1] - self.settings.side_tie {
            1.0
        } else {
            -1.0
        };
        let index = |side: f64| if side > 0.0 { 0 } else { 1 };
        if self.side == 0.0
            || ups[index(best)] > ups[index(self.side)] + self.settings.side_hysteresis
        {
            self.side = best;
        }
        Ok(self.side)
    }

    /// (theta, phi, theta_lo, theta_hi) radians: the style's preferred place on the upright side.
    pub fn preferred_place(&mut self, torus: &Torus) -> Result<[f64; 4], NoRotation> {
        let lo = self.settings.theta_margin_rad;
        let hi = toric::theta_max(torus.alpha) - self.settings.theta_margin_rad;
        let goal_theta = lo + self.style.preferred_theta_ratio * (hi - lo);
        let side = self.upright_side(torus, goal_theta)?;
        Ok([
            goal_theta,
            side * radians(self.style.preferred_phi_deg),
            lo,
            hi,
        ])
    }

    /// The camera's place on the frame's torus (None: degenerate) and its pose; `level`: B is
    /// only the gaze-room point (pose_on_torus).
    pub fn run(
        &mut self,
        torus: Option<&Torus>,
        level: bool,
        dt_s: f64,
    ) -> Result<Placed, NoRotation> {
        let Some(torus) = torus else {
            return Ok(Placed {
                theta: self.theta.unwrap_or(0.0),
                phi: self.phi,
                pose: None,
            });
        };
        let place = self.preferred_place(torus)?;
        let theta = match (self.theta, self.position_world) {
            (Some(_), Some(position)) => {
                let (theta, phi) = toric::torus_angles(torus, &position);
                self.phi = phi;
                self.integrate(torus, theta, &place, dt_s)
            }
            _ => {
                self.phi = place[1];
                place[0]
            }
        };
        self.theta = Some(theta);
        let pose = pose_on_torus(
            torus,
            theta,
            self.phi,
            &self.style.screen_a,
            &self.style.screen_b,
            &self.lens,
            level,
        )?;
        self.position_world = Some(pose.0);
        Ok(Placed {
            theta,
            phi: self.phi,
            pose: Some(pose),
        })
    }

    /// The spring from (theta, self.phi) toward the preferred place (preferred_place's goal
    /// theta, phi and theta range) over dt_s, in substeps; answers theta and leaves phi and the
    /// rates in self (ToricMotion._integrate).
    fn integrate(&mut self, torus: &Torus, mut theta: f64, place: &[f64; 4], dt_s: f64) -> f64 {
        let [goal_theta, goal_phi, lo, hi] = *place;
        if dt_s <= 0.0 {
            return theta;
        }
        let steps = (self.settings.max_substeps as f64)
            .min(1.0f64.max((dt_s / self.settings.max_substep_s).ceil()));
        let h = (dt_s / steps).min(self.settings.max_substep_s);
        let omega = 1.0 / self.style.response_time_s;
        // J v: world metres per second of the (theta, phi) rates v through the tangent frame
        let speed =
            |t: &[Vec3; 3], v: &[f64; 2]| norm(&[0, 1, 2].map(|i| t[0][i] * v[0] + t[1][i] * v[1]));
        for _ in 0..steps as u32 {
            let tangents = toric::tangent_frame(torus, theta, self.phi);
            let error = [
                goal_theta - theta,
                libm::remainder(goal_phi - self.phi, TAU),
            ];
            let (k, c) = (omega * omega, 2.0 * omega);
            let mut accel = [
                k * error[0] - c * self.rate[0],
                k * error[1] - c * self.rate[1],
            ];
            let scale = limit_scale(speed(&tangents, &accel), self.style.max_accel_m_s2);
            accel = accel.map(|a| a * scale);
            self.rate = [self.rate[0] + h * accel[0], self.rate[1] + h * accel[1]];
            let scale = limit_scale(speed(&tangents, &self.rate), self.style.max_speed_m_s);
            self.rate = self.rate.map(|r| r * scale);
            theta += h * self.rate[0];
            self.phi = libm::remainder(self.phi + h * self.rate[1], TAU);
            if !(lo <= theta && theta <= hi) {
                theta = theta.max(lo).min(hi);
                self.rate[0] = 0.0;
            }
        }
        theta
    }
}

fn limit_scale(norm: f64, limit: f64) -> f64 {
    if norm > limit {
        limit / norm
    } else {
        1.0
    }
}

/// camera.level_look_rotation: the camera-to-world quaternion with no roll showing `point` at
/// the screen point from `camera` (metres).
fn level_look_rotation(camera: &Vec3, point: &Vec3, screen: &[f64; 2], lens: &Lens) -> [f64; 4] {
    let d = [
        screen[0] * lens.tan_half_fov_x,
        screen[1] * lens.tan_half_fov_y,
        -1.0,
    ];
    let a = [
        point[0] - camera[0],
        point[1] - camera[1],
        point[2] - camera[2],
    ];
    let (na, nd) = (norm(&a), norm(&d));
    matrix_to_quat(&level_rotation(&a.map(|c| c / na), &d.map(|c| c / nd)))
}

/// The camera at (theta, phi) radians composing A and B (camera_motion.pose_on_torus). With
/// `level` (B is only a gaze-room point), A is placed exactly and the horizon kept level.
pub fn pose_on_torus(
    torus: &Torus,
    theta: f64,
    phi: f64,
    screen_a: &[f64; 2],
    screen_b: &[f64; 2],
    lens: &Lens,
    level: bool,
) -> Result<Pose, NoRotation> {
    if !level {
        return toric::compose_pose(torus, theta, phi, screen_a, screen_b, lens);
    }
    let position = toric::torus_position(torus, theta, phi);
    let rotation = level_look_rotation(&position, &torus.a_world, screen_a, lens);
    Ok((position, rotation))
}
