//! camdirector._native's TORIC FRAMING and MOTION stages (FRAMING_ONLY): framing.rs and
//! motion.rs behind classes that stand in for pipeline/toric/framing.py's Framing and
//! camera_motion.py's ToricMotion. Each holds what its Python twin holds between frames and is
//! built from the same arguments; its per-frame `run` takes what the Python reads from the
//! frame's state and answers what the Python writes into it.
//!
//! What crosses: `lens` as camera.Lens (or any object with vertical_fov_deg and aspect) or a
//! tuple (vertical_fov_deg, aspect); `style` as style.Style or any object with the fields these
//! stages read; `settings` as framing.FramingSettings / camera_motion.MotionSettings (or objects
//! with their fields), None for their defaults; points as (3,) array-likes; the torus as
//! _native's Torus; poses as (position_world (3,), rotation_xyzw (4,), vertical_fov_deg), the
//! fields of camera.CameraPose. Errors: ValueError where the Python raises ValueError.

use numpy::{PyArray1, PyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::framing::{Framing, FramingSettings, FramingStyle};
use crate::motion::{self, Motion, MotionSettings, MotionStyle};
use crate::rotation::Vec3;
use crate::toric::Lens;
use crate::toric_py::{floats, lens_of, points, vec3, Array1, PyTorus};

/// camera.CameraPose's fields: position_world (3,), rotation_xyzw (4,), vertical_fov_deg.
pub(crate) type PyPose<'py> = (Array1<'py>, Array1<'py>, f64);

/// The lens's tangents and its vertical field of view, degrees (a pose's field of view).
pub(crate) fn lens_and_fov(obj: &Bound<'_, PyAny>) -> PyResult<(Lens, f64)> {
    let fov: f64 = match obj.cast::<PyTuple>() {
        Ok(tuple) => tuple.get_item(0)?.extract()?,
        Err(_) => obj.getattr("vertical_fov_deg")?.extract()?,
    };
    Ok((lens_of(obj)?, fov))
}

pub(crate) fn attr(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<f64> {
    obj.getattr(name)?.extract()
}

pub(crate) fn screen(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 2]> {
    floats::<2>(&obj.getattr(name)?, name)
}

fn framing_style(style: &Bound<'_, PyAny>) -> PyResult<FramingStyle> {
    Ok(FramingStyle {
        screen_a: screen(style, "screen_a")?,
        screen_b: screen(style, "screen_b")?,
        gaze_room_m: attr(style, "gaze_room_m")?,
    })
}

fn motion_style(style: &Bound<'_, PyAny>) -> PyResult<MotionStyle> {
    Ok(MotionStyle {
        screen_a: screen(style, "screen_a")?,
        screen_b: screen(style, "screen_b")?,
        preferred_theta_ratio: attr(style, "preferred_theta_ratio")?,
        preferred_phi_deg: attr(style, "preferred_phi_deg")?,
        response_time_s: attr(style, "response_time_s")?,
        max_speed_m_s: attr(style, "max_speed_m_s")?,
        max_accel_m_s2: attr(style, "max_accel_m_s2")?,
    })
}

/// framing.FramingSettings's fields; None: its defaults.
fn framing_settings(settings: Option<&Bound<'_, PyAny>>) -> PyResult<FramingSettings> {
    Ok(match settings {
        Some(s) => FramingSettings {
            heading_time_constant_s: attr(s, "heading_time_constant_s")?,
            heading_min_speed_m_s: attr(s, "heading_min_speed_m_s")?,
            min_ab_distance_m: attr(s, "min_ab_distance_m")?,
        },
        None => FramingSettings {
            heading_time_constant_s: 0.6,
            heading_min_speed_m_s: 0.2,
            min_ab_distance_m: 1e-3,
        },
    })
}

/// camera_motion.MotionSettings's fields; None: its defaults.
fn motion_settings(settings: Option<&Bound<'_, PyAny>>) -> PyResult<MotionSettings> {
    Ok(match settings {
        Some(s) => MotionSettings {
            max_substep_s: attr(s, "max_substep_s")?,
            max_substeps: s.getattr("max_substeps")?.extract()?,
            theta_margin_rad: attr(s, "theta_margin_rad")?,
            side_hysteresis: attr(s, "side_hysteresis")?,
            side_recheck_axis_dot: attr(s, "side_recheck_axis_dot")?,
            side_tie: attr(s, "side_tie")?,
        },
        None => MotionSettings {
            max_substep_s: 1.0 / 60.0,
            max_substeps: 30,
            theta_margin_rad: 0.02,
            side_hysteresis: 0.2,
            side_recheck_axis_dot: 0.02,
            side_tie: 1e-9,
        },
    })
}

/// The frame's aim points: a list of (3,) array-likes (FrameState.aim_points_world) or (k, 3).
pub(crate) fn aim_points(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Vec3>> {
    if obj.is_instance_of::<PyArrayDyn<f64>>() {
        return points(obj, "aim_points_world");
    }
    obj.try_iter()?
        .map(|item| floats::<3>(&item?, "aim_points_world[i]"))
        .collect()
}

pub(crate) fn py_pose<'py>(py: Python<'py>, pose: &motion::Pose, fov_deg: f64) -> PyPose<'py> {
    (
        vec3(py, &pose.0),
        PyArray1::from_slice(py, &pose.1),
        fov_deg,
    )
}

/// What FramingCore.run answers: (a_world (3,), b_world (3,), b_is_gaze_point, torus or None,
/// flags).
type Framed<'py> = (
    Array1<'py>,
    Array1<'py>,
    bool,
    Option<PyTorus>,
    Vec<&'static str>,
);

