//! camdirector._native's Toric functions: toric.rs behind Python signatures that match
//! src/camdirector/geometry/toric.py's argument for argument, so one can stand in for the other.
//!
//! What crosses: points and screen points as numpy float64 arrays or sequences (tuples, lists; any
//! other array-like is converted by numpy as np.asarray would); `lens` as camera.Lens (or any
//! object with vertical_fov_deg and aspect) or a tuple (vertical_fov_deg, aspect); results as
//! floats, tuples and fresh float64 arrays. Errors: DegenerateTorus (a ValueError) where Python
//! raises toric.DegenerateTorus, ValueError where it raises ValueError.

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{
    AllowTypeChange, PyArray1, PyArray2, PyArray3, PyArrayDyn, PyArrayLikeDyn, PyArrayMethods,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyFloat, PyTuple};

use crate::rotation::Vec3;
use crate::toric::{self, Degenerate, Lens, NoRotation};

pyo3::create_exception!(
    camdirector._native,
    DegenerateTorus,
    PyValueError,
    "A, B and alpha name no usable torus (A and B coincide, alpha near 0 or pi, non-finite input)."
);

impl From<Degenerate> for PyErr {
    fn from(e: Degenerate) -> PyErr {
        DegenerateTorus::new_err(e.0)
    }
}

impl From<NoRotation> for PyErr {
    fn from(e: NoRotation) -> PyErr {
        PyValueError::new_err(e.0)
    }
}

/// A float64 ndarray's values in C order, copied without a borrow: None unless it is C-contiguous.
/// The copy is made with the GIL held and no Rust reference to the array kept, so nothing can
/// write it meanwhile; rust-numpy's borrow registry (a shared hash map, entered and left per read)
/// cost the frame's few small reads more than the reads (docs/frame_path.md).
pub(crate) fn c_order_values(array: &Bound<'_, PyArrayDyn<f64>>) -> Option<Vec<f64>> {
    if array.is_c_contiguous() {
        array.to_vec().ok()
    } else {
        None
    }
}

/// Any array-like as a float64 array: a float64 ndarray as it is, anything else through numpy.
fn float_array<'py>(obj: &Bound<'py, PyAny>) -> PyResult<ArrayD<f64>> {
    if let Ok(array) = obj.cast::<PyArrayDyn<f64>>() {
        if let Some(values) = c_order_values(array) {
            return Ok(ArrayD::from_shape_vec(IxDyn(array.shape()), values).expect("its own shape"));
        }
        return Ok(array.try_readonly()?.as_array().to_owned());
    }
    let array: PyArrayLikeDyn<'py, f64, AllowTypeChange> = obj.extract()?;
    Ok(array.as_array().to_owned())
}

/// N floats (a point (3,), a screen point (2,)) from a float64 ndarray of N elements, a sequence
/// of N numbers, or any array-like numpy converts to N floats.
pub(crate) fn floats<const N: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; N]> {
    if let Ok(array) = obj.cast::<PyArrayDyn<f64>>() {
        if let Some(Ok(values)) = c_order_values(array).map(<[f64; N]>::try_from) {
            return Ok(values); // the per-frame case: N float64 values, one copy
        }
    } else if let Ok(values) = obj.extract::<[f64; N]>() {
        return Ok(values); // a tuple or list, no array made
    }
    let array = float_array(obj)?;
    <[f64; N]>::try_from(array.iter().copied().collect::<Vec<f64>>()).map_err(|_| {
        PyValueError::new_err(format!(
            "{name} must have shape ({N},), got {:?}",
            array.shape()
        ))
    })
}

/// The lens: a tuple (vertical_fov_deg, aspect) or an object with those attributes (camera.Lens).
pub(crate) fn lens_of(obj: &Bound<'_, PyAny>) -> PyResult<Lens> {
    let (vertical_fov_deg, aspect): (f64, f64) = match obj.cast::<PyTuple>() {
        Ok(tuple) => tuple.extract()?,
        Err(_) => (
            obj.getattr("vertical_fov_deg")?.extract()?,
            obj.getattr("aspect")?.extract()?,
        ),
    };
    Ok(Lens::new(vertical_fov_deg, aspect))
}

