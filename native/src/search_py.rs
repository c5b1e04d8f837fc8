//! camdirector._native.SearchCore: the search of the map and ray-cast modes (search.rs) for
//! Python, standing in for pipeline/toric/occlusion_search.py's `OcclusionSearch.step` and the
//! pose ToricRig places at its answer (camera_motion.pose_on_torus).
//!
//! What crosses: `settings` as occlusion_search.SearchSettings (or any object with its fields),
//! `style` as style.Style (screen_a, screen_b, max_speed_m_s, max_accel_m_s2), `lens` as in
//! stages_py.rs; the torus as _native's Torus or geometry.toric's; the particle as a tuple of
//! OcclusionSearch's fields, which the caller keeps; the risk field as an AnticipationMap
//! (its `a_map` and `window`, read as OcclusionMaps.risk reads them) or None for ray casts; the
//! ray casts through a _native.Scene; random numbers from the session's numpy Generator itself
//! (its bit generator's `next_double`, behind its lock), so a step draws what the Python step
//! draws, in the same order, and leaves the generator where the Python leaves it.

use std::borrow::Cow;
use std::ffi::c_void;
use std::ptr::NonNull;

use numpy::{PyArray1, PyArray2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyCapsule, PyList, PyTuple};

use crate::amap::{AMap, Window};
use crate::bvh::Stack;
use crate::bvh_py::{rows, SEGMENT_END};
use crate::motion;
use crate::rotation::Vec3;
use crate::scene::Scene;
use crate::scene_py::PyScene;
use crate::search::{
    Frame, Occlusion, Particle, RaycastRisk, Risk, Scored, Search, SearchSettings, Step, Uniform,
};
use crate::stages_py::{attr, lens_and_fov, screen};
use crate::toric::{Lens, Torus};
use crate::toric_py::{floats, vec3, Array1, PyTorus};

/// numpy's bitgen_t (numpy/random/bitgen.h), what a BitGenerator's "BitGenerator" capsule holds.
#[repr(C)]
struct BitGen {
    state: *mut c_void,
    next_uint64: unsafe extern "C" fn(*mut c_void) -> u64,
    next_uint32: unsafe extern "C" fn(*mut c_void) -> u32,
    next_double: unsafe extern "C" fn(*mut c_void) -> f64,
    next_raw: unsafe extern "C" fn(*mut c_void) -> u64,
}

/// The stream of a numpy Generator's bit generator, used while its capsule is held.
struct NumpyStream(NonNull<BitGen>);

impl Uniform for NumpyStream {
    fn next_double(&mut self) -> f64 {
        // SAFETY: the pointer is the capsule's bitgen_t, alive while the caller holds the capsule
        // (with_stream), and its lock is held, as numpy holds it around its own draws.
        unsafe {
            let bitgen = self.0.as_ptr();
            ((*bitgen).next_double)((*bitgen).state)
        }
    }
}

/// Runs `f` on the stream of `rng` (a numpy Generator), its bit generator's lock held.
fn with_stream<R>(
    rng: &Bound<'_, PyAny>,
    f: impl FnOnce(&mut NumpyStream) -> PyResult<R>,
) -> PyResult<R> {
    let bit_generator = rng.getattr("bit_generator")?;
    let capsule = bit_generator.getattr("capsule")?.cast_into::<PyCapsule>()?;
    let pointer = capsule.pointer_checked(Some(c"BitGenerator"))?;
    let lock = bit_generator.getattr("lock")?;
    lock.call_method0("acquire")?;
    let _held = Held(lock); // released however `f` ends
    f(&mut NumpyStream(pointer.cast()))
}

/// A held threading.Lock, released when dropped.
struct Held<'py>(Bound<'py, PyAny>);

impl Drop for Held<'_> {
    fn drop(&mut self) {
        // the GIL is held (the lock's owner is alive): a failed release has nothing to undo
        let _ = self.0.call_method0("release");
    }
}

/// The share of the target sample points hidden from a camera place, by the Scene's segments
/// stopping SEGMENT_END of the way (VisibilityEstimate.occluded_fraction's rule).
struct Sighting<'a> {
    scene: &'a Scene,
    points_world: &'a [Vec3],
    stack: Stack,
}

impl Occlusion for Sighting<'_> {
    fn occluded(&mut self, camera_world: &Vec3) -> f64 {
        let c = camera_world;
        let hidden = self
            .points_world
            .iter()
            .filter(|t| {
                let direction = [t[0] - c[0], t[1] - c[1], t[2] - c[2]];
                self.scene
                    .occluded(c, &direction, SEGMENT_END, &mut self.stack)
            })
            .count();
        hidden as f64 / self.points_world.len() as f64
    }
}