/// FramingCore(lens, style, initial_rotation_xyzw, settings=None): framing.Framing compiled.
/// Keeps the one-target heading between frames; `run` fills a frame's A, B and torus.
#[pyclass(name = "FramingCore", module = "camdirector._native")]
pub struct FramingCore {
    pub(crate) inner: Framing,
}

#[pymethods]
impl FramingCore {
    #[new]
    #[pyo3(signature = (lens, style, initial_rotation_xyzw, settings = None))]
    fn new(
        lens: &Bound<'_, PyAny>,
        style: &Bound<'_, PyAny>,
        initial_rotation_xyzw: &Bound<'_, PyAny>,
        settings: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<FramingCore> {
        Ok(FramingCore {
            inner: Framing::new(
                lens_of(lens)?,
                framing_style(style)?,
                &floats::<4>(initial_rotation_xyzw, "initial_rotation_xyzw")?,
                framing_settings(settings)?,
            ),
        })
    }

    /// From the next frame on: the composition angle and the gaze room of `style`.
    fn set_style(&mut self, style: &Bound<'_, PyAny>) -> PyResult<()> {
        self.inner.set_style(framing_style(style)?);
        Ok(())
    }

    /// run(aim_points_world, dt_s) -> (a_world, b_world, b_is_gaze_point, torus, flags)
    /// (Framing.run): aim_points_world one or two (3,) points, metres; dt_s since the last frame;
    /// torus None when the framing is degenerate; flags what Framing.run appends to state.flags.
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        aim_points_world: &Bound<'py, PyAny>,
        dt_s: f64,
    ) -> PyResult<Framed<'py>> {
        let aims = aim_points(aim_points_world)?;
        if aims.is_empty() {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "aim_points_world is empty",
            ));
        }
        let framed = self.inner.run(&aims, dt_s);
        Ok((
            vec3(py, &framed.a_world),
            vec3(py, &framed.b_world),
            framed.b_is_gaze_point,
            framed.torus.map(|inner| PyTorus { inner }),
            framed.flags,
        ))
    }

    /// error(position_world, rotation_xyzw, a_world, b_world, b_is_gaze_point) -> float
    /// (Framing.error): the frame's framing error, normalised screen units, from its final pose;
    /// NaN when a framed point is behind the camera.
    fn error(
        &self,
        position_world: &Bound<'_, PyAny>,
        rotation_xyzw: &Bound<'_, PyAny>,
        a_world: &Bound<'_, PyAny>,
        b_world: &Bound<'_, PyAny>,
        b_is_gaze_point: bool,
    ) -> PyResult<f64> {
        Ok(self.inner.error(
            &floats(position_world, "position_world")?,
            &floats(rotation_xyzw, "rotation_xyzw")?,
            &floats(a_world, "a_world")?,
            &floats(b_world, "b_world")?,
            b_is_gaze_point,
        ))
    }

    /// The smoothed one-target heading, radians about world up from +Z.
    #[getter]
    fn heading_rad(&self) -> f64 {
        self.inner.heading_rad
    }

    /// The style's composition angle, radians.
    #[getter]
    fn alpha(&self) -> f64 {
        self.inner.alpha
    }

    #[setter]
    fn set_heading_rad(&mut self, heading_rad: f64) {
        self.inner.heading_rad = heading_rad;
    }

    /// The last aim point the heading saw (3,), metres; None before the first.
    #[getter]
    fn last_aim<'py>(&self, py: Python<'py>) -> Option<Array1<'py>> {
        self.inner.last_aim.map(|p| vec3(py, &p))
    }

    #[setter]
    fn set_last_aim(&mut self, last_aim: Option<Bound<'_, PyAny>>) -> PyResult<()> {
        self.inner.last_aim = last_aim.map(|p| floats::<3>(&p, "last_aim")).transpose()?;
        Ok(())
    }
}

