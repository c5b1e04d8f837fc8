//! camdirector._native.Bvh: the deterministic BVH (bvh.rs) for Python, with the queries of
//! geometry/raycast.py's RayScene on static meshes (`occluded`, `first_hit`). Arrays are copied in
//! with the GIL held, then every ray is cast with it released.

use numpy::ndarray::ArrayView2;
use numpy::{PyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::bvh::{Bvh, Stack};

/// Where a segment stops, as a share of origin -> target: RayScene.occluded's 1 - 1e-4, so a
/// target on a surface does not occlude itself.
pub(crate) const SEGMENT_END: f64 = 1.0 - 1e-4;

/// Rows of an (n, 3) array, refused unless (n, 3) and finite (NaN would slip through every test).
pub(crate) fn rows(name: &str, array: ArrayView2<'_, f64>) -> PyResult<Vec<[f64; 3]>> {
    if array.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "{name} must be (n, 3), got {:?}",
            array.shape()
        )));
    }
    let out: Vec<[f64; 3]> = array
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2]])
        .collect();
    if out.iter().flatten().any(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{name} has NaN or infinite coordinates"
        )));
    }
    Ok(out)
}

/// Two (n, 3) arrays of the same n, as rows.
pub(crate) type RowPairs = (Vec<[f64; 3]>, Vec<[f64; 3]>);

pub(crate) fn pairs(
    names: [&str; 2],
    first: &PyReadonlyArray2<'_, f64>,
    second: &PyReadonlyArray2<'_, f64>,
) -> PyResult<RowPairs> {
    if first.shape() != second.shape() {
        let [a, b] = names;
        return Err(PyValueError::new_err(format!(
            "{a} {:?} and {b} {:?} differ in shape",
            first.shape(),
            second.shape()
        )));
    }
    Ok((
        rows(names[0], first.as_array())?,
        rows(names[1], second.as_array())?,
    ))
}

/// Faces as int32 (TriMesh's) or int64 (numpy's default) (m, 3) indices, all into `n` vertices.
pub(crate) fn faces_of(faces: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<[u32; 3]>> {
    let (shape, indices): (Vec<usize>, Vec<i64>) =
        if let Ok(a) = faces.extract::<PyReadonlyArray2<'_, i32>>() {
            (
                a.shape().to_vec(),
                a.as_array().iter().map(|&i| i as i64).collect(),
            )
        } else {
            let a = faces.extract::<PyReadonlyArray2<'_, i64>>()?;
            (a.shape().to_vec(), a.as_array().iter().copied().collect())
        };
    if shape[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "faces must be (m, 3), got {shape:?}"
        )));
    }
    if indices.is_empty() {
        return Err(PyValueError::new_err(
            "faces is empty: a Bvh needs at least one triangle",
        ));
    }
    if indices.iter().any(|&i| i < 0 || i as usize >= n) {
        return Err(PyValueError::new_err(format!(
            "a face index is out of range (there are {n} vertices)"
        )));
    }
    // ndarray iterates in logical (row-major) order, whatever the strides
    Ok(indices
        .chunks_exact(3)
        .map(|f| [f[0] as u32, f[1] as u32, f[2] as u32])
        .collect())
}

/// A deterministic BVH of one static triangle mesh: the same answers, to the bit, on every x86-64
/// machine (native/src/bvh.rs says how). Built from vertices (n, 3) float64 metres and faces
/// (m, 3) int32 or int64, a TriMesh's arrays. Ray parameters are in units of the direction's
/// length, as Embree's.
#[pyclass(name = "Bvh", module = "camdirector._native", frozen)]
pub struct PyBvh {
    bvh: Bvh,
}

#[pymethods]
impl PyBvh {
    #[new]
    fn new(
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f64>,
        faces: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        let vertices = rows("vertices", vertices.as_array())?;
        let faces = faces_of(faces, vertices.len())?;
        let bvh = py.detach(|| Bvh::new(&vertices, &faces));
        Ok(PyBvh { bvh })
    }

    /// RayScene.occluded's segment end (a share of origin -> target).
    #[classattr]
    const SEGMENT_END: f64 = SEGMENT_END;

    #[getter]
    fn triangle_count(&self) -> usize {
        self.bvh.triangle_count()
    }

    /// (k,) bool: whether the segment from each origin to its target (k, 3) float64 meets a
    /// triangle at 0 <= t <= SEGMENT_END of the way (RayScene.occluded's segment).
    fn occluded<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f64>,
        targets: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (origins, targets) = pairs(["origins", "targets"], &origins, &targets)?;
        let hit: Vec<bool> = py.detach(|| {
            let mut stack = Stack::with_capacity(64);
            let mut out = Vec::with_capacity(origins.len());
            for (o, t) in origins.iter().zip(&targets) {
                let direction = [t[0] - o[0], t[1] - o[1], t[2] - o[2]];
                out.push(self.bvh.occluded(*o, direction, SEGMENT_END, &mut stack));
            }
            out
        });
        Ok(PyArray1::from_vec(py, hit))
    }

    /// (k,) float64: the ray parameter t >= 0 of the nearest hit along each ray o + t d, origins and
    /// directions (k, 3) float64 (not necessarily unit: t is in units of |d|); inf where none.
    /// t_max: only hits at t <= t_max count (Bvh::first_hit_within, what the maps cast).
    #[pyo3(signature = (origins, directions, t_max = f64::INFINITY))]
    fn first_hit<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f64>,
        directions: PyReadonlyArray2<'py, f64>,
        t_max: f64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (origins, directions) = pairs(["origins", "directions"], &origins, &directions)?;
        let t: Vec<f64> = py.detach(|| {
            let mut stack = Stack::with_capacity(64);
            origins
                .iter()
                .zip(&directions)
                .map(
                    |(o, d)| match self.bvh.first_hit_within(*o, *d, t_max, &mut stack) {
                        (t, Some(_)) => t,
                        (_, None) => f64::INFINITY,
                    },
                )
                .collect()
        });
        Ok(PyArray1::from_vec(py, t))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyBvh>()
}
