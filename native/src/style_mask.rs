//! Style masks over Toric texture space, the viewpoints a map mode avoids (the
//! occlusion-anticipation paper's section 5.2 and Figure 10): the twin of
//! pipeline/toric/style_masks.py's `style_mask`, whose docstrings say how "behind", top and bottom
//! views are read. 1 = allowed, 0 = excluded.

use std::f64::consts::{PI, TAU};

use crate::amap::Window;
use crate::rotation::floor_mod;

/// Which mask (pipeline.style.MaskKind): (a) none, (b) a gradient behind the targets, (c) a hard
/// exclusion behind them, (d) behind, top and bottom views avoided smoothly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MaskKind {
    Empty,
    SoftBehind,
    HardBehind,
    AvoidBehindTopBottom,
}

/// StyleMaskSettings' fields.
#[derive(Clone, Copy, Debug)]
pub struct MaskSettings {
    pub kind: MaskKind,
    pub soft_width_rad: f64,
    pub top_view_phi_deg: f64,
    pub bottom_view_phi_deg: f64,
    pub view_ramp_deg: f64,
}

/// Hermite smoothstep of x between edge0 and edge1 (style_masks._smoothstep).
fn smoothstep(edge0: f64, edge1: f64, x: f64) -> f64 {
    let t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The mask (res * res) float32 in [0, 1] over `window`, rows theta, for a torus of `alpha_rad`
/// (style_mask).
pub fn style_mask(mask: &MaskSettings, window: &Window, alpha_rad: f64) -> Vec<f32> {
    let n = window.resolution;
    if mask.kind == MaskKind::Empty {
        return vec![1.0; n * n];
    }
    let behind = PI - 2.0 * alpha_rad; // style_masks.behind_theta_rad
    let rows: Vec<f64> = (0..n)
        .map(|i| Window::centre(window.theta_min_rad, window.theta_step_rad, i))
        .collect();
    if mask.kind == MaskKind::HardBehind {
        let allowed = |theta: f64| if theta >= behind { 1.0f32 } else { 0.0 };
        return rows
            .iter()
            .flat_map(|&theta| std::iter::repeat_n(allowed(theta), n))
            .collect();
    }
    let soft: Vec<f64> = rows
        .iter()
        .map(|&theta| smoothstep(behind - mask.soft_width_rad, behind, theta))
        .collect();
    if mask.kind == MaskKind::SoftBehind {
        return soft
            .iter()
            .flat_map(|&s| std::iter::repeat_n(s as f32, n))
            .collect();
    }
    let half = 0.5 * mask.view_ramp_deg;
    let (top_deg, bottom_deg) = (mask.top_view_phi_deg, mask.bottom_view_phi_deg);
    let views: Vec<(f64, f64)> = (0..n)
        .map(|j| {
            let phi = Window::centre(window.phi_min_rad, window.phi_step_rad, j);
            let abs_phi = (floor_mod(phi + PI, TAU) - PI).abs() * (180.0 / PI); // np.degrees
            let top = smoothstep(top_deg - half, top_deg + half, abs_phi);
            let bottom = 1.0 - smoothstep(bottom_deg - half, bottom_deg + half, abs_phi);
            (top, bottom)
        })
        .collect();
    soft.iter()
        .flat_map(|&s| {
            views
                .iter()
                .map(move |&(top, bottom)| (s * top * bottom) as f32)
        })
        .collect()
}
