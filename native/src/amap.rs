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

impl Window {
    /// The lower edge of row (theta) or column (phi) 0 plus k + 1/2 texels: the centre of texel
    /// k along that axis (MapWindow.theta_centers_rad and phi_centers_rad).
    pub(crate) fn centre(min_rad: f64, step_rad: f64, k: usize) -> f64 {
        min_rad + (k as f64 + 0.5) * step_rad
    }

    /// Whether two windows are the one MapWindow (its dataclass equality).
    fn same(&self, other: &Window) -> bool {
        self.theta_min_rad == other.theta_min_rad
            && self.phi_min_rad == other.phi_min_rad
            && self.theta_step_rad == other.theta_step_rad
            && self.phi_step_rad == other.phi_step_rad
            && self.resolution == other.resolution
    }

    /// Bilinear resampling of one map (res * res float32, rows theta) on this window onto
    /// `destination` (MapWindow.resample): (values (res_d * res_d) float32, covered (res_d *
    /// res_d)); destination texels off this window are 0 times the value there (numpy's product
    /// with the bool, which keeps a NaN) and not covered.
    pub fn resample(&self, values: &[f32], destination: &Window) -> (Vec<f32>, Vec<bool>) {
        let (n, nd) = (self.resolution, destination.resolution);
        let rows: Vec<Tap> = (0..nd)
            .map(|k| {
                let theta =
                    Window::centre(destination.theta_min_rad, destination.theta_step_rad, k);
                Tap::at(self.texel_coords(theta, self.phi_min_rad).0, n)
            })
            .collect();
        let cols: Vec<Tap> = (0..nd)
            .map(|k| {
                let phi = Window::centre(destination.phi_min_rad, destination.phi_step_rad, k);
                Tap::at(self.texel_coords(self.theta_min_rad, phi).1, n)
            })
            .collect();
        let col_weights: Vec<f32> = cols.iter().map(|col| col.weight).collect();
        let col_inside: Vec<f32> = cols
            .iter()
            .map(|col| if col.ok { 1.0 } else { 0.0 })
            .collect();
        let (mut out, mut covered) = (vec![0.0f32; nd * nd], vec![false; nd * nd]);
        let (mut by_row, mut below, mut above) =
            (vec![0.0f32; n], vec![0.0f32; nd], vec![0.0f32; nd]);
        let rows_out = out.chunks_exact_mut(nd).zip(covered.chunks_exact_mut(nd));
        for (row, (out, covered)) in rows.iter().zip(rows_out) {
            let (r0, r1) = (&values[row.lo * n..][..n], &values[row.hi * n..][..n]);
            let w = row.weight;
            for (cell, (&a, &b)) in by_row.iter_mut().zip(r0.iter().zip(r1)) {
                *cell = a + (b - a) * w;
            }
            // the columns' taps gathered first, so that the interpolation runs on whole vectors
            for ((a, b), col) in below.iter_mut().zip(above.iter_mut()).zip(&cols) {
                (*a, *b) = (by_row[col.lo], by_row[col.hi]);
            }
            let row_inside = if row.ok { 1.0 } else { 0.0 };
            for (j, cell) in out.iter_mut().enumerate() {
                let (a, b) = (below[j], above[j]);
                *cell = (a + (b - a) * col_weights[j]) * (col_inside[j] * row_inside);
            }
            covered
                .iter_mut()
                .zip(&cols)
                .for_each(|(c, col)| *c = row.ok && col.ok);
        }
        (out, covered)
    }
}

/// One destination texel's linear interpolation along an axis (base.py's _linear_taps): the
/// source texels below and above, the weight of the one above (float32, as resample casts it),
/// and whether the coordinate lies on the source window (within 1e-6 texel).
struct Tap {
    lo: usize,
    hi: usize,
    weight: f32,
    ok: bool,
}

impl Tap {
    fn at(coord: f64, n: usize) -> Tap {
        let last = n as f64 - 1.0;
        let ok = coord >= -0.5 - 1e-6 && coord <= n as f64 - 0.5 + 1e-6;
        // whole-texel shifts arrive as x.9999999 or x.0000001: snapped so that they copy exactly
        let nearest = coord.round_ties_even();
        let snapped = if (coord - nearest).abs() < 1e-6 {
            nearest
        } else {
            coord
        };
        let c = snapped.clamp(0.0, last);
        let lo = (c.floor() as usize).min(n - 1);
        Tap {
            lo,
            hi: (lo + 1).min(n - 1),
            weight: (c - lo as f64) as f32,
            ok,
        }
    }
}

/// The masked aggregate A and its coverage over `newest`, each (res * res) float32
/// (AnticipationMap.aggregate; the occlusion-anticipation paper's section 4.2, A = 1 / (2r)
/// times the sum of the A_s where every map covers a texel, and 5.2's style mask): `slots` the
/// slots' windows and A_s (res * res float32 each), None for a slot without a map; a map on an
/// older window is resampled onto `newest`. A texel no map covers reads 0 with coverage 0;
/// `mask` (res * res) is applied as 1 - (1 - A) * mask in float64 (apply_style_mask).
pub fn aggregate(
    slots: &[Option<(Window, &[f32])>],
    newest: &Window,
    mask: &[f32],
) -> (Vec<f32>, Vec<f32>) {
    let n = newest.resolution;
    let (mut total, mut count) = (vec![0.0f32; n * n], vec![0.0f32; n * n]);
    for (window, a_s) in slots.iter().flatten() {
        if window.same(newest) {
            total.iter_mut().zip(*a_s).for_each(|(t, &a)| *t += a);
            count.iter_mut().for_each(|c| *c += 1.0);
        } else {
            let (values, covered) = window.resample(a_s, newest);
            total.iter_mut().zip(&values).for_each(|(t, &a)| *t += a);
            let covers = count.iter_mut().zip(&covered);
            covers.for_each(|(c, &k)| *c += if k { 1.0 } else { 0.0 });
        }
    }
    let masked = total
        .iter()
        .zip(&count)
        .zip(mask)
        .map(|((&t, &c), &m)| {
            let a = if c > 0.0 { t / c } else { 0.0 };
            (1.0 - (1.0 - f64::from(a)) * f64::from(m)) as f32
        })
        .collect();
    let slot_count = slots.len() as f32;
    (masked, count.iter().map(|&c| c / slot_count).collect())
}
