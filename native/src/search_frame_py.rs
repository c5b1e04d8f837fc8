//! camdirector._native.search_frame: MOTION's search and VISIBILITY of a compiled TORIC frame in
//! a search mode (ANTICIPATION, NO_ANTICIPATION, RAYCAST; pipeline/toric/compiled_rig.py) in one
//! call, after FRAMING and, in the map modes, the maps' update: the sample points carried by the
//! targets, the upright side (MotionCore.preferred_place), SearchCore.step and the pose at its
//! answer, then the share seen (Scene.visible_share_of) and FramingCore.error, lapped on the
//! session's clock where ToricRig.run's StageClock laps MOTION and VISIBILITY. It runs the code
//! the separate calls ran, in their order, so a frame has the same bits either way; what it saves
//! is the Python between them (the side's compose_pose in numpy, the points' concatenation, the
//! step's result objects, a second Scene check and two laps: docs/frame_path.md).

use pyo3::exceptions::PyValueError;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::carry::carry;
use crate::scene_py::{points_of, pose_of, PyScene};
use crate::search_py::{ParticleIn, PyParticle, SearchCore};
use crate::stages_py::{py_pose, FramingCore, MotionCore, PyPose};
use crate::toric_frame_py::Laps;
use crate::toric_py::{floats, PyTorus};

/// What search_frame answers: (theta, phi, cut, strategy, particle, pose, side, side_key,
/// visibility, framing_error).
type Searched<'py> = (
    f64,
    f64,
    bool,
    &'static str,
    PyParticle<'py>,
    PyPose<'py>,
    f64,
    Option<f64>,
    f64,
    f64,
);

/// (n, 3) world metres: `points_local`'s rows carried target by target, in equal blocks, each by
/// its target's transform (CarriedTargetSampler.points_world, all slots).
fn carried_points(
    points_local: &Bound<'_, PyAny>,
    target_transforms: &Bound<'_, PyAny>,
) -> PyResult<Vec<[f64; 3]>> {
    let (local, _) = points_of("points_local", points_local)?;
    let transforms = target_transforms
        .try_iter()?
        .map(|transform| pose_of(&transform?))
        .collect::<PyResult<Vec<_>>>()?;
    if transforms.is_empty() || local.is_empty() || local.len() % transforms.len() != 0 {
        return Err(PyValueError::new_err(format!(
            "points_local: {} points cannot be split among {} targets",
            local.len(),
            transforms.len()
        )));
    }
    let per_target = local.len() / transforms.len();
    Ok(local
        .chunks(per_target)
        .zip(&transforms)
        .flat_map(|(points, pose)| carry(pose, points))
        .collect())
}

/// search_frame(search, side_motion, framing, scene, torus, particle, side, side_key, points_local,
/// target_transforms, rng, amap, samples_local, a_world, b_world, b_is_gaze_point, time_s, dt_s,
/// clock, last_s, stage_ms) -> (theta, phi, cut, strategy, particle, pose, side, side_key,
/// visibility, framing_error): CompiledToricRig's search and VISIBILITY of one frame (module
/// docstring).
///
/// search: the rig's SearchCore; side_motion: a MotionCore of the rig's style, lens and motion
/// settings, whose upright side is set to (`side`, `side_key`, ToricMotion's) before it is
/// chosen and answered after; framing: the FramingCore; scene: the session's Scene, its moving
/// objects where the frame puts them; torus: the frame's (FRAMING's); particle: the search's
/// (theta, phi, velocity_world, shot_start_s, occluded_since_s), answered moved; points_local:
/// the search's sample points (slots, 3), target-major in equal blocks, in the targets' frames
/// (as they were before the maps' update redrew any); target_transforms: the targets'
/// RigidTransforms in target order; rng: the session's numpy Generator; amap: the maps'
/// AnticipationMap in the map modes, None for ray casts; samples_local: VISIBILITY's sample points,
/// each target's (k, 3); a_world, b_world, b_is_gaze_point: FRAMING's; clock: the session's clock
/// (s); last_s: its last reading (the StageClock's); stage_ms: the frame's laps (ms), where
/// "motion" and "visibility" are added. pose: (position_world, rotation_xyzw, vertical_fov_deg).
/// ValueError for points that do not split among the targets, no sample points, or a torus on
/// which no camera can be composed.
#[pyfunction]
#[allow(clippy::too_many_arguments)] // the frame's inputs, one by one, as the separate calls took them
fn search_frame<'py>(
    py: Python<'py>,
    search: PyRef<'py, SearchCore>,
    mut side_motion: PyRefMut<'py, MotionCore>,
    framing: PyRef<'py, FramingCore>,
    scene: PyRef<'py, PyScene>,
    torus: PyRef<'py, PyTorus>,
    particle: ParticleIn<'py>,
    side: f64,
    side_key: Option<f64>,
    points_local: &Bound<'py, PyAny>,
    target_transforms: &Bound<'py, PyAny>,
    rng: &Bound<'py, PyAny>,
    amap: Option<&Bound<'py, PyAny>>,
    samples_local: &Bound<'py, PyAny>,
    a_world: &Bound<'py, PyAny>,
    b_world: &Bound<'py, PyAny>,
    b_is_gaze_point: bool,
    time_s: f64,
    dt_s: f64,
    clock: &Bound<'py, PyAny>,
    last_s: f64,
    stage_ms: &Bound<'py, PyDict>,
) -> PyResult<Searched<'py>> {
    let mut laps = Laps {
        clock,
        stage_ms,
        last_s,
    };
    // MOTION: the points, the upright half for cuts (ToricRig._move), the step and its pose
    let points = carried_points(points_local, target_transforms)?;
    let torus = &torus.inner;
    let motion = &mut side_motion.inner;
    (motion.side, motion.side_key) = (side, side_key);
    let upright = 1f64.copysign(motion.preferred_place(torus)?[1]);
    let mut particle = SearchCore::particle_of(particle)?;
    let (step, (position, rotation)) = search.answer(
        torus,
        &mut particle,
        (dt_s, time_s, upright),
        &scene.scene,
        &points,
        rng,
        amap,
        b_is_gaze_point,
        None,
    )?;
    laps.done(intern!(py, "motion"))?;
    // VISIBILITY, from the frame's pose
    let visibility = scene.carried_share(py, &position, samples_local, target_transforms)?;
    let framing_error = framing.inner.error(
        &position,
        &rotation,
        &floats(a_world, "a_world")?,
        &floats(b_world, "b_world")?,
        b_is_gaze_point,
    );
    laps.done(intern!(py, "visibility"))?;
    Ok((
        step.theta,
        step.phi,
        step.cut,
        step.strategy.name(),
        SearchCore::py_particle(py, &particle),
        py_pose(py, &(position, rotation), search.fov_deg),
        motion.side,
        motion.side_key,
        visibility,
        framing_error,
    ))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(search_frame, m)?)
}
