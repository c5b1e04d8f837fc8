//! camdirector._native.DeoccluderCore: deoccluder.rs behind a class that stands in for
//! pipeline/toric/reactive.py's Deoccluder (the same settings, the same state between frames, each
//! readable and settable so a rig hands it to the Python twin and back).

use pyo3::prelude::*;

use crate::deoccluder::{Deoccluder, DeoccluderSettings};
use crate::scene_py::PyScene;
use crate::stages_py::attr;
use crate::toric_py::{floats, vec3, Array1};

/// What DeoccluderCore.run answers: (position_world (3,), rotation_xyzw (4,), displaced).
type Corrected<'py> = (Array1<'py>, Array1<'py>, bool);

/// DeoccluderCore(settings): reactive.Deoccluder compiled, `settings` a reactive.ReactiveSettings
/// (or an object with its fields). The state starts as a new Deoccluder's.
#[pyclass(name = "DeoccluderCore", module = "camdirector._native")]
pub struct DeoccluderCore {
    pub(crate) inner: Deoccluder,
}

#[pymethods]
impl DeoccluderCore {
    #[new]
    fn new(settings: &Bound<'_, PyAny>) -> PyResult<DeoccluderCore> {
        Ok(DeoccluderCore {
            inner: Deoccluder::new(DeoccluderSettings {
                minimum_distance_m: attr(settings, "minimum_distance_m")?,
                camera_radius_m: attr(settings, "camera_radius_m")?,
                damping_s: attr(settings, "damping_s")?,
                damping_when_occluded_s: attr(settings, "damping_when_occluded_s")?,
            }),
        })
    }

    /// run(position_world, rotation_xyzw, a_world, time_s, dt_s, scene) -> (position_world,
    /// rotation_xyzw, displaced) (Deoccluder.run on the proposed pose's position and rotation):
    /// its ray casts in `scene`, the session's Scene.
    #[allow(clippy::too_many_arguments)] // the Python twin's arguments, one by one
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        position_world: &Bound<'py, PyAny>,
        rotation_xyzw: &Bound<'py, PyAny>,
        a_world: &Bound<'py, PyAny>,
        time_s: f64,
        dt_s: f64,
        scene: PyRef<'py, PyScene>,
    ) -> PyResult<Corrected<'py>> {
        let position = floats::<3>(position_world, "position_world")?;
        let rotation = floats::<4>(rotation_xyzw, "rotation_xyzw")?;
        let a = floats::<3>(a_world, "a_world")?;
        let (camera, rotation, displaced) =
            self.inner
                .run(&position, &rotation, &a, time_s, dt_s, &scene.scene);
        Ok((
            vec3(py, &camera),
            numpy::PyArray1::from_slice(py, &rotation),
            displaced,
        ))
    }

    // The state kept between frames (reactive.Deoccluder's), each with a setter.

    /// Last camera position - A, m; None before the first run.
    #[getter]
    fn offset_from_a<'py>(&self, py: Python<'py>) -> Option<Array1<'py>> {
        self.inner.offset_from_a.map(|v| vec3(py, &v))
    }

    #[setter]
    fn set_offset_from_a(&mut self, value: Option<Bound<'_, PyAny>>) -> PyResult<()> {
        self.inner.offset_from_a = value
            .map(|v| floats::<3>(&v, "offset_from_a"))
            .transpose()?;
        Ok(())
    }

    /// The last correction, m.
    #[getter]
    fn displacement<'py>(&self, py: Python<'py>) -> Array1<'py> {
        vec3(py, &self.inner.displacement)
    }

    #[setter]
    fn set_displacement(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        self.inner.displacement = floats::<3>(value, "displacement")?;
        Ok(())
    }

    /// The last damping time, s.
    #[getter]
    fn damp_time_s(&self) -> f64 {
        self.inner.damp_time_s
    }

    #[setter]
    fn set_damp_time_s(&mut self, value: f64) {
        self.inner.damp_time_s = value;
    }

    /// When it last ran, s; None before the first run.
    #[getter]
    fn time_s(&self) -> Option<f64> {
        self.inner.time_s
    }

    #[setter]
    fn set_time_s(&mut self, value: Option<f64>) {
        self.inner.time_s = value;
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<DeoccluderCore>()?;
    Ok(())
}