/// A (n,) float64 array made here.
pub(crate) type Array1<'py> = Bound<'py, PyArray1<f64>>;

/// (theta (n,), phi (n,)) radians.
type Angles<'py> = (Array1<'py>, Array1<'py>);

/// camera.CameraPose's fields: position_world (3,), rotation_xyzw (4,), vertical_fov_deg.
type Pose<'py> = (Array1<'py>, Array1<'py>, f64);

pub(crate) fn vec3<'py>(py: Python<'py>, v: &Vec3) -> Array1<'py> {
    PyArray1::from_slice(py, v)
}

/// The torus of camera centres framing A and B at angle alpha (toric.Torus); build it with
/// make_torus. a_world, b_world, axis_world, ref_world, side_world, mid_world: (3,) metres (the
/// directions unit); basis: (3, 3) rows axis, ref, side; alpha: radians. Arrays are fresh copies.
#[pyclass(name = "Torus", frozen, module = "camdirector._native")]
pub struct PyTorus {
    pub(crate) inner: toric::Torus,
}

#[pymethods]
impl PyTorus {
    #[getter]
    fn a_world<'py>(&self, py: Python<'py>) -> Array1<'py> {
        vec3(py, &self.inner.a_world)
    }
    #[getter]
    fn b_world<'py>(&self, py: Python<'py>) -> Array1<'py> {
        vec3(py, &self.inner.b_world)
    }
    #[getter]
    fn alpha(&self) -> f64 {
        self.inner.alpha
    }
    #[getter]
    fn axis_world<'py>(&self, py: Python<'py>) -> Array1<'py> {
        vec3(py, &self.inner.basis[0])
    }
    #[getter]
    fn ref_world<'py>(&self, py: Python<'py>) -> Array1<'py> {
        vec3(py, &self.inner.basis[1])
    }
    #[getter]
    fn side_world<'py>(&self, py: Python<'py>) -> Array1<'py> {
        vec3(py, &self.inner.basis[2])
    }
    #[getter]
    fn length_ab_m(&self) -> f64 {
        self.inner.length_ab_m
    }
    #[getter]
    fn arc_radius_m(&self) -> f64 {
        self.inner.arc_radius_m
    }
    #[getter]
    fn mid_world<'py>(&self, py: Python<'py>) -> Array1<'py> {
        vec3(py, &self.inner.mid_world)
    }
    #[getter]
    fn basis<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(PyArray2::from_vec2(
            py,
            &self.inner.basis.map(|row| row.to_vec()),
        )?)
    }
    #[getter]
    fn center_offset_m(&self) -> f64 {
        self.inner.center_offset_m
    }
}

/// make_torus(a_world, b_world, alpha, up_world=(0, 1, 0)) -> Torus (toric.make_torus; primer
/// sections 2-3). a_world, b_world, up_world: (3,) metres (up: any length); alpha: radians.
/// DegenerateTorus if |AB| < 1e-6 m, alpha is outside [1e-4, pi - 1e-4], an input is not finite
/// or up is zero; ValueError if a shape is wrong.
#[pyfunction]
#[pyo3(signature = (a_world, b_world, alpha, up_world = None))]
fn make_torus(
    a_world: &Bound<'_, PyAny>,
    b_world: &Bound<'_, PyAny>,
    alpha: f64,
    up_world: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyTorus> {
    let a = floats::<3>(a_world, "a_world")?;
    let b = floats::<3>(b_world, "b_world")?;
    let up = match up_world {
        Some(up) => floats::<3>(up, "up_world")?,
        None => [0.0, 1.0, 0.0],
    };
    Ok(PyTorus {
        inner: toric::make_torus(&a, &b, alpha, &up)?,
    })
}

/// theta_max(alpha) -> float: upper end 2 (pi - alpha) of theta's open range, radians.
#[pyfunction]
fn theta_max(alpha: f64) -> f64 {
    toric::theta_max(alpha)
}

/// view_direction(screen_xy, lens) -> (3,): unit camera-space direction through the normalised
/// screen point screen_xy (2,) (primer section 1).
#[pyfunction]
fn view_direction<'py>(
    py: Python<'py>,
    screen_xy: &Bound<'py, PyAny>,
    lens: &Bound<'py, PyAny>,
) -> PyResult<Array1<'py>> {
    Ok(vec3(
        py,
        &toric::view_direction(&floats(screen_xy, "screen_xy")?, &lens_of(lens)?),
    ))
}

