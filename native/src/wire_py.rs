//! camdirector._native's frame wire (wire.rs) for worker/codec.py's compiled frame path:
//! `decode_frame`, the core of `codec.frame_from_wire` (a frame's bytes read and checked as
//! `frame_from_msg` checks the parsed message), and `CameraUpdateWire`, the reply
//! `codec.camera_update_wire` makes (the bytes of `camera_update_msg(state, ...)`).
//!
//! What crosses: the request's bytes; the session's ids as any containers of str (Python sets);
//! a frame's states as a list of ids and one (n, 10) float64 array of rows px, py, pz, qx, qy,
//! qz, qw, sx, sy, sz; a refused frame as FrameRefused(status, message); the reply's state as
//! pipeline/state.py's FrameState (or any object with its fields).

use std::cell::RefCell;

use numpy::ndarray::{s, Array2};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyString};

use crate::toric_py::c_order_values;
use crate::wire::{self, Known, Status, STRIDE};

pyo3::create_exception!(
    camdirector._native,
    FrameRefused,
    PyValueError,
    "A frame the codec refuses: args (status, message), status the name of the gRPC status code \
     (INVALID_ARGUMENT, NOT_FOUND or FAILED_PRECONDITION) and message codec.frame_from_msg's."
);

/// The frame's ids as Python strings and what the session knows of them (wire::Objects).
struct SessionIds<'a, 'py> {
    names: Vec<Bound<'py, PyString>>,
    movable: &'a Bound<'py, PyAny>,
    static_ids: &'a Bound<'py, PyAny>,
    error: RefCell<Option<PyErr>>, // a failed lookup, raised once the checks are done
}

impl SessionIds<'_, '_> {
    fn holds(&self, ids: &Bound<'_, PyAny>, index: usize) -> bool {
        ids.contains(&self.names[index]).unwrap_or_else(|e| {
            self.error.borrow_mut().get_or_insert(e);
            false
        })
    }
}

impl wire::Objects for SessionIds<'_, '_> {
    fn known(&self, index: usize) -> Known {
        if self.holds(self.movable, index) {
            Known::Movable
        } else if self.holds(self.static_ids, index) {
            Known::Static
        } else {
            Known::Unknown
        }
    }

    fn quoted(&self, index: usize) -> String {
        match self.names[index].repr() {
            Ok(repr) => repr.to_string_lossy().into_owned(),
            Err(e) => {
                self.error.borrow_mut().get_or_insert(e);
                String::new()
            }
        }
    }
}

/// A frame's (session_id, frame, time_s, ids, rows, states): `rows` (n, 10) float64 for the n
/// `ids` (the states' in order, then the packed ones), rotations normalised; `states` a list of
/// (id, transform(position (3,), rotation_xyzw (4,), scale (3,))) in the same order, the arrays
/// views of `rows`.
type Decoded<'py> = (
    String,
    u64,
    f64,
    Bound<'py, PyList>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyList>,
);

/// decode_frame(payload, movable, static_ids, transform) -> (session_id, frame, time_s, ids,
/// rows, states) | None: a FrameUpdate's bytes checked as codec.frame_from_msg checks it, in its
/// order and with its messages (FrameRefused otherwise); None for a frame with game events or
/// player stats, which the Python codec reads (wire.rs). `movable`: the ids of targets and
/// dynamic objects; `static_ids`: those of static objects; `transform`: what each row is made
/// into (RigidTransform), called with three views of `rows`, the row's columns 0:3, 3:7 and
/// 7:10, as `map(transform, rows[:, 0:3], rows[:, 3:7], rows[:, 7:10])` makes them: made here,
/// the views cost no numpy indexing and the list no Python loop.
#[pyfunction]
fn decode_frame<'py>(
    py: Python<'py>,
    payload: &[u8],
    movable: &Bound<'py, PyAny>,
    static_ids: &Bound<'py, PyAny>,
    transform: &Bound<'py, PyAny>,
) -> PyResult<Option<Decoded<'py>>> {
    let Some(msg) = wire::FrameUpdate::parse(payload) else {
        return Ok(None);
    };
    let ids = msg
        .states
        .iter()
        .map(|s| s.id)
        .chain(msg.packed_ids.iter().copied());
    let objects = SessionIds {
        names: ids.map(|id| PyString::new(py, id)).collect(),
        movable,
        static_ids,
        error: RefCell::new(None),
    };
    let checked = wire::checked_rows(&msg, &objects);
    if let Some(e) = objects.error.take() {
        return Err(e);
    }
    let rows = checked.map_err(|refusal| {
        let status = match refusal.status {
            Status::InvalidArgument => "INVALID_ARGUMENT",
            Status::NotFound => "NOT_FOUND",
            Status::FailedPrecondition => "FAILED_PRECONDITION",
        };
        FrameRefused::new_err((status, refusal.message))
    })?;
    let names = &objects.names;
    let flat: Vec<f64> = rows.into_iter().flatten().collect();
    let rows = Array2::from_shape_vec((names.len(), STRIDE), flat).expect("STRIDE values a row");
    let rows = PyArray2::from_owned_array(py, rows);
    // SAFETY: only the new array's data pointer and strides are read through this view (where
    // each row's views start), never its values.
    let values = unsafe { rows.as_array() };
    let view = |k: usize, columns: std::ops::Range<usize>| {
        // SAFETY: a view of `rows`, its base: the array's memory never moves (it owns it, and
        // nothing resizes it) and lives as long as the view keeps `rows` alive.
        unsafe {
            PyArray1::borrow_from_array(&values.slice(s![k, columns]), rows.clone().into_any())
        }
    };
    let states = names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            Ok((
                name.clone(),
                transform.call1((view(k, 0..3), view(k, 3..7), view(k, 7..STRIDE)))?,
            ))
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok(Some((
        msg.session_id.to_string(),
        msg.frame,
        msg.time_s,
        PyList::new(py, names)?,
        rows,
        PyList::new(py, states)?,
    )))
}