fn search_settings(s: &Bound<'_, PyAny>) -> PyResult<SearchSettings> {
    let count = |name: &str| -> PyResult<usize> { s.getattr(name)?.extract() };
    Ok(SearchSettings {
        samples: count("samples")?,
        chi_deg: attr(s, "chi_deg")?,
        g_per_m: attr(s, "g_per_m")?,
        h: attr(s, "h")?,
        rho_m: attr(s, "rho_m")?,
        look_ahead_frames: count("look_ahead_frames")?,
        damping_per_s: attr(s, "damping_per_s")?,
        cut_samples: count("cut_samples")?,
        min_cut_angle_deg: attr(s, "min_cut_angle_deg")?,
        min_shot_s: attr(s, "min_shot_s")?,
        improvement: attr(s, "improvement")?,
        stuck_occluded: attr(s, "stuck_occluded")?,
        stuck_s: attr(s, "stuck_s")?,
        theta_margin_ratio: attr(s, "theta_margin_ratio")?,
        view_phi_margin_deg: attr(s, "view_phi_margin_deg")?,
    })
}

/// A _native Torus, or geometry.toric's Torus read field by field (no arithmetic: the same bits).
pub(crate) fn torus_of(torus: &Bound<'_, PyAny>) -> PyResult<Torus> {
    if let Ok(native) = torus.cast::<PyTorus>() {
        return Ok(native.get().inner.clone());
    }
    let basis = torus.getattr("basis")?;
    Ok(Torus {
        a_world: floats(&torus.getattr("a_world")?, "torus.a_world")?,
        b_world: floats(&torus.getattr("b_world")?, "torus.b_world")?,
        alpha: attr(torus, "alpha")?,
        basis: [0, 1, 2]
            .map(|i| {
                basis
                    .get_item(i)
                    .and_then(|row| floats(&row, "torus.basis"))
            })
            .into_iter()
            .collect::<PyResult<Vec<_>>>()?
            .try_into()
            .expect("three rows"),
        length_ab_m: attr(torus, "length_ab_m")?,
        arc_radius_m: attr(torus, "arc_radius_m")?,
        mid_world: floats(&torus.getattr("mid_world")?, "torus.mid_world")?,
        center_offset_m: attr(torus, "center_offset_m")?,
    })
}

/// A MapWindow's fields.
pub(crate) fn window_of(window: &Bound<'_, PyAny>) -> PyResult<Window> {
    Ok(Window {
        theta_min_rad: attr(window, "theta_min_rad")?,
        phi_min_rad: attr(window, "phi_min_rad")?,
        theta_step_rad: attr(window, "theta_step_rad")?,
        phi_step_rad: attr(window, "phi_step_rad")?,
        resolution: window.getattr("resolution")?.extract()?,
    })
}

/// An AnticipationMap's masked A-map (a_map (res, res) float32, window a MapWindow), or None
/// before its first update; read with `outside` 1 (OcclusionMaps.risk).
fn amap_view<'py>(
    amap: &Bound<'py, PyAny>,
) -> PyResult<Option<(PyReadonlyArray2<'py, f32>, Window)>> {
    let (a_map, window) = (amap.getattr("a_map")?, amap.getattr("window")?);
    if a_map.is_none() || window.is_none() {
        return Ok(None);
    }
    let a_map: PyReadonlyArray2<'py, f32> = a_map.extract()?;
    let window = window_of(&window)?;
    let n = window.resolution;
    if a_map.shape() != [n, n] {
        return Err(PyValueError::new_err(format!(
            "a_map must be ({n}, {n}), got {:?}",
            a_map.shape()
        )));
    }
    Ok(Some((a_map, window)))
}

/// An array's values in row order, borrowed when it is C-contiguous (an A-map is).
pub(crate) fn contiguous<'a>(array: &'a PyReadonlyArray2<'_, f32>) -> Cow<'a, [f32]> {
    match array.as_slice() {
        Ok(values) => Cow::Borrowed(values),
        Err(_) => Cow::Owned(array.as_array().iter().copied().collect()),
    }
}

/// The particle: (theta, phi, velocity_world (3,), shot_start_s, occluded_since_s or None).
pub(crate) type PyParticle<'py> = (f64, f64, Array1<'py>, f64, Option<f64>);

/// A particle as a caller hands it in: PyParticle with the velocity as any (3,) sequence.
pub(crate) type ParticleIn<'py> = (f64, f64, Bound<'py, PyAny>, f64, Option<f64>);

