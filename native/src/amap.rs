//! The occlusion anticipation map as the search reads it (the occlusion-anticipation paper,
//! section 4.2 and 5: the local searches pick the least risky place on A): the twin of
//! pipeline/toric/anticipation_map.py's `AnticipationMap.lookup` over a window of Toric texture
//! space (geometry/toric_maps/base.py's MapWindow, whose docstring fixes the texel layout).

use std::f64::consts::{PI, TAU};

use crate::rotation::floor_mod;
use crate::search::Risk;
use crate::toric::Torus;

/// MapWindow's fields: lower edges of texel row and column 0 and the texel size, radians, and
/// the texels per side.
#[derive(Clone, Copy, Debug)]
pub struct Window {
    pub theta_min_rad: f64,
    pub phi_min_rad: f64,
    pub theta_step_rad: f64,
    pub phi_step_rad: f64,
    pub resolution: usize,
}

impl Window {
    /// Float texel coordinates (i, j) of (theta, phi) radians, phi wrapped into the turn centred
    /// on the window (MapWindow.texel_coords).
    pub fn texel_coords(&self, theta: f64, phi: f64) -> (f64, f64) {
        let i = (theta - self.theta_min_rad) / self.theta_step_rad - 0.5;
        let phi_span = self.phi_step_rad * self.resolution as f64;
        let phi_center = self.phi_min_rad + 0.5 * phi_span;
        let d_phi = floor_mod(phi - phi_center + PI, TAU) - PI;
        let j = (d_phi + 0.5 * phi_span) / self.phi_step_rad - 0.5;
        (i, j)
    }
}

/// The masked A-map, values (res * res) float32 rows theta and columns phi, on its window, read
/// bilinearly; `outside` off the window (AnticipationMap.lookup). `None`: no map yet, every
/// place reads `outside`.
pub struct AMap<'a> {
    pub map: Option<(&'a [f32], Window)>,
    pub outside: f64,
}

impl AMap<'_> {
    pub fn lookup(&self, theta: f64, phi: f64) -> f64 {
        let Some((a, window)) = self.map else {
            return self.outside;
        };
        let (i, j) = window.texel_coords(theta, phi);
        let n = window.resolution;
        let top = n as f64 - 0.5;
        // written so that NaN coordinates read `outside`, as numpy's comparisons make them
        if !(i >= -0.5 && i <= top && j >= -0.5 && j <= top) {
            return self.outside;
        }
        let last = n as f64 - 1.0;
        let (ic, jc) = (i.max(0.0).min(last), j.max(0.0).min(last));
        let (i0, j0) = (
            (ic.floor() as usize).min(n - 1),
            (jc.floor() as usize).min(n - 1),
        );
        let (i1, j1) = ((i0 + 1).min(n - 1), (j0 + 1).min(n - 1));
        let (wi, wj) = (ic - i0 as f64, jc - j0 as f64);
        let at = |r: usize, c: usize| f64::from(a[r * n + c]);
        (1.0 - wi) * ((1.0 - wj) * at(i0, j0) + wj * at(i0, j1))
            + wi * ((1.0 - wj) * at(i1, j0) + wj * at(i1, j1))
    }
}

/// The A-map as the search's risk field (OcclusionMaps.risk).
impl Risk for AMap<'_> {
    fn risk(&mut self, _torus: &Torus, theta: f64, phi: f64) -> f64 {
        self.lookup(theta, phi)
    }
}