/// N floats from a float64 array (read at once) or a sequence of N numbers.
fn floats<const N: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; N]> {
    if let Ok(array) = obj.cast::<PyArray1<f64>>() {
        let values = match c_order_values(array.to_dyn()) {
            Some(values) => values,
            None => array.try_readonly()?.as_array().to_vec(),
        };
        if values.len() == N {
            return Ok(std::array::from_fn(|k| values[k]));
        }
        return Err(PyValueError::new_err(format!(
            "{name} must have {N} values, got {}",
            values.len()
        )));
    }
    obj.extract()
}

/// A dict of str -> float as (key, value) pairs.
fn entries(obj: &Bound<'_, PyAny>) -> PyResult<Vec<(String, f64)>> {
    let dict = obj.cast::<PyDict>()?;
    dict.iter()
        .map(|(k, v)| Ok((k.extract()?, v.extract()?)))
        .collect()
}

fn pose_of(pose: &Bound<'_, PyAny>) -> PyResult<wire::Pose> {
    let py = pose.py();
    Ok(wire::Pose {
        position_world: floats(
            &pose.getattr(intern!(py, "position_world"))?,
            "pose.position_world",
        )?,
        rotation_xyzw: floats(
            &pose.getattr(intern!(py, "rotation_xyzw"))?,
            "pose.rotation_xyzw",
        )?,
        vertical_fov_deg: pose.getattr(intern!(py, "vertical_fov_deg"))?.extract()?,
    })
}

fn diagnostics_of(state: &Bound<'_, PyAny>) -> PyResult<wire::Diagnostics> {
    let py = state.py();
    let toric = state.getattr(intern!(py, "toric"))?;
    let toric = if toric.is_none() {
        None
    } else {
        let torus = toric.getattr(intern!(py, "torus"))?;
        let alpha = if torus.is_none() {
            None
        } else {
            Some(torus.getattr(intern!(py, "alpha"))?.extract()?)
        };
        Some((
            toric.getattr(intern!(py, "theta"))?.extract()?,
            toric.getattr(intern!(py, "phi"))?.extract()?,
            alpha,
        ))
    };
    Ok(wire::Diagnostics {
        toric,
        stage_ms: entries(&state.getattr(intern!(py, "stage_ms"))?)?,
        flags: state.getattr(intern!(py, "flags"))?.extract()?,
        scores: entries(&state.getattr(intern!(py, "scores"))?)?,
    })
}

/// CameraUpdateWire(state): the reply to a computed frame without a MATCH part, as
/// codec.camera_update_msg(state, compute_ms) makes it, with its map entries in the order of
/// their keys (upb's changes from one process to the next). What the session table reads and
/// sets of a reply: `compute_ms` (set once the frame is done), `stale` (False: a computed
/// frame), SerializeToString().
#[pyclass(name = "CameraUpdateWire", module = "camdirector._native")]
pub struct PyCameraUpdateWire {
    head: Vec<u8>,
    tail: Vec<u8>,
    #[pyo3(get, set)]
    compute_ms: f64,
}

#[pymethods]
impl PyCameraUpdateWire {
    #[new]
    fn new(state: &Bound<'_, PyAny>) -> PyResult<Self> {
        let py = state.py(); // attribute names interned: no string made and hashed per frame
        if !state.getattr(intern!(py, "match"))?.is_none() {
            return Err(PyValueError::new_err(
                "a state with a MATCH part is answered by codec.camera_update_msg",
            ));
        }
        let pose = state.getattr(intern!(py, "pose"))?;
        let reply = wire::CameraUpdate {
            frame: state.getattr(intern!(py, "frame"))?.extract()?,
            time_s: state.getattr(intern!(py, "time_s"))?.extract()?,
            pose: if pose.is_none() {
                None
            } else {
                Some(pose_of(&pose)?)
            },
            cut: state.getattr(intern!(py, "cut"))?.extract()?,
            shot_id: u64::from(state.getattr(intern!(py, "shot_id"))?.extract::<u32>()?),
            visibility: state.getattr(intern!(py, "visibility"))?.extract()?,
            diagnostics: diagnostics_of(state)?,
        };
        let (head, tail) = reply.pieces();
        Ok(PyCameraUpdateWire {
            head,
            tail,
            compute_ms: 0.0,
        })
    }

    #[getter]
    fn stale(&self) -> bool {
        false
    }

    #[pyo3(name = "SerializeToString")]
    fn serialize_to_string<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(
            py,
            &wire::reply_bytes(&self.head, self.compute_ms, &self.tail),
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(decode_frame, m)?)?;
    m.add_class::<PyCameraUpdateWire>()?;
    m.add("FrameRefused", m.py().get_type::<FrameRefused>())?;
    Ok(())
}
