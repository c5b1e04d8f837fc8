//! camdirector._native.move_scene: a frame's moving objects put where its rows say, in the Scene,
//! in one call: the compiled decoder's rows (codec.frame_from_wire) read as they are, where
//! Scene.set_transform reads one RigidTransform's three arrays a call (about 0.9 us each). And
//! turn_rates: the angular velocities the maps' scene moves its objects with (occlusion_maps.py's
//! `_turn_rates`), compiled.

use numpy::ndarray::{ArrayView1, ArrayView2};
use numpy::{PyArray2, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyList, PyString};

use crate::rotation::turn_rotvec;
use crate::scene::Pose;
use crate::scene_py::PyScene;
use crate::toric_py::c_order_values;

/// Doubles a row: position (3), rotation xyzw (4), scale (3), as codec.PACKED_STRIDE.
const STRIDE: usize = 10;

/// move_scene(scene, ids, rows) -> list[str]: each object of ids (n,) str that the Scene holds as
/// a moving object placed at its row of rows (n, 10) float64 (position, rotation xyzw, scale:
/// the rows RigidTransform(rows[k, 0:3], rows[k, 3:7], rows[k, 7:10]) is made of), in order, as
/// Scene.set_transform(ids[k], that transform) would; ids the Scene does not hold (a frame's
/// targets) are passed over. Returns the ids moved, in order. ValueError, before anything is
/// moved, for rows of another shape or a row set_transform would refuse (not finite, a zero scale).
#[pyfunction]
fn move_scene<'py>(
    mut scene: PyRefMut<'_, PyScene>,
    ids: &Bound<'py, PyList>,
    rows: &Bound<'py, PyAny>,
) -> PyResult<Vec<Bound<'py, PyString>>> {
    // the decoder's own C-order array read without a borrow (toric_py::c_order_values); anything
    // else as before
    let copied = rows
        .cast::<PyArray2<f64>>()
        .ok()
        .and_then(|array| c_order_values(array.to_dyn()).map(|values| (array.dims(), values)));
    let borrowed;
    let rows = match &copied {
        Some((dims, values)) => ArrayView2::from_shape(*dims, values).expect("its own shape"),
        None => {
            borrowed = rows.extract::<PyReadonlyArray2<'_, f64>>()?;
            borrowed.as_array()
        }
    };
    if rows.ncols() != STRIDE || rows.nrows() != ids.len() {
        return Err(PyValueError::new_err(format!(
            "rows must be ({}, {STRIDE}) for {} ids, got {:?}",
            ids.len(),
            ids.len(),
            rows.shape()
        )));
    }
    let mut poses = Vec::with_capacity(rows.nrows());
    for (k, row) in rows.outer_iter().enumerate() {
        let r: Vec<f64> = row.iter().copied().collect();
        if r.iter().any(|x| !x.is_finite()) || r[7..].contains(&0.0) {
            return Err(PyValueError::new_err(format!(
                "row {k} must be finite with no zero scale, got {r:?}"
            )));
        }
        poses.push(Pose {
            position: [r[0], r[1], r[2]],
            rotation_xyzw: [r[3], r[4], r[5], r[6]],
            scale: [r[7], r[8], r[9]],
        });
    }
    let mut moved = Vec::with_capacity(poses.len());
    for (id, pose) in ids.iter().zip(&poses) {
        let id = id.cast_into::<PyString>()?;
        if scene.scene.set_transform(id.to_str()?, pose).is_ok() {
            moved.push(id);
        }
    }
    Ok(moved)
}

/// turn_rates(before_xyzw, now_xyzw, dt_s) -> (m, 3) float64: the angular velocities, rad/s in
/// the world frame, of m objects turned from before_xyzw to now_xyzw, each (m, 4) float64
/// quaternions (x, y, z, w), in dt_s seconds: occlusion_maps.py's scipy
/// `(Rotation.from_quat(now) * Rotation.from_quat(before).inv()).as_rotvec() / dt_s` within
/// rounding, the same bits on every x86-64 machine (rotation.rs turn_rotvec). ValueError for
/// arrays of another shape, a zero or non-finite quaternion, or dt_s not positive.
#[pyfunction]
fn turn_rates<'py>(
    py: Python<'py>,
    before_xyzw: PyReadonlyArray2<'py, f64>,
    now_xyzw: PyReadonlyArray2<'py, f64>,
    dt_s: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let (before, now) = (before_xyzw.as_array(), now_xyzw.as_array());
    if before.ncols() != 4 || before.shape() != now.shape() {
        return Err(PyValueError::new_err(format!(
            "before_xyzw and now_xyzw must both be (m, 4), got {:?} and {:?}",
            before.shape(),
            now.shape()
        )));
    }
    if !(dt_s > 0.0 && dt_s.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "dt_s must be a positive number of seconds, got {dt_s}"
        )));
    }
    let mut rates = Vec::with_capacity(before.nrows());
    for (k, (b, n)) in before.outer_iter().zip(now.outer_iter()).enumerate() {
        let quat = |row: ArrayView1<'_, f64>| [row[0], row[1], row[2], row[3]];
        let turn = turn_rotvec(&quat(b), &quat(n)).ok_or_else(|| {
            PyValueError::new_err(format!(
                "object {k}: a quaternion must be finite and nonzero, got {:?} and {:?}",
                quat(b),
                quat(n)
            ))
        })?;
        rates.push(turn.map(|c| c / dt_s).to_vec());
    }
    if rates.is_empty() {
        return Ok(PyArray2::zeros(py, [0, 3], false));
    }
    PyArray2::from_vec2(py, &rates).map_err(|e| PyValueError::new_err(e.to_string()))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(move_scene, m)?)?;
    m.add_function(wrap_pyfunction!(turn_rates, m)?)
}