/// What MotionCore.run answers: (theta, phi, pose or None, flags).
type Placed<'py> = (f64, f64, Option<PyPose<'py>>, Vec<&'static str>);

/// MotionCore(style, lens, settings=None): camera_motion.ToricMotion compiled. Keeps the
/// camera's place on the torus and its rates between frames; `run` moves it for one frame.
#[pyclass(name = "MotionCore", module = "camdirector._native")]
pub struct MotionCore {
    pub(crate) inner: Motion,
    pub(crate) fov_deg: f64,
}

#[pymethods]
impl MotionCore {
    #[new]
    #[pyo3(signature = (style, lens, settings = None))]
    fn new(
        style: &Bound<'_, PyAny>,
        lens: &Bound<'_, PyAny>,
        settings: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<MotionCore> {
        let (lens, fov_deg) = lens_and_fov(lens)?;
        Ok(MotionCore {
            inner: Motion::new(motion_style(style)?, lens, motion_settings(settings)?),
            fov_deg,
        })
    }

    /// From the next frame on; the upright side is re-chosen.
    fn set_style(&mut self, style: &Bound<'_, PyAny>) -> PyResult<()> {
        self.inner.set_style(motion_style(style)?);
        Ok(())
    }

    /// preferred_place(torus) -> (theta, phi, theta_lo, theta_hi) radians
    /// (ToricMotion.preferred_place): the style's place on the upright side.
    fn preferred_place(&mut self, torus: &PyTorus) -> PyResult<(f64, f64, f64, f64)> {
        let [theta, phi, lo, hi] = self.inner.preferred_place(&torus.inner)?;
        Ok((theta, phi, lo, hi))
    }

    /// run(torus, b_is_gaze_point, dt_s) -> (theta, phi, pose, flags) (ToricMotion.run): the
    /// camera's place (radians) on the frame's torus and its pose; torus None (degenerate
    /// framing): the place held, pose None and flags ["pose_held"].
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        torus: Option<PyRef<'py, PyTorus>>,
        b_is_gaze_point: bool,
        dt_s: f64,
    ) -> PyResult<Placed<'py>> {
        let placed = self
            .inner
            .run(torus.as_deref().map(|t| &t.inner), b_is_gaze_point, dt_s)?;
        let flags = if placed.pose.is_none() {
            vec!["pose_held"]
        } else {
            vec![]
        };
        Ok((
            placed.theta,
            placed.phi,
            placed.pose.map(|pose| py_pose(py, &pose, self.fov_deg)),
            flags,
        ))
    }

    // The state kept between frames, each with a setter: a rig hands the camera to the Python
    // stages and back (pipeline/toric/compiled_rig.py) by copying these to and from ToricMotion's.

    /// The camera's theta, radians; None before the first torus.
    #[getter]
    fn theta(&self) -> Option<f64> {
        self.inner.theta
    }

    #[setter]
    fn set_theta(&mut self, theta: Option<f64>) {
        self.inner.theta = theta;
    }

    #[getter]
    fn phi(&self) -> f64 {
        self.inner.phi
    }

    #[setter]
    fn set_phi(&mut self, phi: f64) {
        self.inner.phi = phi;
    }

    /// (dtheta/dt, dphi/dt), rad/s.
    #[getter]
    fn rate<'py>(&self, py: Python<'py>) -> Array1<'py> {
        PyArray1::from_slice(py, &self.inner.rate)
    }

    #[setter]
    fn set_rate(&mut self, rate: &Bound<'_, PyAny>) -> PyResult<()> {
        self.inner.rate = floats::<2>(rate, "rate")?;
        Ok(())
    }

    /// The last pose's position (3,), metres; None before the first.
    #[getter]
    fn position_world<'py>(&self, py: Python<'py>) -> Option<Array1<'py>> {
        self.inner.position_world.map(|p| vec3(py, &p))
    }

    #[setter]
    fn set_position_world(&mut self, position_world: Option<Bound<'_, PyAny>>) -> PyResult<()> {
        self.inner.position_world = position_world
            .map(|p| floats::<3>(&p, "position_world"))
            .transpose()?;
        Ok(())
    }

    /// +1 or -1: the upright half of the torus (0 before the first choice).
    #[getter]
    fn side(&self) -> f64 {
        self.inner.side
    }

    #[setter]
    fn set_side(&mut self, side: f64) {
        self.inner.side = side;
    }

    /// The A-B axis's elevation (dot with world up) the side was chosen at; None: re-choose it
    /// on the next frame (ToricMotion._side_key).
    #[getter]
    fn side_key(&self) -> Option<f64> {
        self.inner.side_key
    }

    #[setter]
    fn set_side_key(&mut self, side_key: Option<f64>) {
        self.inner.side_key = side_key;
    }
}

/// pose_on_torus(torus, theta, phi, style, lens, level) -> (position_world (3,), rotation_xyzw
/// (4,), vertical_fov_deg) (camera_motion.pose_on_torus): the camera at (theta, phi) radians
/// composing A and B; with `level` A exact and the horizon level.
#[pyfunction]
fn pose_on_torus<'py>(
    py: Python<'py>,
    torus: &PyTorus,
    theta: f64,
    phi: f64,
    style: &Bound<'py, PyAny>,
    lens: &Bound<'py, PyAny>,
    level: bool,
) -> PyResult<PyPose<'py>> {
    let (screen_a, screen_b) = (screen(style, "screen_a")?, screen(style, "screen_b")?);
    let (lens, fov_deg) = lens_and_fov(lens)?;
    let pose = motion::pose_on_torus(&torus.inner, theta, phi, &screen_a, &screen_b, &lens, level)?;
    Ok(py_pose(py, &pose, fov_deg))
}

/// Adds FramingCore, MotionCore and pose_on_torus.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<FramingCore>()?;
    m.add_class::<MotionCore>()?;
    m.add_function(wrap_pyfunction!(pose_on_torus, m)?)?;
    Ok(())
}