/// composition_angle(screen_a, screen_b, lens) -> float: alpha, radians, the angle between the
/// view rays through screen_a (2,) and screen_b (2,) (primer section 1).
#[pyfunction]
fn composition_angle(
    screen_a: &Bound<'_, PyAny>,
    screen_b: &Bound<'_, PyAny>,
    lens: &Bound<'_, PyAny>,
) -> PyResult<f64> {
    Ok(toric::composition_angle(
        &floats(screen_a, "screen_a")?,
        &floats(screen_b, "screen_b")?,
        &lens_of(lens)?,
    ))
}

/// An angle argument: a float (the per-frame case) or an array of any shape.
fn angles(obj: &Bound<'_, PyAny>) -> PyResult<ArrayD<f64>> {
    if let Ok(value) = obj.cast::<PyFloat>() {
        return Ok(ArrayD::from_elem(IxDyn(&[]), value.value()));
    }
    float_array(obj)
}

/// numpy's broadcast shape of two shapes, None if they do not broadcast.
fn broadcast_shape(a: &[usize], b: &[usize]) -> Option<Vec<usize>> {
    let n = a.len().max(b.len());
    let at = |s: &[usize], i: usize| {
        if i + s.len() >= n {
            s[i + s.len() - n]
        } else {
            1
        }
    };
    (0..n)
        .map(|i| match (at(a, i), at(b, i)) {
            (x, y) if x == y || y == 1 => Some(x),
            (1, y) => Some(y),
            _ => None,
        })
        .collect()
}

/// torus_position(torus, theta, phi) -> camera centre, metres, at (theta, phi) radians
/// (toric.torus_position; primer section 3). Scalars give (3,); arrays broadcast together,
/// shape (...,) -> (..., 3). A theta outside its open range continues around the arc's circle.
#[pyfunction]
fn torus_position<'py>(
    py: Python<'py>,
    torus: &PyTorus,
    theta: &Bound<'py, PyAny>,
    phi: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let (thetas, phis) = (angles(theta)?, angles(phi)?);
    let shape = broadcast_shape(thetas.shape(), phis.shape()).ok_or_else(|| {
        PyValueError::new_err(format!(
            "theta {:?} and phi {:?} do not broadcast",
            thetas.shape(),
            phis.shape()
        ))
    })?;
    let (thetas, phis) = (
        thetas.broadcast(IxDyn(&shape)).expect("shape broadcasts"),
        phis.broadcast(IxDyn(&shape)).expect("shape broadcasts"),
    );
    let out: Vec<f64> = thetas
        .iter()
        .zip(phis.iter())
        .flat_map(|(&t, &p)| toric::torus_position(&torus.inner, t, p))
        .collect();
    let mut out_shape = shape;
    out_shape.push(3);
    let out = ArrayD::from_shape_vec(IxDyn(&out_shape), out).expect("3 values per place");
    Ok(PyArrayDyn::from_owned_array(py, out))
}

/// torus_angles(torus, position_world) -> (theta, phi) radians of the torus point for
/// position_world (3,) metres (toric.torus_angles; primer section 5): a point off the torus is
/// brought onto it, theta clamped to [1e-6, theta_max - 1e-6], phi in (-pi, pi].
#[pyfunction]
fn torus_angles(torus: &PyTorus, position_world: &Bound<'_, PyAny>) -> PyResult<(f64, f64)> {
    Ok(toric::torus_angles(
        &torus.inner,
        &floats(position_world, "position_world")?,
    ))
}

/// Rows of an (n, 3) array-like (or one (3,) point: atleast_2d), metres.
pub(crate) fn points(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Vec3>> {
    let array = float_array(obj)?;
    let shape = array.shape();
    if !(shape.len() <= 2 && shape.last() == Some(&3)) {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (n, 3), got {shape:?}"
        )));
    }
    Ok(array
        .iter()
        .copied()
        .collect::<Vec<f64>>()
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect())
}

