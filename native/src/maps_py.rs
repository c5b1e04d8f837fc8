//! camdirector._native.shadow_velocity_maps: the S-maps and V-maps by ray casting (maps.rs) for
//! Python, the compute of geometry/toric_maps/native.py's NativeMapBackend. The torus is
//! _native's or geometry.toric's, the window a MapWindow, the Scene a _native.Scene holding the
//! occluder scene's meshes (its moving objects in the OccluderScene's order); the rays are cast
//! with the GIL released.

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::bvh_py::rows;
use crate::maps::{shadow_velocity_maps as compute, Motion, Sample};
use crate::scene_py::PyScene;
use crate::search_py::{torus_of, window_of};

/// (shadow (k, res, res) float32, velocity_rad_s (k, res, res, 2) float32, depth_m (k, res, res)
/// float32): ShadowVelocityMaps' arrays.
type MapArrays<'py> = (Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>);

/// shadow_velocity_maps(scene, torus, window, sample_points_world, ignores, positions_world,
/// linear_velocities_m_s, angular_velocities_rad_s, previous_torus=None, dt_s=0.0)
/// -> (shadow, velocity_rad_s, depth_m)
///
/// The maps of sample_points_world (k, 3) metres over `window` of `torus`
/// (EmbreeMapBackend.compute): ignores, k entries, the index among the Scene's moving objects of
/// each sample's own object, or -1; the moving objects' origins (m, 3) world metres and their
/// linear (m, 3) m/s and angular (m, 3) rad/s world velocities, in the Scene's order;
/// previous_torus with dt_s > 0: the torus dt_s earlier (its points' velocity is subtracted).
#[pyfunction]
#[pyo3(signature = (scene, torus, window, sample_points_world, ignores, positions_world, linear_velocities_m_s, angular_velocities_rad_s, previous_torus = None, dt_s = 0.0))]
#[allow(clippy::too_many_arguments)]
fn shadow_velocity_maps<'py>(
    py: Python<'py>,
    scene: PyRef<'py, PyScene>,
    torus: &Bound<'py, PyAny>,
    window: &Bound<'py, PyAny>,
    sample_points_world: PyReadonlyArray2<'py, f64>,
    ignores: Vec<i64>,
    positions_world: PyReadonlyArray2<'py, f64>,
    linear_velocities_m_s: PyReadonlyArray2<'py, f64>,
    angular_velocities_rad_s: PyReadonlyArray2<'py, f64>,
    previous_torus: Option<&Bound<'py, PyAny>>,
    dt_s: f64,
) -> PyResult<MapArrays<'py>> {
    let torus = torus_of(torus)?;
    let window = window_of(window)?;
    let points = rows("sample_points_world", sample_points_world.as_array())?;
    let objects = scene.scene.objects.len();
    if ignores.len() != points.len() || ignores.iter().any(|&i| i < -1 || i >= objects as i64) {
        return Err(PyValueError::new_err(format!(
            "ignores must be {} entries, each -1 or a moving object's index below {objects}",
            points.len()
        )));
    }
    let [positions, linear, angular] = [
        ("positions_world", &positions_world),
        ("linear_velocities_m_s", &linear_velocities_m_s),
        ("angular_velocities_rad_s", &angular_velocities_rad_s),
    ]
    .map(|(name, array)| rows(name, array.as_array()));
    let (positions, linear, angular) = (positions?, linear?, angular?);
    if [positions.len(), linear.len(), angular.len()] != [objects; 3] {
        return Err(PyValueError::new_err(format!(
            "one position and velocity per moving object: {objects}"
        )));
    }
    let motions: Vec<Motion> = (0..objects)
        .map(|i| Motion {
            position: positions[i],
            linear: linear[i],
            angular: angular[i],
        })
        .collect();
    let samples: Vec<Sample> = points
        .iter()
        .zip(&ignores)
        .map(|(&point, &i)| Sample {
            point,
            ignores: (i >= 0).then_some(i as usize),
        })
        .collect();
    let previous = match previous_torus {
        Some(before) if dt_s > 0.0 && dt_s.is_finite() => Some(torus_of(before)?),
        Some(_) => return Err(PyValueError::new_err("previous_torus needs dt_s > 0")),
        None => None,
    };
    let scene = &scene.scene;
    let maps = py.detach(|| {
        compute(
            scene,
            &motions,
            &torus,
            &window,
            &samples,
            previous.as_ref().map(|before| (before, dt_s)),
        )
    });
    let (k, n) = (samples.len(), window.resolution);
    let velocity: Vec<f32> = maps.velocity.iter().flatten().copied().collect();
    Ok((
        PyArray1::from_vec(py, maps.shadow)
            .reshape([k, n, n])?
            .into_any(),
        PyArray1::from_vec(py, velocity)
            .reshape([k, n, n, 2])?
            .into_any(),
        PyArray1::from_vec(py, maps.depth)
            .reshape([k, n, n])?
            .into_any(),
    ))
}

/// set_map_threads(threads): how many threads each later shadow_velocity_maps call of this
/// process may share its texels among (1, the default: the caller's alone; maps.rs set_threads).
/// The maps are the same bits whatever the count.
#[pyfunction]
fn set_map_threads(threads: usize) {
    crate::maps::set_threads(threads);
}

/// set_map_threads_here(threads): set_map_threads for the calling thread's later calls alone, over
/// the process's count (maps.rs set_threads_here).
#[pyfunction]
fn set_map_threads_here(threads: usize) {
    crate::maps::set_threads_here(threads);
}

/// Adds shadow_velocity_maps, set_map_threads and set_map_threads_here.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(shadow_velocity_maps, m)?)?;
    m.add_function(wrap_pyfunction!(set_map_threads, m)?)?;
    m.add_function(wrap_pyfunction!(set_map_threads_here, m)?)
}
