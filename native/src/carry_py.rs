//! camdirector._native.carry: carry.rs for Python, RigidTransform.apply's machine-independent twin.

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;

use crate::carry::carry as carried;
use crate::scene_py::{points_of, pose_of};

/// carry(points_local, transform): points_local (n, 3) float64 (or one point (3,)) carried by a
/// RigidTransform (position_world, rotation_xyzw, scale): (n, 3) (or (3,)) float64 world points,
/// RigidTransform.apply's within rounding and the same bits on every x86-64 machine.
#[pyfunction]
fn carry<'py>(
    py: Python<'py>,
    points_local: &Bound<'py, PyAny>,
    transform: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let (points, one) = points_of("points_local", points_local)?;
    let out = carried(&pose_of(transform)?, &points);
    if one {
        return Ok(PyArray1::from_slice(py, &out[0]).into_any());
    }
    let flat: Vec<f64> = out.iter().flatten().copied().collect();
    let array: Bound<'py, PyArray2<f64>> = Array2::from_shape_vec((out.len(), 3), flat)
        .expect("n rows of 3")
        .into_pyarray(py);
    Ok(array.into_any())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(carry, m)?)
}