/// torus_angles_many(torus, positions_world) -> (theta (n,), phi (n,)) radians: torus_angles for
/// (n, 3) points in metres at once, same rules.
#[pyfunction]
fn torus_angles_many<'py>(
    py: Python<'py>,
    torus: &PyTorus,
    positions_world: &Bound<'py, PyAny>,
) -> PyResult<Angles<'py>> {
    let (thetas, phis): (Vec<f64>, Vec<f64>) = points(positions_world, "positions_world")?
        .iter()
        .map(|p| toric::torus_angles(&torus.inner, p))
        .unzip();
    Ok((PyArray1::from_vec(py, thetas), PyArray1::from_vec(py, phis)))
}

type Frame<'py> = (Array1<'py>, Array1<'py>, Array1<'py>);

/// tangent_frame(torus, theta, phi) -> (d pos/d theta, d pos/d phi, outward unit normal), each
/// (3,) world, metres per radian for the derivatives (toric.tangent_frame; primer "Distortion").
#[pyfunction]
fn tangent_frame<'py>(py: Python<'py>, torus: &PyTorus, theta: f64, phi: f64) -> Frame<'py> {
    let [d_theta, d_phi, normal] = toric::tangent_frame(&torus.inner, theta, phi);
    (vec3(py, &d_theta), vec3(py, &d_phi), vec3(py, &normal))
}

/// What the rotations frame: A and B (3,) metres at screen_a and screen_b (2,) through the lens.
struct Framing {
    a: Vec3,
    b: Vec3,
    screen_a: [f64; 2],
    screen_b: [f64; 2],
    lens: Lens,
}

impl Framing {
    fn read(
        a_world: &Bound<'_, PyAny>,
        b_world: &Bound<'_, PyAny>,
        screen_a: &Bound<'_, PyAny>,
        screen_b: &Bound<'_, PyAny>,
        lens: &Bound<'_, PyAny>,
    ) -> PyResult<Framing> {
        Ok(Framing {
            a: floats(a_world, "a_world")?,
            b: floats(b_world, "b_world")?,
            screen_a: floats(screen_a, "screen_a")?,
            screen_b: floats(screen_b, "screen_b")?,
            lens: lens_of(lens)?,
        })
    }
}

/// look_rotation(camera_world, a_world, b_world, screen_a, screen_b, lens) -> (4,) xyzw, w >= 0:
/// the camera-to-world unit quaternion showing A at screen_a and B at screen_b (toric.
/// look_rotation; primer step 4, R = W D^T). Points (3,) metres, screen points (2,). ValueError
/// if the camera is at A or B or in line with both.
#[pyfunction]
fn look_rotation<'py>(
    py: Python<'py>,
    camera_world: &Bound<'py, PyAny>,
    a_world: &Bound<'py, PyAny>,
    b_world: &Bound<'py, PyAny>,
    screen_a: &Bound<'py, PyAny>,
    screen_b: &Bound<'py, PyAny>,
    lens: &Bound<'py, PyAny>,
) -> PyResult<Array1<'py>> {
    let camera = floats(camera_world, "camera_world")?;
    let f = Framing::read(a_world, b_world, screen_a, screen_b, lens)?;
    Ok(PyArray1::from_slice(
        py,
        &toric::look_rotation(&camera, &f.a, &f.b, &f.screen_a, &f.screen_b, &f.lens)?,
    ))
}

/// level_pair_rotation(camera_world, a_world, b_world, screen_a, screen_b, lens) -> (4,) xyzw:
/// camera-to-world unit quaternion with no roll framing A near screen_a and B near screen_b
/// (toric.level_pair_rotation). ValueError if the camera is at A or B or between them.
#[pyfunction]
fn level_pair_rotation<'py>(
    py: Python<'py>,
    camera_world: &Bound<'py, PyAny>,
    a_world: &Bound<'py, PyAny>,
    b_world: &Bound<'py, PyAny>,
    screen_a: &Bound<'py, PyAny>,
    screen_b: &Bound<'py, PyAny>,
    lens: &Bound<'py, PyAny>,
) -> PyResult<Array1<'py>> {
    let camera = floats(camera_world, "camera_world")?;
    let f = Framing::read(a_world, b_world, screen_a, screen_b, lens)?;
    Ok(PyArray1::from_slice(
        py,
        &toric::level_pair_rotation(&camera, &f.a, &f.b, &f.screen_a, &f.screen_b, &f.lens)?,
    ))
}

