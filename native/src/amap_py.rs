//! camdirector._native.aggregate_amap: the A-map's aggregate and style mask (amap.rs,
//! style_mask.rs) for Python, the twin of pipeline/toric/anticipation_map.py's
//! `AnticipationMap.aggregate` that pipeline/toric/compiled_maps.py's CompiledAnticipationMap
//! uses. Windows are MapWindows, the mask a StyleMaskSettings; the aggregate is formed with the
//! GIL released.

use std::borrow::Cow;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::amap::{aggregate, Window};
use crate::search_py::{contiguous, window_of};
use crate::stages_py::attr;
use crate::style_mask::{style_mask, MaskKind, MaskSettings};

/// A StyleMaskSettings' fields.
fn mask_of(mask: &Bound<'_, PyAny>) -> PyResult<MaskSettings> {
    let kind: String = mask.getattr("kind")?.getattr("value")?.extract()?;
    Ok(MaskSettings {
        kind: match kind.as_str() {
            "empty" => MaskKind::Empty,
            "soft_behind" => MaskKind::SoftBehind,
            "hard_behind" => MaskKind::HardBehind,
            "avoid_behind_top_bottom" => MaskKind::AvoidBehindTopBottom,
            other => {
                return Err(PyValueError::new_err(format!(
                    "unknown mask kind {other:?}"
                )))
            }
        },
        soft_width_rad: attr(mask, "soft_width_rad")?,
        top_view_phi_deg: attr(mask, "top_view_phi_deg")?,
        bottom_view_phi_deg: attr(mask, "bottom_view_phi_deg")?,
        view_ramp_deg: attr(mask, "view_ramp_deg")?,
    })
}

/// aggregate_amap(a_s, windows, newest, mask, alpha_rad) -> (a_map, coverage)
///
/// AnticipationMap.aggregate: the slots' A_s, each a (res, res) float32 array on its window of
/// `windows` (a MapWindow, or None for a slot without a map, whose array is not read), aggregated
/// on `newest` and masked by `mask` for a torus of `alpha_rad`; a_map and coverage (res_newest,
/// res_newest) float32, the same bits as the numpy code's.
#[pyfunction]
fn aggregate_amap<'py>(
    py: Python<'py>,
    a_s: Vec<Bound<'py, PyAny>>,
    windows: Vec<Option<Bound<'py, PyAny>>>,
    newest: &Bound<'py, PyAny>,
    mask: &Bound<'py, PyAny>,
    alpha_rad: f64,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    if a_s.len() != windows.len() {
        return Err(PyValueError::new_err(format!(
            "one A_s per window: {} and {}",
            a_s.len(),
            windows.len()
        )));
    }
    let newest = window_of(newest)?;
    let mask = mask_of(mask)?;
    let mut held: Vec<Option<(Window, PyReadonlyArray2<'py, f32>)>> = Vec::with_capacity(a_s.len());
    let mut read: Vec<(&Bound<'py, PyAny>, Window)> = Vec::new();
    for (values, window) in a_s.iter().zip(&windows) {
        let Some(window) = window else {
            held.push(None);
            continue;
        };
        // a window object is usually shared by the slots of one update: read once
        let window = match read.iter().find(|(object, _)| object.is(window)) {
            Some((_, known)) => *known,
            None => {
                let known = window_of(window)?;
                read.push((window, known));
                known
            }
        };
        let values: PyReadonlyArray2<'py, f32> = values.extract()?;
        let n = window.resolution;
        if values.shape() != [n, n] {
            return Err(PyValueError::new_err(format!(
                "an A_s on a window of {n} texels must be ({n}, {n}), got {:?}",
                values.shape()
            )));
        }
        held.push(Some((window, values)));
    }
    // borrowed where C-contiguous (a row of the A-map's store, or of a prediction), else copied
    let values: Vec<Option<(Window, Cow<'_, [f32]>)>> = held
        .iter()
        .map(|slot| slot.as_ref().map(|(w, v)| (*w, contiguous(v))))
        .collect();
    let (a_map, coverage) = py.detach(|| {
        let slots: Vec<Option<(Window, &[f32])>> = values
            .iter()
            .map(|slot| slot.as_ref().map(|(w, v)| (*w, v.as_ref())))
            .collect();
        aggregate(&slots, &newest, &style_mask(&mask, &newest, alpha_rad))
    });
    let n = newest.resolution;
    Ok((
        PyArray1::from_vec(py, a_map).reshape([n, n])?.into_any(),
        PyArray1::from_vec(py, coverage).reshape([n, n])?.into_any(),
    ))
}

/// Adds aggregate_amap.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(aggregate_amap, m)?)
}