/// What SearchCore.step answers: (theta, phi, cut, strategy, risk, particle, pose, trace).
type Stepped<'py> = (
    f64,
    f64,
    bool,
    &'static str,
    f64,
    PyParticle<'py>,
    (Array1<'py>, Array1<'py>, f64),
    Option<Bound<'py, PyList>>,
);

fn trace_list<'py>(py: Python<'py>, trace: &[Scored]) -> PyResult<Bound<'py, PyList>> {
    let items = trace
        .iter()
        .map(|scored| -> PyResult<Bound<'py, PyTuple>> {
            match scored {
                Scored::Risk { theta, phi, value } => PyTuple::new(
                    py,
                    [
                        "risk".into_pyobject(py)?.into_any(),
                        PyArray1::from_slice(py, theta).into_any(),
                        PyArray1::from_slice(py, phi).into_any(),
                        PyArray1::from_slice(py, value).into_any(),
                    ],
                ),
                Scored::Occluded {
                    cameras_world,
                    value,
                } => PyTuple::new(
                    py,
                    [
                        "occluded".into_pyobject(py)?.into_any(),
                        PyArray2::from_vec2(
                            py,
                            &cameras_world.iter().map(|c| c.to_vec()).collect::<Vec<_>>(),
                        )
                        .map_err(|e| PyValueError::new_err(e.to_string()))?
                        .into_any(),
                        PyArray1::from_slice(py, value).into_any(),
                    ],
                ),
            }
        })
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, items)
}

/// SearchCore(settings, style, lens): OcclusionSearch.step compiled, with the pose at its answer.
/// Holds the settings and what it reads of the style and the lens; the particle is the caller's.
#[pyclass(name = "SearchCore", module = "camdirector._native")]
pub struct SearchCore {
    search: Search,
    screen_a: [f64; 2],
    screen_b: [f64; 2],
    max_speed_m_s: f64,
    max_accel_m_s2: f64,
    lens: Lens,
    pub(crate) fov_deg: f64,
}

impl SearchCore {
    /// One frame of the search from `particle` (moved), and pose_on_torus's pose at its answer
    /// (position_world, rotation_xyzw): `step`'s work, for it and for search_frame
    /// (search_frame_py.rs). `frame`: (dt_s, time_s, side); the rest as `step` takes them.
    #[allow(clippy::too_many_arguments)] // step's inputs, read from Python by its callers
    pub(crate) fn answer(
        &self,
        torus: &Torus,
        particle: &mut Particle,
        (dt_s, time_s, side): (f64, f64, f64),
        scene: &Scene,
        points: &[Vec3],
        rng: &Bound<'_, PyAny>,
        amap: Option<&Bound<'_, PyAny>>,
        level: bool,
        record: Option<&mut Vec<Scored>>,
    ) -> PyResult<(Step, motion::Pose)> {
        if points.is_empty() {
            return Err(PyValueError::new_err("points_world is empty"));
        }
        let frame = Frame {
            dt_s,
            time_s,
            side,
            max_speed_m_s: self.max_speed_m_s,
            max_accel_m_s2: self.max_accel_m_s2,
        };
        let view = amap.map(amap_view).transpose()?.flatten();
        let mut sighting = Sighting {
            scene,
            points_world: points,
            stack: Stack::with_capacity(64),
        };
        let step = with_stream(rng, |stream| {
            Ok(match (&view, amap) {
                (_, None) => {
                    // the risk's ray casts and the cut's share one Scene and point set
                    let mut casts = Sighting {
                        scene,
                        points_world: points,
                        stack: Stack::with_capacity(64),
                    };
                    let mut risk = RaycastRisk(&mut casts);
                    self.search.step(
                        particle,
                        torus,
                        &frame,
                        &mut risk,
                        &mut sighting,
                        stream,
                        record,
                    )
                }
                (view, Some(_)) => {
                    let values = view.as_ref().map(|(a, w)| (contiguous(a), *w));
                    let mut risk = AMap {
                        map: values.as_ref().map(|(a, w)| (a.as_ref(), *w)),
                        outside: 1.0,
                    };
                    self.search.step(
                        particle,
                        torus,
                        &frame,
                        &mut risk as &mut dyn Risk,
                        &mut sighting,
                        stream,
                        record,
                    )
                }
            })
        })?;
        let pose = motion::pose_on_torus(
            torus,
            step.theta,
            step.phi,
            &self.screen_a,
            &self.screen_b,
            &self.lens,
            level,
        )?;
        Ok((step, pose))
    }