/// level_pair_matrices(cameras_world, a_world, b_world, screen_a, screen_b, lens) -> (m, 3, 3)
/// camera-to-world rotation matrices of level_pair_rotation for m cameras (m, 3) metres at once
/// (toric.level_pair_matrices); rows of NaN where a camera is at A or B or between them.
#[pyfunction]
fn level_pair_matrices<'py>(
    py: Python<'py>,
    cameras_world: &Bound<'py, PyAny>,
    a_world: &Bound<'py, PyAny>,
    b_world: &Bound<'py, PyAny>,
    screen_a: &Bound<'py, PyAny>,
    screen_b: &Bound<'py, PyAny>,
    lens: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let cameras = points(cameras_world, "cameras_world")?;
    let f = Framing::read(a_world, b_world, screen_a, screen_b, lens)?;
    let matrices =
        toric::level_pair_matrices(&cameras, &f.a, &f.b, &f.screen_a, &f.screen_b, &f.lens);
    let flat: Vec<f64> = matrices.iter().flatten().flatten().copied().collect();
    PyArray1::from_vec(py, flat).reshape([matrices.len(), 3, 3])
}

/// compose_pose(torus, theta, phi, screen_a, screen_b, lens) -> (position_world (3,) metres,
/// rotation_xyzw (4,), vertical_fov_deg): camera.CameraPose's fields, at (theta, phi) radians,
/// framing torus.a_world at screen_a (2,) and torus.b_world at screen_b (2,) (toric.compose_pose;
/// primer steps 3-4); the torus must be built with alpha = composition_angle(screen_a, screen_b, lens).
#[pyfunction]
fn compose_pose<'py>(
    py: Python<'py>,
    torus: &PyTorus,
    theta: f64,
    phi: f64,
    screen_a: &Bound<'py, PyAny>,
    screen_b: &Bound<'py, PyAny>,
    lens: &Bound<'py, PyAny>,
) -> PyResult<Pose<'py>> {
    let vertical_fov_deg: f64 = match lens.cast::<PyTuple>() {
        Ok(tuple) => tuple.get_item(0)?.extract()?,
        Err(_) => lens.getattr("vertical_fov_deg")?.extract()?,
    };
    let (sa, sb) = (floats(screen_a, "screen_a")?, floats(screen_b, "screen_b")?);
    let (position, rotation) =
        toric::compose_pose(&torus.inner, theta, phi, &sa, &sb, &lens_of(lens)?)?;
    Ok((
        vec3(py, &position),
        PyArray1::from_slice(py, &rotation),
        vertical_fov_deg,
    ))
}

/// Adds the Toric functions, the Torus class, DegenerateTorus and toric.py's constants.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTorus>()?;
    m.add("DegenerateTorus", m.py().get_type::<DegenerateTorus>())?;
    m.add("MIN_AB_DISTANCE_M", toric::MIN_AB_DISTANCE_M)?;
    m.add("MIN_ALPHA_RAD", toric::MIN_ALPHA_RAD)?;
    m.add("PARALLEL_SIN_EPS", toric::PARALLEL_SIN_EPS)?;
    m.add("THETA_MARGIN_RAD", toric::THETA_MARGIN_RAD)?;
    m.add_function(wrap_pyfunction!(make_torus, m)?)?;
    m.add_function(wrap_pyfunction!(theta_max, m)?)?;
    m.add_function(wrap_pyfunction!(view_direction, m)?)?;
    m.add_function(wrap_pyfunction!(composition_angle, m)?)?;
    m.add_function(wrap_pyfunction!(torus_position, m)?)?;
    m.add_function(wrap_pyfunction!(torus_angles, m)?)?;
    m.add_function(wrap_pyfunction!(torus_angles_many, m)?)?;
    m.add_function(wrap_pyfunction!(tangent_frame, m)?)?;
    m.add_function(wrap_pyfunction!(look_rotation, m)?)?;
    m.add_function(wrap_pyfunction!(level_pair_rotation, m)?)?;
    m.add_function(wrap_pyfunction!(level_pair_matrices, m)?)?;
    m.add_function(wrap_pyfunction!(compose_pose, m)?)?;
    Ok(())
}
