//! camdirector._native.Scene: the compiled twin of geometry/raycast.py's RayScene (scene.rs), with
//! its constructor, add_dynamic, set_transform, occluded and first_hit, and the TORIC VISIBILITY
//! stage's query as one call (visible_share). Arrays are copied in with the GIL held, then every
//! ray is cast with it released.

use numpy::ndarray::{ArrayView2, Axis};
use numpy::{
    PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyKeyError, PyValueError};
use pyo3::prelude::*;

use crate::bvh::Stack;
use crate::bvh_py::{faces_of, rows, SEGMENT_END};
use crate::carry::carry;
use crate::scene::{Pose, Scene};
use crate::toric_py::{c_order_values, floats};

type Mesh = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// A TriMesh (anything with `vertices` (n, 3) float64 and `faces` (m, 3) int32 or int64), or a
/// (vertices, faces) pair.
fn mesh_of(mesh: &Bound<'_, PyAny>) -> PyResult<Mesh> {
    let (vertices, faces) = match mesh.getattr("vertices") {
        Ok(vertices) => (vertices, mesh.getattr("faces")?),
        Err(_) => mesh.extract::<(Bound<'_, PyAny>, Bound<'_, PyAny>)>()?,
    };
    let vertices = rows(
        "vertices",
        vertices.extract::<PyReadonlyArray2<'_, f64>>()?.as_array(),
    )?;
    let faces = faces_of(&faces, vertices.len())?;
    Ok((vertices, faces))
}

/// A RigidTransform's fields (position_world (3,), rotation_xyzw (4,), scale (3,)), finite.
pub(crate) fn pose_of(transform: &Bound<'_, PyAny>) -> PyResult<Pose> {
    let field = |name: &str, n: usize| -> PyResult<Vec<f64>> {
        let value = transform.getattr(name)?;
        // a float64 ndarray (a RigidTransform's) read at once, not element by element as a sequence
        let values: Vec<f64> = match value.cast::<PyArrayDyn<f64>>() {
            Ok(array) if array.ndim() == 1 => match c_order_values(array) {
                Some(values) => values,
                None => array.try_readonly()?.as_array().iter().copied().collect(),
            },
            _ => value.extract()?,
        };
        if values.len() != n || values.iter().any(|x| !x.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "transform.{name} must be {n} finite numbers, got {values:?}"
            )));
        }
        Ok(values)
    };
    let (p, q, s) = (
        field("position_world", 3)?,
        field("rotation_xyzw", 4)?,
        field("scale", 3)?,
    );
    if s.contains(&0.0) {
        return Err(PyValueError::new_err(format!(
            "transform.scale has a zero: {s:?}"
        )));
    }
    Ok(Pose {
        position: [p[0], p[1], p[2]],
        rotation_xyzw: [q[0], q[1], q[2], q[3]],
        scale: [s[0], s[1], s[2]],
    })
}

/// Points (n, 3) float64, or one point (3,) as a row (then `true`).
pub(crate) fn points_of(name: &str, points: &Bound<'_, PyAny>) -> PyResult<(Vec<[f64; 3]>, bool)> {
    if let Ok(array) = points.cast::<PyArrayDyn<f64>>() {
        let shape = array.shape().to_vec();
        if let (1 | 2, Some(values)) = (shape.len(), c_order_values(array)) {
            let (n, k) = match shape[..] {
                [k] => (1, k), // one point, as a row
                [n, k] => (n, k),
                _ => unreachable!("one or two dimensions"),
            };
            let view = ArrayView2::from_shape((n, k), &values).expect("its own shape");
            return Ok((rows(name, view)?, shape.len() == 1));
        }
    }
    if let Ok(one) = points.extract::<PyReadonlyArray1<'_, f64>>() {
        return Ok((rows(name, one.as_array().insert_axis(Axis(0)))?, true));
    }
    Ok((
        rows(
            name,
            points.extract::<PyReadonlyArray2<'_, f64>>()?.as_array(),
        )?,
        false,
    ))
}

/// Static meshes in the world frame, one BVH built once, plus moving rigid objects each in its
/// local frame with a RigidTransform, as RayScene (native/src/scene.rs says how): the same
/// answers as RayScene's up to Embree's float32 rounding, the same bits on every x86-64 machine.
/// Built from a list of TriMeshes or (vertices (n, 3) float64, faces (m, 3) int) pairs.
#[pyclass(name = "Scene", module = "camdirector._native")]
pub struct PyScene {
    pub(crate) scene: Scene,
}

impl PyScene {
    /// The share of the targets' sample points seen from camera (3,) metres, the TORIC
    /// VISIBILITY stage's estimate: each target's points_local (k, 3) carried by its
    /// RigidTransform as `carry` carries them (pairs taken as zip takes them), all of them in
    /// target order as one (n, 3), then `visible_share`'s count. ValueError for no points.
    pub(crate) fn carried_share(
        &self,
        py: Python<'_>,
        camera: &[f64; 3],
        samples_local: &Bound<'_, PyAny>,
        target_transforms: &Bound<'_, PyAny>,
    ) -> PyResult<f64> {
        let camera = rows(
            "camera_world",
            ArrayView2::from_shape((1, 3), camera).expect("one row of 3"),
        )?;
        let mut points = Vec::new();
        for (local, transform) in samples_local.try_iter()?.zip(target_transforms.try_iter()?) {
            let (local, _) = points_of("points_local", &local?)?;
            points.extend(carry(&pose_of(&transform?)?, &local));
        }
        self.share_seen(py, &camera, &points)
    }