    /// The particle the Python search keeps (py_particle's tuple), read.
    pub(crate) fn particle_of(particle: ParticleIn<'_>) -> PyResult<Particle> {
        let (theta, phi, velocity, shot_start_s, occluded_since_s) = particle;
        Ok(Particle {
            theta,
            phi,
            velocity_world: floats(&velocity, "velocity_world")?,
            shot_start_s,
            occluded_since_s,
        })
    }

    /// The particle as the Python search keeps it: (theta, phi, velocity_world, shot_start_s, occluded_since_s).
    pub(crate) fn py_particle<'py>(py: Python<'py>, particle: &Particle) -> PyParticle<'py> {
        (
            particle.theta,
            particle.phi,
            vec3(py, &particle.velocity_world),
            particle.shot_start_s,
            particle.occluded_since_s,
        )
    }

    fn read_style(&mut self, style: &Bound<'_, PyAny>) -> PyResult<()> {
        self.screen_a = screen(style, "screen_a")?;
        self.screen_b = screen(style, "screen_b")?;
        self.max_speed_m_s = attr(style, "max_speed_m_s")?;
        self.max_accel_m_s2 = attr(style, "max_accel_m_s2")?;
        Ok(())
    }
}

#[pymethods]
impl SearchCore {
    #[new]
    fn new(
        settings: &Bound<'_, PyAny>,
        style: &Bound<'_, PyAny>,
        lens: &Bound<'_, PyAny>,
    ) -> PyResult<SearchCore> {
        let (lens, fov_deg) = lens_and_fov(lens)?;
        let mut core = SearchCore {
            search: Search {
                settings: search_settings(settings)?,
            },
            screen_a: [0.0; 2],
            screen_b: [0.0; 2],
            max_speed_m_s: 0.0,
            max_accel_m_s2: 0.0,
            lens,
            fov_deg,
        };
        core.read_style(style)?;
        Ok(core)
    }

    /// From the next step on: the composition and the speed and acceleration limits of `style`.
    fn set_style(&mut self, style: &Bound<'_, PyAny>) -> PyResult<()> {
        self.read_style(style)
    }

    /// step(torus, particle, dt_s, time_s, side, scene, points_world, rng, amap=None,
    /// level=False, trace=False) -> (theta, phi, cut, strategy, risk, particle, pose, trace)
    ///
    /// One frame of the search (OcclusionSearch.step): `particle` (theta, phi, velocity_world,
    /// shot_start_s, occluded_since_s) where the last step left it, answered moved; the risk
    /// field `amap`'s A-map (an AnticipationMap; places off its window, or all before its first
    /// update, read 1), or ray casts when None (RaycastRisk); the cut search's ray casts from
    /// `scene` to `points_world` (k, 3) metres; `side` +1 or -1, the upright half; random numbers
    /// drawn from `rng`, a numpy Generator, as the Python draws them. `pose` (position_world,
    /// rotation_xyzw, vertical_fov_deg) is pose_on_torus's at the answer (`level`: B is a gaze
    /// point). With `trace`, the queries made, in order: ("risk", theta (n,), phi (n,), risk
    /// (n,), inf where not asked) and ("occluded", cameras_world (n, 3), share (n,)); else None.
    #[pyo3(signature = (torus, particle, dt_s, time_s, side, scene, points_world, rng, amap = None, level = false, trace = false))]
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &self,
        py: Python<'py>,
        torus: &Bound<'py, PyAny>,
        particle: ParticleIn<'py>,
        dt_s: f64,
        time_s: f64,
        side: f64,
        scene: PyRef<'py, PyScene>,
        points_world: PyReadonlyArray2<'py, f64>,
        rng: &Bound<'py, PyAny>,
        amap: Option<&Bound<'py, PyAny>>,
        level: bool,
        trace: bool,
    ) -> PyResult<Stepped<'py>> {
        let torus = torus_of(torus)?;
        let points = rows("points_world", points_world.as_array())?;
        let mut particle = SearchCore::particle_of(particle)?;
        let mut scored = Vec::new();
        let (step, (position, rotation)) = self.answer(
            &torus,
            &mut particle,
            (dt_s, time_s, side),
            &scene.scene,
            &points,
            rng,
            amap,
            level,
            trace.then_some(&mut scored),
        )?;
        Ok((
            step.theta,
            step.phi,
            step.cut,
            step.strategy.name(),
            step.risk,
            SearchCore::py_particle(py, &particle),
            (
                vec3(py, &position),
                PyArray1::from_slice(py, &rotation),
                self.fov_deg,
            ),
            trace.then(|| trace_list(py, &scored)).transpose()?,
        ))
    }
}

/// Adds SearchCore.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<SearchCore>()
}
