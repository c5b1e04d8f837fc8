//! camdirector._native.toric_frame: the stages after INGEST of a compiled TORIC frame in
//! FRAMING_ONLY or REACTIVE (pipeline/toric/compiled_rig.py) in one call: FRAMING (FramingCore),
//! MOTION (MotionCore; in REACTIVE, DeoccluderCore's pull in front of occluders), VISIBILITY
//! (Scene.visible_share_of and FramingCore.error), each lapped on the session's clock where
//! ToricRig.run's StageClock laps it. It runs the cores' own code in the order the separate
//! calls ran it, so a frame has the same bits either way; what it saves is the Python between
//! those calls (about ten arrays, tuples and attribute reads and three laps a frame:
//! docs/frame_path.md).

use pyo3::exceptions::PyValueError;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

use crate::deoccluder_py::DeoccluderCore;
use crate::scene_py::PyScene;
use crate::stages_py::{aim_points, py_pose, FramingCore, MotionCore, PyPose};
use crate::toric_py::{floats, vec3, Array1, PyTorus};

/// What toric_frame answers: (a_world (3,), b_world (3,), b_is_gaze_point, torus or None, theta,
/// phi, pose or None (None: held_pose holds), flags, visibility, framing_error).
type Frame<'py> = (
    Array1<'py>,
    Array1<'py>,
    bool,
    Option<PyTorus>,
    f64,
    f64,
    Option<PyPose<'py>>,
    Vec<&'static str>,
    f64,
    f64,
);

/// StageClock.done on a frame's stage_ms: the time since `last_s` added to `key`'s laps, ms.
pub(crate) struct Laps<'a, 'py> {
    pub(crate) clock: &'a Bound<'py, PyAny>,
    pub(crate) stage_ms: &'a Bound<'py, PyDict>,
    pub(crate) last_s: f64,
}

impl Laps<'_, '_> {
    pub(crate) fn done(&mut self, key: &Bound<'_, PyString>) -> PyResult<()> {
        let now_s: f64 = self.clock.call0()?.extract()?;
        let before: f64 = match self.stage_ms.get_item(key)? {
            Some(ms) => ms.extract()?,
            None => 0.0,
        };
        self.stage_ms
            .set_item(key, before + (now_s - self.last_s) * 1e3)?;
        self.last_s = now_s;
        Ok(())
    }
}

/// toric_frame(framing, motion, deoccluder, scene, aim_points_world, samples_local,
/// target_transforms, held_pose, time_s, dt_s, clock, start_s, stage_ms) -> (a_world, b_world,
/// b_is_gaze_point, torus, theta, phi, pose, flags, visibility, framing_error): CompiledToricRig's
/// FRAMING, MOTION and VISIBILITY of one frame (module docstring).
///
/// framing, motion: the rig's FramingCore and MotionCore; deoccluder: its DeoccluderCore in
/// REACTIVE, None in FRAMING_ONLY; scene: the session's Scene, its moving objects already where
/// the frame puts them; aim_points_world: one (3,) point a target, metres; samples_local: each
/// target's sample points (k, 3) in its frame; target_transforms: the targets' RigidTransforms in
/// target order; held_pose: the camera.CameraPose the frame keeps when MOTION answers none (a
/// degenerate torus: the last pose); time_s, dt_s: the frame's, s; clock: the session's clock (s),
/// read after each stage; start_s: its reading before FRAMING; stage_ms: the frame's laps (ms),
/// where "framing", "motion" and "visibility" are added. flags: what the stages append to the
/// state's, in order. ValueError for no aim points or no sample points.
#[pyfunction]
#[allow(clippy::too_many_arguments)] // the frame's inputs, one by one, as the separate calls took them
fn toric_frame<'py>(
    py: Python<'py>,
    mut framing: PyRefMut<'py, FramingCore>,
    mut motion: PyRefMut<'py, MotionCore>,
    deoccluder: Option<PyRefMut<'py, DeoccluderCore>>,
    scene: PyRef<'py, PyScene>,
    aim_points_world: &Bound<'py, PyAny>,
    samples_local: &Bound<'py, PyAny>,
    target_transforms: &Bound<'py, PyAny>,
    held_pose: &Bound<'py, PyAny>,
    time_s: f64,
    dt_s: f64,
    clock: &Bound<'py, PyAny>,
    start_s: f64,
    stage_ms: &Bound<'py, PyDict>,
) -> PyResult<Frame<'py>> {
    let mut laps = Laps {
        clock,
        stage_ms,
        last_s: start_s,
    };
    // FRAMING
    let aims = aim_points(aim_points_world)?;
    if aims.is_empty() {
        return Err(PyValueError::new_err("aim_points_world is empty"));
    }
    let framed = framing.inner.run(&aims, dt_s);
    let (a_world, b_world, b_is_gaze_point) =
        (framed.a_world, framed.b_world, framed.b_is_gaze_point);
    let mut flags = framed.flags;
    laps.done(intern!(py, "framing"))?;
    // MOTION
    let placed = motion
        .inner
        .run(framed.torus.as_ref(), b_is_gaze_point, dt_s)?;
    let mut pose = placed.pose;
    match (&mut pose, deoccluder) {
        (None, _) => flags.push("pose_held"),
        (Some(pose), Some(mut deoccluder)) => {
            let (camera, rotation, pulled) =
                deoccluder
                    .inner
                    .run(&pose.0, &pose.1, &a_world, time_s, dt_s, &scene.scene);
            if pulled {
                *pose = (camera, rotation);
                flags.push("pulled_in");
            }
        }
        (Some(_), None) => {}
    }
    laps.done(intern!(py, "motion"))?;
    // VISIBILITY, from the frame's final pose
    let (position, rotation) = match &pose {
        Some((position, rotation)) => (*position, *rotation),
        None => (
            floats::<3>(
                &held_pose.getattr(intern!(py, "position_world"))?,
                "held_pose.position_world",
            )?,
            floats::<4>(
                &held_pose.getattr(intern!(py, "rotation_xyzw"))?,
                "held_pose.rotation_xyzw",
            )?,
        ),
    };
    let visibility = scene.carried_share(py, &position, samples_local, target_transforms)?;
    let framing_error =
        framing
            .inner
            .error(&position, &rotation, &a_world, &b_world, b_is_gaze_point);
    laps.done(intern!(py, "visibility"))?;
    Ok((
        vec3(py, &a_world),
        vec3(py, &b_world),
        b_is_gaze_point,
        framed.torus.map(|inner| PyTorus { inner }),
        placed.theta,
        placed.phi,
        pose.map(|pose| py_pose(py, &pose, motion.fov_deg)),
        flags,
        visibility,
        framing_error,
    ))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(toric_frame, m)?)
}
