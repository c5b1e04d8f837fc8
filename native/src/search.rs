//! The camera particle's search of the occlusion-anticipation paper (section 5, "Camera motion",
//! and 5.1, "Physically-plausible search areas"): the twin of
//! src/camdirector/pipeline/toric/occlusion_search.py's `OcclusionSearch.step`, whose module
//! docstring states the method and what we added to the paper (speed and acceleration limits,
//! the upright side for cuts, the phi margin, the shortest shot, the stuck rule).
//!
//! Each step keeps the Python's operation order and draws the same random numbers in the same
//! order from the same stream (`Uniform`: the session's numpy generator, search_py.rs), so one
//! frame's candidates are the Python's to rounding. Transcendentals are libm's. The risk a
//! local search reads is a `Risk` (the A-map, amap.rs, or ray casts, `RaycastRisk`) and the cut
//! search's ray casts an `Occlusion` (scene.rs's Scene to the target sample points).

use std::f64::consts::{PI, TAU};

use crate::rotation::Vec3;
use crate::toric::{tangent_frame, theta_max, torus_angles, torus_position, Torus};

/// occlusion_search.SearchSettings's fields (their units and limits are there).
pub struct SearchSettings {
    pub samples: usize,
    pub chi_deg: f64,
    pub g_per_m: f64,
    pub h: f64,
    pub rho_m: f64,
    pub look_ahead_frames: usize,
    pub damping_per_s: f64,
    pub cut_samples: usize,
    pub min_cut_angle_deg: f64,
    pub min_shot_s: f64,
    pub improvement: f64,
    pub stuck_occluded: f64,
    pub stuck_s: f64,
    pub theta_margin_ratio: f64,
    pub view_phi_margin_deg: f64,
}

/// The camera particle between frames (OcclusionSearch's theta, phi, velocity_world,
/// shot_start_s and _occluded_since_s): its place on the torus, radians, its tangent velocity,
/// world m/s (undamped, as realised), when its shot began and since when it is stuck, s.
pub struct Particle {
    pub theta: f64,
    pub phi: f64,
    pub velocity_world: Vec3,
    pub shot_start_s: f64,
    pub occluded_since_s: Option<f64>,
}

/// Which move a step made (SearchResult.strategy; "start" is the Python's alone).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Strategy {
    SingleFrame,
    LookAhead,
    Cut,
    Coast,
}

impl Strategy {
    pub fn name(self) -> &'static str {
        match self {
            Strategy::SingleFrame => "single_frame",
            Strategy::LookAhead => "look_ahead",
            Strategy::Cut => "cut",
            Strategy::Coast => "coast",
        }
    }
}

/// SearchResult: the place chosen, radians, whether it is a cut, the move, and the chosen
/// place's risk (local searches) or occluded share (cut).
pub struct Step {
    pub theta: f64,
    pub phi: f64,
    pub cut: bool,
    pub strategy: Strategy,
    pub risk: f64,
}

/// The frame's inputs a step reads beyond the torus: s, and the style's limits.
pub struct Frame {
    pub dt_s: f64,
    pub time_s: f64,
    /// +1 or -1: the upright half of the torus, where cut candidates are drawn
    pub side: f64,
    pub max_speed_m_s: f64,
    pub max_accel_m_s2: f64,
}

/// Uniform doubles in [0, 1), numpy's `next_double`: Generator.uniform(low, high) is
/// low + (high - low) * next_double.
pub trait Uniform {
    fn next_double(&mut self) -> f64;
}

/// The risk field the local searches read (occlusion_search.RiskField): risk in [0, 1] at a
/// torus place (theta, phi) radians.
pub trait Risk {
    fn risk(&mut self, torus: &Torus, theta: f64, phi: f64) -> f64;
}

/// The cut search's ray casts (occlusion_search.Occlusion): the share of the target sample
/// points hidden from a camera place, world metres.
pub trait Occlusion {
    fn occluded(&mut self, camera_world: &Vec3) -> f64;
}

/// The paper's R baseline as a Risk (occlusion_search.RaycastRisk): ray casts from the torus
/// point of each place.
pub struct RaycastRisk<'a, O: Occlusion>(pub &'a mut O);

impl<O: Occlusion> Risk for RaycastRisk<'_, O> {
    fn risk(&mut self, torus: &Torus, theta: f64, phi: f64) -> f64 {
        self.0.occluded(&torus_position(torus, theta, phi))
    }
}

