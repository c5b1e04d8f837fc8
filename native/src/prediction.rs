//! The per-sample occlusion prediction A_s (the occlusion-anticipation paper, section 4.2: the
//! uncertainty function U = U_l U_a of equation 1, and A_s as a double sum over S_s and V_s):
//! the twin of pipeline/toric/occlusion_prediction.py's `KernelBank` and `predict_occlusion`,
//! whose module docstring says how we read the paper's open parts (travel over the horizon in
//! texels, the relative length falloff, each kernel normalised to unit sum, A_s clipped at 1,
//! travel snapped to bins).
//!
//! The same model: the same bins (snap_travel), kernels (KernelBank.table) and sums. The sums'
//! order differs from numpy's bincounts (one texel after another here, one travel length after
//! another there), and libm's log, atan2, hypot, pow may differ from numpy's in the last bit, so
//! a texel agrees with the Python to float rounding (the float32 output to an ulp or so), and a
//! travel within rounding of a bin's edge could take the neighbouring bin. Always the same bits
//! on every machine.

use std::f64::consts::TAU;

/// AnticipationSettings's fields the prediction reads (their units and limits are there), and
/// its `length_bins`.
pub struct PredictionSettings {
    pub horizon_s: f64,
    pub length_cutoff: f64,
    pub angle_cutoff_rad: f64,
    pub anticipate: bool,
    pub max_travel_texels: f64,
    pub min_travel_texels: f64,
    pub direction_bins: usize,
    pub length_bin_ratio: f64,
    pub length_bins: usize,
}

/// A kernel's entries on one row, at consecutive columns: texel offset (di, dj) of the first,
/// and the weights from there on.
struct Run {
    di: i64,
    dj: i64,
    weights: Vec<f64>,
}

/// One travel length's kernels: per direction, its non-zero entries (weights normalised to unit
/// sum) in KernelBank.table's order, as runs along its rows. A texel's kernel adds to each cell
/// once, so the runs change no sum's order: each cell's sum still takes the texels in texel
/// order. They let `predict` clip a row once and add a run as one loop over contiguous cells.
type Table = Vec<Vec<Run>>;

/// A kernel's entries (di, dj, weight), row-major, as runs of consecutive columns.
fn runs(entries: Vec<(i64, i64, f64)>) -> Vec<Run> {
    let mut runs: Vec<Run> = Vec::new();
    for (di, dj, w) in entries {
        match runs.last_mut() {
            Some(run) if run.di == di && run.dj + run.weights.len() as i64 == dj => {
                run.weights.push(w)
            }
            _ => runs.push(Run {
                di,
                dj,
                weights: vec![w],
            }),
        }
    }
    runs
}

/// U(v1, v2) = U_l(delta) U_a(gamma) for travel v1 and offset v2, texels (uncertainty).
fn uncertainty(
    travel: [f64; 2],
    offset: [f64; 2],
    length_cutoff: f64,
    angle_cutoff_rad: f64,
) -> f64 {
    let length = libm::hypot(travel[0], travel[1]);
    let reach = libm::hypot(offset[0], offset[1]);
    if length <= 0.0 {
        return if reach == 0.0 { 1.0 } else { 0.0 };
    }
    let cross = travel[0] * offset[1] - travel[1] * offset[0];
    let dot = travel[0] * offset[0] + travel[1] * offset[1];
    let gamma = if reach > 0.0 {
        libm::atan2(cross.abs(), dot)
    } else {
        0.0
    };
    let delta = (length - reach) / length;
    (1.0 - delta.abs() / length_cutoff).max(0.0) * (1.0 - gamma.abs() / angle_cutoff_rad).max(0.0)
}

/// The kernels of every travel bin (KernelBank, all tables built at once, as `warm` does).
pub struct KernelBank {
    pub settings: PredictionSettings,
    tables: Vec<Table>,
    /// the largest kernel half-side, texels (KernelBank.max_radius)
    pub max_radius: usize,
}

impl KernelBank {
    pub fn new(settings: PredictionSettings) -> KernelBank {
        let radius_of = |length: f64| ((1.0 + settings.length_cutoff) * length).ceil() as usize;
        let length_of = |bin: usize| {
            settings.min_travel_texels * libm::pow(settings.length_bin_ratio, bin as f64)
        };
        let tables = (0..settings.length_bins)
            .map(|bin| Self::table(&settings, length_of(bin), radius_of(length_of(bin))))
            .collect();
        let max_radius = radius_of(length_of(settings.length_bins - 1));
        KernelBank {
            settings,
            tables,
            max_radius,
        }
    }

