//! camdirector._native.KernelBank: the A-map's per-sample prediction (prediction.rs) for Python,
//! standing in for pipeline/toric/occlusion_prediction.py's KernelBank and predict_occlusion.
//! `settings` is an AnticipationSettings (or any object with its fields and `length_bins`); the
//! maps are numpy float32 arrays, S (k, res, res) and V (k, res, res, 2) rad/s; the window a
//! MapWindow (its texel size). The prediction runs with the GIL released.

use numpy::{
    PyArray1, PyArray3, PyArrayMethods, PyReadonlyArray3, PyReadonlyArray4, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::prediction::{KernelBank, PredictionSettings};
use crate::stages_py::attr;

fn prediction_settings(s: &Bound<'_, PyAny>) -> PyResult<PredictionSettings> {
    let count = |name: &str| -> PyResult<usize> { s.getattr(name)?.extract() };
    Ok(PredictionSettings {
        horizon_s: attr(s, "horizon_s")?,
        length_cutoff: attr(s, "length_cutoff")?,
        angle_cutoff_rad: attr(s, "angle_cutoff_rad")?,
        anticipate: s.getattr("anticipate")?.extract()?,
        max_travel_texels: attr(s, "max_travel_texels")?,
        min_travel_texels: attr(s, "min_travel_texels")?,
        direction_bins: count("direction_bins")?,
        length_bin_ratio: attr(s, "length_bin_ratio")?,
        length_bins: count("length_bins")?,
    })
}

/// KernelBank(settings): every travel bin's normalised kernel, built at once (KernelBank.warm's
/// work), for the A_s of `predict`.
#[pyclass(name = "KernelBank", frozen, module = "camdirector._native")]
pub struct PyKernelBank {
    bank: KernelBank,
}

#[pymethods]
impl PyKernelBank {
    #[new]
    fn new(py: Python<'_>, settings: &Bound<'_, PyAny>) -> PyResult<Self> {
        let settings = prediction_settings(settings)?;
        if settings.length_bins == 0 || settings.direction_bins == 0 {
            return Err(PyValueError::new_err("KernelBank: no travel bins"));
        }
        Ok(PyKernelBank {
            bank: py.detach(|| KernelBank::new(settings)),
        })
    }

    /// The largest kernel's half-side, texels.
    #[getter]
    fn max_radius(&self) -> usize {
        self.bank.max_radius
    }

    /// predict(shadow, velocity_rad_s, window) -> A_s (k, res, res) float32 (predict_occlusion):
    /// shadow (k, res, res) float32, velocity_rad_s (k, res, res, 2) float32, on `window`.
    fn predict<'py>(
        &self,
        py: Python<'py>,
        shadow: PyReadonlyArray3<'py, f32>,
        velocity_rad_s: PyReadonlyArray4<'py, f32>,
        window: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let [k, rows, res] = [0, 1, 2].map(|a| shadow.shape()[a]);
        if rows != res || velocity_rad_s.shape() != [k, res, res, 2] {
            return Err(PyValueError::new_err(format!(
                "shadow must be (k, res, res) and velocity_rad_s (k, res, res, 2), got {:?} and {:?}",
                shadow.shape(),
                velocity_rad_s.shape()
            )));
        }
        let resolution: usize = window.getattr("resolution")?.extract()?;
        if resolution != res {
            return Err(PyValueError::new_err(format!(
                "maps of {res} texels on a window of {resolution}"
            )));
        }
        let steps = [
            attr(window, "theta_step_rad")?,
            attr(window, "phi_step_rad")?,
        ];
        let s = shadow.as_array().iter().copied().collect::<Vec<f32>>();
        let v = velocity_rad_s
            .as_array()
            .iter()
            .copied()
            .collect::<Vec<f32>>();
        let predicted = py.detach(|| self.bank.predict(&s, &v, res, steps));
        PyArray1::from_vec(py, predicted).reshape([k, res, res])
    }
}

/// Adds KernelBank.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyKernelBank>()
}
