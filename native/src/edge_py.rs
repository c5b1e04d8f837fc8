//! camdirector._native's edge (edge.rs, zmq_edge.rs) for front/edge.py: `Edge` starts it and is
//! the front's handle on it.
//!
//! What crosses: events as tuples ("auth", token, authorization | None), ("open" | "frame" |
//! "unary", token, session id, tenant, payload bytes), ("closed", session id), ("zmq", token,
//! [frame bytes]); answers as (token, status code, message, body, key id | None, tenant, opened),
//! ZeroMQ's as (token, [reply frame bytes], (key id | None, tenant) | None); drained frames as
//! (elapsed_s, compute_ms, flags, stage names bytes, stage times tuple, via: edge.rs's Via),
//! errors as (status code, via), sessions as (id, frames, bit 1 << via of each via); with the
//! front's own table (`set_inline`), a frame as (session id, payload bytes), called on the edge's
//! thread, and its reply as bytes in a worker's framing, or None.

use bytes::Bytes;
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};

use crate::edge::{self, Answer, Bucket, Config, Event, Status};
use crate::zmq_edge;

#[pyclass(name = "Edge", module = "camdirector._native")]
pub struct Edge {
    edge: edge::Edge,
}

#[pymethods]
impl Edge {
    /// Starts the edge's own thread (edge.rs), serving gRPC on `address` when given. `wake_fd`: a Unix socket's
    /// end the edge writes a byte to when events wait (the edge owns it from now on); `tls`: the
    /// certificate chain and key, PEM bytes, for a TLS port.
    #[new]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (address, upstream_path, wake_fd, metadata, max_message_bytes, rate_limit, max_fps, resend_frames, tls=None))]
    fn new(
        py: Python<'_>,
        address: Option<&str>,
        upstream_path: String,
        wake_fd: i32,
        metadata: Vec<(String, String)>,
        max_message_bytes: usize,
        rate_limit: bool,
        max_fps: f64,
        resend_frames: f64,
        tls: Option<(Vec<u8>, Vec<u8>)>,
    ) -> PyResult<Self> {
        let config = Config {
            max_message_bytes,
            metadata,
            rate_limit,
            max_fps,
            resend_frames,
        };
        // SAFETY: Python hands over a socket it has detached (front/edge.py)
        let wake = unsafe { edge::socket_from_fd(wake_fd) };
        let edge = py
            .detach(|| {
                let tls = tls
                    .as_ref()
                    .map(|(cert, key)| (cert.as_slice(), key.as_slice()));
                edge::Edge::start(config, address, upstream_path, wake, tls)
            })
            .map_err(|e| {
                PyOSError::new_err(format!(
                    "cannot serve gRPC on {}: {e}",
                    address.unwrap_or("")
                ))
            })?;
        Ok(Edge { edge })
    }

    /// The bound gRPC port (None: gRPC is not served here).
    #[getter]
    fn port(&self) -> Option<u16> {
        self.edge.address.map(|a| a.port())
    }

    /// Serves the front's ZeroMQ ROUTER socket from now on: pyzmq's `Socket.underlying` at
    /// `address`, through the libzmq loaded from `libzmq_path`, which must be of `version`
    /// (zmq.zmq_version_info()). Python must not touch the socket again until `stop` returns.
    fn serve_zmq(
        &self,
        address: usize,
        libzmq_path: &str,
        version: (i32, i32, i32),
    ) -> PyResult<()> {
        // SAFETY: front/edge.py hands over a live socket it no longer reads or writes, and closes
        // it only after `stop`
        let socket = unsafe { zmq_edge::Socket::adopt(address, libzmq_path, version) }
            .map_err(PyOSError::new_err)?;
        self.edge.serve_zmq(socket);
        Ok(())
    }

    /// The frame socket of the worker in `slot` (a detached file descriptor the edge owns from now on).
    fn set_worker(&self, slot: usize, fd: i32) -> PyResult<()> {
        // SAFETY: Python hands over a socket it has detached (worker_pool.py)
        let socket = unsafe { edge::socket_from_fd(fd) };
        self.edge
            .enter(|| self.edge.shared.set_worker(slot, socket))
            .map_err(|e| PyOSError::new_err(e.to_string()))
    }

    /// The front's own session table holds the sessions of `slot` (`serve --workers 0`): the
    /// edge answers their frames on its own thread through `answer(session_id, payload)`, which
    /// returns the reply in a worker's framing, or None for the front's loop to answer it
    /// (WorkerPool.answer_inline); and, whenever the thread is about to sleep, `idle()` does one
    /// piece of the table's idle work and says whether more waits (WorkerPool.idle_inline).
    fn set_inline(&self, slot: usize, answer: Py<PyAny>, idle: Py<PyAny>) {
        self.edge
            .shared
            .set_inline(slot, Box::new(InlineAnswer { answer, idle }));
    }

    /// Routes the session's frames to the worker in `slot`, with its rate bucket (router._admit_frame):
    /// `tokens` and `resend` frames, last filled `age_s` ago (None: full).
    #[pyo3(signature = (session_id, slot, tenant, tokens, resend, age_s))]
    fn route(
        &self,
        session_id: String,
        slot: usize,
        tenant: String,
        tokens: f64,
        resend: f64,
        age_s: Option<f64>,
    ) {
        let bucket = Bucket {
            tokens,
            resend,
            age_s,
        };
        self.edge.shared.route(session_id, slot, tenant, bucket);
    }