    /// KernelBank.table: per direction, U over the square of half-side `radius` (rows di, then
    /// columns dj), its positive entries normalised; a direction with none keeps the occluder
    /// where it is.
    fn table(s: &PredictionSettings, length: f64, radius: usize) -> Table {
        let r = radius as i64;
        (0..s.direction_bins)
            .map(|d| {
                let angle = d as f64 * (TAU / s.direction_bins as f64);
                let (sin, cos) = libm::sincos(angle);
                let travel = [length * cos, length * sin];
                let kept: Vec<(i64, i64, f64)> = (-r..=r)
                    .flat_map(|di| (-r..=r).map(move |dj| (di, dj)))
                    .map(|(di, dj)| {
                        let w = uncertainty(
                            travel,
                            [di as f64, dj as f64],
                            s.length_cutoff,
                            s.angle_cutoff_rad,
                        );
                        (di, dj, w)
                    })
                    .filter(|&(_, _, w)| w > 0.0)
                    .collect();
                if kept.is_empty() {
                    return runs(vec![(0, 0, 1.0)]);
                }
                let total: f64 = kept.iter().map(|k| k.2).sum();
                runs(
                    kept.into_iter()
                        .map(|(di, dj, w)| (di, dj, w / total))
                        .collect(),
                )
            })
            .collect()
    }

    /// The bin of a travel (t_theta, t_phi) texels (snap_travel): 0 still, else 1 + length bin *
    /// direction_bins + direction.
    fn bin(&self, travel: [f64; 2]) -> Option<(usize, usize)> {
        let s = &self.settings;
        let length = libm::hypot(travel[0], travel[1]);
        if length < s.min_travel_texels {
            return None;
        }
        let clamped = length.min(s.max_travel_texels);
        let k_len = (libm::log(clamped.max(1e-300) / s.min_travel_texels)
            / libm::log(s.length_bin_ratio))
        .round_ties_even()
        .clamp(0.0, (s.length_bins - 1) as f64) as usize;
        let n_dir = s.direction_bins as f64;
        let turn = (libm::atan2(travel[1], travel[0]) / TAU * n_dir).round_ties_even();
        let k_dir = crate::rotation::floor_mod(turn, n_dir) as usize;
        Some((k_len, k_dir))
    }

    /// A_s (k, res, res) of k S-maps (k, res, res) and V-maps (k, res, res, 2) rad/s on a window
    /// of texel size (theta_step_rad, phi_step_rad) (predict_occlusion): each occluded texel's
    /// kernel, weighted by its S, added where it lands inside the window; clipped at 1.
    pub fn predict(
        &self,
        shadow: &[f32],
        velocity: &[f32],
        res: usize,
        steps_rad: [f64; 2],
    ) -> Vec<f32> {
        let s = &self.settings;
        if !s.anticipate {
            return shadow.iter().map(|&v| v.clamp(0.0, 1.0)).collect();
        }
        let per_map = res * res;
        let mut sum = vec![0.0f64; shadow.len()];
        let scale = [s.horizon_s / steps_rad[0], s.horizon_s / steps_rad[1]];
        for (texel, &value) in shadow.iter().enumerate() {
            if value.is_nan() || value <= 0.0 {
                continue;
            }
            let value = f64::from(value);
            let (map, row, col) = (texel / per_map, (texel % per_map) / res, texel % res);
            let travel = [
                f64::from(velocity[2 * texel]) * scale[0],
                f64::from(velocity[2 * texel + 1]) * scale[1],
            ];
            let Some((k_len, k_dir)) = self.bin(travel) else {
                sum[texel] += value;
                continue;
            };
            let (base, n) = (map * per_map, res as i64);
            for run in &self.tables[k_len][k_dir] {
                let (i, j) = (row as i64 + run.di, col as i64 + run.dj);
                // the run's entries that land inside the window: columns j + lo .. j + hi
                let (lo, hi) = ((-j).max(0), (n - j).min(run.weights.len() as i64));
                if !(0..n).contains(&i) || lo >= hi {
                    continue;
                }
                let start = base + (i * n + j + lo) as usize;
                let cells = &mut sum[start..start + (hi - lo) as usize];
                for (cell, &w) in cells.iter_mut().zip(&run.weights[lo as usize..hi as usize]) {
                    *cell += w * value;
                }
            }
        }
        sum.into_iter().map(|v| v.min(1.0) as f32).collect()
    }
}