/// One query a step made, as the Python makes it in one call: the places asked and the answers
/// (a test compares them with the Python's). A local search's places off the allowed range are
/// not asked (the Python asks, then reads them as infinitely risky): their answer is inf.
pub enum Scored {
    Risk {
        theta: Vec<f64>,
        phi: Vec<f64>,
        value: Vec<f64>,
    },
    Occluded {
        cameras_world: Vec<Vec3>,
        value: Vec<f64>,
    },
}

pub(crate) fn add(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn sub(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn scale(a: &Vec3, k: f64) -> Vec3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

pub(crate) fn div(a: &Vec3, k: f64) -> Vec3 {
    [a[0] / k, a[1] / k, a[2] / k]
}

pub(crate) fn dot(a: &Vec3, b: &Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn norm(a: &Vec3) -> f64 {
    dot(a, a).sqrt()
}

pub(crate) fn cross(u: &Vec3, v: &Vec3) -> Vec3 {
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

/// math.radians: x * (pi / 180).
fn radians(deg: f64) -> f64 {
    deg * (PI / 180.0)
}

/// n draws of Generator.uniform(low, high, n).
fn uniforms(rng: &mut dyn Uniform, low: f64, high: f64, n: usize) -> Vec<f64> {
    let range = high - low;
    (0..n).map(|_| low + range * rng.next_double()).collect()
}

/// np.argmin: the first least value, or the first NaN when there is one.
fn argmin(values: &[f64]) -> usize {
    let mut best = 0;
    for (k, &v) in values.iter().enumerate() {
        if v.is_nan() {
            return k;
        }
        if v < values[best] {
            best = k;
        }
    }
    best
}

/// The local frame of a step: the camera p on the torus, the tangent plane's unit axes e1, e2
/// and the damped velocity v_t, as OcclusionSearch.step computes them.
struct Local {
    p: Vec3,
    e1: Vec3,
    e2: Vec3,
    v_t: Vec3,
}

pub struct Search {
    pub settings: SearchSettings,
}

impl Search {
    /// (f_r radians, f_l metres) of equation 3 (section 5.1), with f_l >= rho (_spans).
    fn spans(&self, speed_m_s: f64, dt_s: f64) -> (f64, f64) {
        let s = &self.settings;
        let step = speed_m_s * dt_s;
        let chi = radians(s.chi_deg);
        let f_r = (TAU - chi) / libm::exp(s.g_per_m * step) + chi;
        (f_r, (2.0 * s.h * step).max(s.rho_m))
    }

    /// (samples on the tangent plane, world metres, f_l) of the area reachable in dt_s, an
    /// annular sector around the velocity (OcclusionSearch._sector): n angles drawn, then n
    /// squared distances (uniform over the sector's area).
    fn sector(&self, local: &Local, dt_s: f64, rng: &mut dyn Uniform) -> (Vec<Vec3>, f64) {
        let Local { p, e1, e2, v_t } = local;
        let speed = norm(v_t);
        let (f_r, f_l) = self.spans(speed, dt_s);
        let heading = if speed > 0.0 {
            libm::atan2(dot(v_t, e2), dot(v_t, e1))
        } else {
            0.0
        };
        let n = self.settings.samples;
        let angles = uniforms(rng, -0.5 * f_r, 0.5 * f_r, n);
        let (d0, d1) = (
            (speed * dt_s - 0.5 * f_l).max(0.0),
            speed * dt_s + 0.5 * f_l,
        );
        let squared = uniforms(rng, d0 * d0, d1 * d1, n);
        let places = angles
            .iter()
            .zip(&squared)
            .map(|(&offset, &d2)| {
                let (sin, cos) = libm::sincos(heading + offset);
                let dist = d2.sqrt();
                [0, 1, 2].map(|c| p[c] + dist * (cos * e1[c] + sin * e2[c]))
            })
            .collect();
        (places, f_l)
    }

    /// Allowed theta, radians (_theta_range): the arc's ends put the camera on top of A or B.
    fn theta_range(&self, torus: &Torus) -> (f64, f64) {
        let top = theta_max(torus.alpha);
        let ratio = self.settings.theta_margin_ratio;
        (ratio * top, (1.0 - ratio) * top)
    }

    /// Whether the camera may not go to (theta, phi) (_outside): the arc's ends, top and bottom views.
    fn outside(&self, theta: f64, phi: f64, lo: f64, hi: f64) -> bool {
        let margin = radians(self.settings.view_phi_margin_deg);
        theta < lo || theta > hi || phi.abs() < margin || phi.abs() > PI - margin
    }

    /// Each place's risk, inf off the allowed range (not asked there), and the least one's index.
    fn scored(
        &self,
        torus: &Torus,
        places: &[Vec3],
        range: (f64, f64),
        risk: &mut dyn Risk,
        trace: &mut Option<&mut Vec<Scored>>,
    ) -> (Vec<f64>, usize) {
        let (theta, phi): (Vec<f64>, Vec<f64>) =
            places.iter().map(|p| torus_angles(torus, p)).unzip();
        let risks: Vec<f64> = theta
            .iter()
            .zip(&phi)
            .map(|(&t, &f)| {
                if self.outside(t, f, range.0, range.1) {
                    f64::INFINITY
                } else {
                    risk.risk(torus, t, f)
                }
            })
            .collect();
        let best = argmin(&risks);
        if let Some(trace) = trace {
            trace.push(Scored::Risk {
                theta,
                phi,
                value: risks.clone(),
            });
        }
        (risks, best)
    }

    /// One frame of section 5 (OcclusionSearch.step): moves `particle` and answers its new place.
    /// dt_s <= 0: it stays, a coast of NaN risk. `trace`: each query made, in order.
    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &self,
        particle: &mut Particle,
        torus: &Torus,
        frame: &Frame,
        risk: &mut dyn Risk,
        occlusion: &mut dyn Occlusion,
        rng: &mut dyn Uniform,
        mut trace: Option<&mut Vec<Scored>>,
    ) -> Step {
        let s = &self.settings;
        let p = torus_position(torus, particle.theta, particle.phi);
        let dt_s = frame.dt_s;
        if dt_s <= 0.0 {
            return Step {
                theta: particle.theta,
                phi: particle.phi,
                cut: false,
                strategy: Strategy::Coast,
                risk: f64::NAN,
            };
        }
        let [t_theta, _, normal] = tangent_frame(torus, particle.theta, particle.phi);
        let e1 = div(&t_theta, norm(&t_theta));
        let e2 = cross(&normal, &e1);
        let velocity = particle.velocity_world;
        let v_real = sub(&velocity, &scale(&normal, dot(&velocity, &normal))); // last frame's motion
        let decay = (1.0 - s.damping_per_s * dt_s).max(0.0);
        let v_t = scale(&v_real, decay); // the paper's damped velocity v_i
        let coast = add(&p, &scale(&v_t, dt_s));
        let (theta_c, phi_c) = torus_angles(torus, &coast);
        let risk_coast = risk.risk(torus, theta_c, phi_c);
        if let Some(trace) = trace.as_deref_mut() {
            trace.push(Scored::Risk {
                theta: vec![theta_c],
                phi: vec![phi_c],
                value: vec![risk_coast],
            });
        }

        let occluded_now = occluded(occlusion, &[p], &mut trace)[0];
        if occluded_now < s.stuck_occluded {
            particle.occluded_since_s = None;
        } else if particle.occluded_since_s.is_none() {
            particle.occluded_since_s = Some(frame.time_s);
        }
        let can_cut = frame.time_s - particle.shot_start_s >= s.min_shot_s;
        if let (true, Some(since)) = (can_cut, particle.occluded_since_s) {
            if frame.time_s - since >= s.stuck_s {
                if let Some(step) =
                    self.cut_to(particle, torus, &coast, frame, occlusion, rng, &mut trace)
                {
                    return step;
                }
            }
        }

        let local = Local { p, e1, e2, v_t };
        let (mut target, mut strategy, mut chosen_risk) = (coast, Strategy::Coast, risk_coast);
        let (single, f_l) = self.sector(&local, dt_s, rng);
        let range = self.theta_range(torus);
        let (risks, best) = self.scored(torus, &single, range, risk, &mut trace);
        if risks[best] < risk_coast - s.improvement {
            (target, strategy, chosen_risk) = (single[best], Strategy::SingleFrame, risks[best]);
        } else {
            let ahead_dt_s = s.look_ahead_frames as f64 * dt_s;
            let (ahead, _) = self.sector(&local, ahead_dt_s, rng);
            let (risks, best) = self.scored(torus, &ahead, range, risk, &mut trace);
            if risks[best] < risk_coast - s.improvement {
                let toward = sub(&ahead[best], &coast);
                let reach = norm(&toward);
                if reach > 0.0 {
                    target = add(&coast, &scale(&toward, (0.5 * f_l / reach).min(1.0)));
                }
                (strategy, chosen_risk) = (Strategy::LookAhead, risks[best]);
            } else if can_cut {
                if let Some(step) =
                    self.cut_to(particle, torus, &coast, frame, occlusion, rng, &mut trace)
                {
                    return step;
                }
            }
        }

        // physical limits of the style on the camera's own motion, braking by damping included
        let mut velocity = div(&sub(&target, &p), dt_s);
        let accel = div(&sub(&velocity, &v_real), dt_s);
        let a = norm(&accel);
        if a > frame.max_accel_m_s2 {
            velocity = add(&v_real, &scale(&accel, frame.max_accel_m_s2 / a * dt_s));
        }
        let speed = norm(&velocity);
        if speed > frame.max_speed_m_s {
            velocity = scale(&velocity, frame.max_speed_m_s / speed);
        }
        let (theta_n, phi_n) = torus_angles(torus, &add(&p, &scale(&velocity, dt_s)));
        let margin = radians(s.view_phi_margin_deg);
        let phi_next = phi_n.abs().max(margin).min(PI - margin).copysign(phi_n);
        particle.theta = theta_n.max(range.0).min(range.1);
        particle.phi = phi_next;
        let p_next = torus_position(torus, particle.theta, particle.phi);
        particle.velocity_world = div(&sub(&p_next, &p), dt_s);
        Step {
            theta: particle.theta,
            phi: particle.phi,
            cut: false,
            strategy,
            risk: chosen_risk,
        }
    }

    /// Teleports to a cut place when there is one (_cut_to): velocity reset, a new shot.
    #[allow(clippy::too_many_arguments)]
    fn cut_to(
        &self,
        particle: &mut Particle,
        torus: &Torus,
        coast: &Vec3,
        frame: &Frame,
        occlusion: &mut dyn Occlusion,
        rng: &mut dyn Uniform,
        trace: &mut Option<&mut Vec<Scored>>,
    ) -> Option<Step> {
        let (theta, phi, occluded) = self.cut(torus, coast, frame.side, occlusion, rng, trace)?;
        particle.theta = theta;
        particle.phi = phi;
        particle.velocity_world = [0.0; 3];
        particle.shot_start_s = frame.time_s;
        particle.occluded_since_s = None;
        Some(Step {
            theta,
            phi,
            cut: true,
            strategy: Strategy::Cut,
            risk: occluded,
        })
    }

    /// (theta, phi, occluded share) of a less occluded place obeying the 30-degree rule (_cut):
    /// cut_samples thetas drawn, then as many phis on the upright side; None when there is none.
    fn cut(
        &self,
        torus: &Torus,
        coast: &Vec3,
        side: f64,
        occlusion: &mut dyn Occlusion,
        rng: &mut dyn Uniform,
        trace: &mut Option<&mut Vec<Scored>>,
    ) -> Option<(f64, f64, f64)> {
        let s = &self.settings;
        let current = occluded(occlusion, std::slice::from_ref(coast), trace)[0];
        if current <= s.improvement {
            return None;
        }
        let margin = radians(s.view_phi_margin_deg);
        let (lo, hi) = self.theta_range(torus);
        let thetas = uniforms(rng, lo, hi, s.cut_samples);
        let phis = uniforms(rng, margin, PI - margin, s.cut_samples);
        let focus = scale(&add(&torus.a_world, &torus.b_world), 0.5);
        let to_focus = sub(&focus, coast);
        let now = div(&to_focus, norm(&to_focus));
        let widest = libm::cos(radians(s.min_cut_angle_deg));
        let mut kept = Vec::new(); // (theta, phi, place)
        for (&theta, &phi) in thetas.iter().zip(&phis) {
            let phi = side * phi;
            let place = torus_position(torus, theta, phi);
            let view = sub(&focus, &place);
            if dot(&div(&view, norm(&view)), &now) <= widest {
                kept.push((theta, phi, place));
            }
        }
        if kept.is_empty() {
            return None;
        }
        let places: Vec<Vec3> = kept.iter().map(|k| k.2).collect();
        let shares = occluded(occlusion, &places, trace);
        let best = argmin(&shares);
        (shares[best] < current - s.improvement).then(|| (kept[best].0, kept[best].1, shares[best]))
    }
}

/// The occluded share from each camera place, as one query of the trace.
fn occluded(
    occlusion: &mut dyn Occlusion,
    cameras_world: &[Vec3],
    trace: &mut Option<&mut Vec<Scored>>,
) -> Vec<f64> {
    let value: Vec<f64> = cameras_world
        .iter()
        .map(|c| occlusion.occluded(c))
        .collect();
    if let Some(trace) = trace {
        trace.push(Scored::Occluded {
            cameras_world: cameras_world.to_vec(),
            value: value.clone(),
        });
    }
    value
}