    /// 1 - the share of points hidden from camera (one row), as visible_share answers it.
    fn share_seen(
        &self,
        py: Python<'_>,
        camera: &[[f64; 3]],
        points: &[[f64; 3]],
    ) -> PyResult<f64> {
        if points.is_empty() {
            return Err(PyValueError::new_err(
                "points_world is empty: no share to take",
            ));
        }
        let hidden = self
            .segments_occluded(py, camera, points)
            .iter()
            .filter(|&&h| h)
            .count();
        Ok(1.0 - hidden as f64 / points.len() as f64)
    }

    /// (n,) whether each segment origin -> target meets geometry (RayScene.occluded's rule).
    fn segments_occluded(
        &self,
        py: Python<'_>,
        origins: &[[f64; 3]],
        targets: &[[f64; 3]],
    ) -> Vec<bool> {
        py.detach(|| {
            let mut stack = Stack::with_capacity(64);
            let origin = |k: usize| &origins[if origins.len() == 1 { 0 } else { k }];
            (0..targets.len())
                .map(|k| {
                    let (o, t) = (origin(k), &targets[k]);
                    let direction = [t[0] - o[0], t[1] - o[1], t[2] - o[2]];
                    self.scene.occluded(o, &direction, SEGMENT_END, &mut stack)
                })
                .collect()
        })
    }
}

#[pymethods]
impl PyScene {
    #[new]
    fn new(py: Python<'_>, static_meshes_world: Vec<Bound<'_, PyAny>>) -> PyResult<Self> {
        let meshes = static_meshes_world
            .iter()
            .map(mesh_of)
            .collect::<PyResult<Vec<_>>>()?;
        let scene = py.detach(|| Scene::new(&meshes));
        Ok(PyScene { scene })
    }

    /// RayScene.occluded's segment end (a share of origin -> target).
    #[classattr]
    const SEGMENT_END: f64 = SEGMENT_END;

    /// Adds a moving object: mesh_local a TriMesh (or (vertices, faces)) in its local frame,
    /// transform a RigidTransform. ValueError if object_id is taken.
    fn add_dynamic(
        &mut self,
        py: Python<'_>,
        object_id: &str,
        mesh_local: &Bound<'_, PyAny>,
        transform: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let (vertices, faces) = mesh_of(mesh_local)?;
        let pose = pose_of(transform)?;
        py.detach(|| self.scene.add_dynamic(object_id, &vertices, &faces, &pose))
            .map_err(PyValueError::new_err)
    }

    /// Moves an object to a RigidTransform. KeyError if no object has that id.
    fn set_transform(&mut self, object_id: &str, transform: &Bound<'_, PyAny>) -> PyResult<()> {
        let pose = pose_of(transform)?;
        self.scene
            .set_transform(object_id, &pose)
            .map_err(PyKeyError::new_err)
    }

    /// (n,) bool: whether the segment from each origin to its target crosses any geometry,
    /// stopping SEGMENT_END of the way (origins_world (n, 3) or (3,), targets_world (n, 3) or (3,)
    /// float64 metres).
    fn occluded<'py>(
        &self,
        py: Python<'py>,
        origins_world: &Bound<'py, PyAny>,
        targets_world: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (origins, one) = points_of("origins_world", origins_world)?;
        let (targets, _) = points_of("targets_world", targets_world)?;
        if !one && origins.len() != targets.len() {
            return Err(PyValueError::new_err(format!(
                "{} origins and {} targets",
                origins.len(),
                targets.len()
            )));
        }
        Ok(PyArray1::from_vec(
            py,
            self.segments_occluded(py, &origins, &targets),
        ))
    }

    /// (n,) float64: the ray parameter t >= 0 of the nearest hit along each ray o + t d, in units
    /// of |d| (origins_world (n, 3) or (3,), directions_world (n, 3) float64); inf where none.
    fn first_hit<'py>(
        &self,
        py: Python<'py>,
        origins_world: &Bound<'py, PyAny>,
        directions_world: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (origins, one) = points_of("origins_world", origins_world)?;
        let (directions, _) = points_of("directions_world", directions_world)?;
        if !one && origins.len() != directions.len() {
            return Err(PyValueError::new_err(format!(
                "{} origins and {} directions",
                origins.len(),
                directions.len()
            )));
        }
        let t: Vec<f64> = py.detach(|| {
            let mut stack = Stack::with_capacity(64);
            let origin = |k: usize| &origins[if one { 0 } else { k }];
            (0..directions.len())
                .map(|k| self.scene.first_hit(origin(k), &directions[k], &mut stack))
                .collect()
        });
        Ok(PyArray1::from_vec(py, t))
    }

    /// The share of points_world (k, 3) seen from camera_world (3,): VisibilityEstimate's
    /// 1 - occluded_fraction for one camera. ValueError for no points.
    fn visible_share(
        &self,
        py: Python<'_>,
        camera_world: PyReadonlyArray1<'_, f64>,
        points_world: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<f64> {
        let camera = rows("camera_world", camera_world.as_array().insert_axis(Axis(0)))?;
        let points = rows("points_world", points_world.as_array())?;
        self.share_seen(py, &camera, &points)
    }

    /// visible_share_of(camera_world (3,), samples_local, target_transforms) -> float: the TORIC
    /// VISIBILITY stage's share in one call (carried_share): each target's sample points
    /// (k, 3) float64 in `samples_local` carried by its RigidTransform in `target_transforms`,
    /// seen from camera_world metres; what `visible_share` answers for those points carried
    /// one `carry` call each and concatenated in target order. ValueError for no points.
    fn visible_share_of(
        &self,
        py: Python<'_>,
        camera_world: &Bound<'_, PyAny>,
        samples_local: &Bound<'_, PyAny>,
        target_transforms: &Bound<'_, PyAny>,
    ) -> PyResult<f64> {
        let camera = floats::<3>(camera_world, "camera_world")?;
        self.carried_share(py, &camera, samples_local, target_transforms)
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()
}