    /// Stops routing the session here; its bucket (tokens, resend) when it was routed.
    fn unroute(&self, session_id: &str) -> Option<(f64, f64)> {
        self.edge.shared.unroute(session_id)
    }

    /// Streams of this key end at their next frame.
    fn revoke(&self, key_id: String) {
        self.edge.shared.revoke(key_id);
    }

    /// The events waiting for the front's answers, oldest first.
    fn take_events<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyTuple>>> {
        self.edge
            .shared
            .take_events()
            .into_iter()
            .map(|event| match event {
                Event::Auth {
                    token,
                    authorization,
                } => ("auth", token, authorization).into_pyobject(py),
                Event::Open {
                    token,
                    session_id,
                    tenant,
                    payload,
                } => (
                    "open",
                    token,
                    session_id,
                    tenant,
                    PyBytes::new(py, &payload),
                )
                    .into_pyobject(py),
                Event::Frame {
                    unary,
                    token,
                    session_id,
                    tenant,
                    payload,
                } => (
                    if unary { "unary" } else { "frame" },
                    token,
                    session_id,
                    tenant,
                    PyBytes::new(py, &payload),
                )
                    .into_pyobject(py),
                Event::Closed { session_id } => ("closed", session_id).into_pyobject(py),
                Event::Zmq { token, parts } => {
                    let parts: Vec<_> = parts.iter().map(|p| PyBytes::new(py, p)).collect();
                    ("zmq", token, parts).into_pyobject(py)
                }
            })
            .collect()
    }

    /// The front's answer to the event of `token`.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (token, status, message, body, key_id, tenant, opened))]
    fn answer(
        &self,
        token: u64,
        status: u8,
        message: String,
        body: &[u8],
        key_id: Option<String>,
        tenant: String,
        opened: bool,
    ) {
        let answer = Answer {
            status: Status {
                code: status,
                message,
            },
            body: Bytes::copy_from_slice(body),
            key_id,
            tenant,
            opened,
            frames: Vec::new(),
            let_in: false,
        };
        self.edge.shared.answer(token, answer);
    }

    /// The front's reply frames to the ZeroMQ request of `token`; `caller`: (key id, tenant) when
    /// the request was a Frame answered, whose caller the edge may then let in itself.
    #[pyo3(signature = (token, frames, caller))]
    fn answer_zmq(
        &self,
        token: u64,
        frames: Vec<Vec<u8>>,
        caller: Option<(Option<String>, String)>,
    ) {
        let let_in = caller.is_some();
        let (key_id, tenant) = caller.unwrap_or_default();
        let answer = Answer {
            status: Status {
                code: edge::OK,
                message: String::new(),
            },
            body: Bytes::new(),
            key_id,
            tenant,
            opened: false,
            frames: frames.into_iter().map(Bytes::from).collect(),
            let_in,
        };
        self.edge.shared.answer(token, answer);
    }

    /// What happened since the last call: (frames, (error code, via) pairs, (session id, frames,
    /// bits 1 << via) triples).
    #[allow(clippy::type_complexity)]
    fn drain<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Vec<(f64, f64, u8, Bound<'py, PyBytes>, Bound<'py, PyTuple>, u8)>,
        Vec<(u8, u8)>,
        Vec<(String, u64, u8)>,
    )> {
        let drained = self.edge.shared.drain();
        let frames = drained
            .frames
            .into_iter()
            .map(|f| {
                Ok((
                    f.elapsed_s,
                    f.compute_ms,
                    f.flags,
                    PyBytes::new(py, &f.names),
                    PyTuple::new(py, f.values)?,
                    f.via as u8,
                ))
            })
            .collect::<PyResult<Vec<_>>>()?;
        Ok((
            frames,
            drained
                .errors
                .into_iter()
                .map(|(code, via)| (code, via as u8))
                .collect(),
            drained
                .sessions
                .into_iter()
                .map(|(id, (frames, bits))| (id, frames, bits))
                .collect(),
        ))
    }

    /// Stops listening and ends every stream (its thread is gone when this returns).
    fn stop(&mut self, py: Python<'_>) {
        py.detach(|| self.edge.stop());
    }
}

/// WorkerPool.answer_inline and WorkerPool.idle_inline, called on the edge's thread with the GIL
/// taken there.
struct InlineAnswer {
    answer: Py<PyAny>,
    idle: Py<PyAny>,
}

impl edge::InlineTable for InlineAnswer {
    fn frame(&self, session_id: &str, payload: &[u8]) -> Result<Option<Bytes>, String> {
        Python::attach(|py| {
            let reply = self
                .answer
                .call1(py, (session_id, PyBytes::new(py, payload)))
                .map_err(|err| format!("the front's table failed: {err}"))?;
            if reply.is_none(py) {
                return Ok(None);
            }
            let bytes = reply
                .cast_bound::<PyBytes>(py)
                .map_err(|err| format!("the front's table answered no bytes: {err}"))?;
            Ok(Some(Bytes::copy_from_slice(bytes.as_bytes())))
        })
    }

    fn idle(&self) -> bool {
        Python::attach(|py| match self.idle.call0(py) {
            Ok(more) => more.is_truthy(py).unwrap_or(false),
            Err(err) => {
                // a bug in idle work must not stop the edge's thread; Python's unraisable hook logs it
                err.write_unraisable(py, None);
                false
            }
        })
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Edge>()?;
    m.add("EDGE_HAS_METRICS", edge::HAS_METRICS)?;
    m.add("EDGE_STREAM_FRAMES", edge::STREAM_FRAMES)?;
    Ok(())
}
