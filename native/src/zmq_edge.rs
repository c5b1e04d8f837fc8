//! The compiled edge's ZeroMQ side (issue 43, step 5; docs/frame_path.md, "ZeroMQ through the
//! edge"): the node's ROUTER socket read and written on the edge's tokio thread (edge.rs), so that
//! a Frame request of a session routed to the edge goes straight to its worker and back with no
//! Python in the front, as gRPC's frames do.
//!
//! The socket is the one front/zmq_service.py made, configured (CURVE, MAXMSGSIZE) and bound: this
//! module only reads and writes it, through the libzmq that pyzmq loaded into this process
//! (opened again with RTLD_NOLOAD and its version checked against pyzmq's). One libzmq in the
//! process: the same CURVE, limits and wire as the Python front's, and no second C++ build.
//!
//! A request is taken here only when the front's Python has already said yes to it: a Frame
//! (docs/protocol.md's envelope, DEALER or REQ), within the message limit, from a caller Python let
//! in (its key frame's SHA-256, as edge.rs remembers gRPC's callers), of a session routed here.
//! Everything else (other RPCs, a first frame, unknown keys, malformed envelopes, a frame of a
//! session that has a frame with Python: Shared::with_python keeps a session's frames in order) goes
//! to Python whole (`Event::Zmq`), and its reply frames are sent back as they come.

use std::ffi::{c_int, c_void, CString};
use std::os::fd::{AsRawFd, RawFd};
use std::sync::Arc;
use std::time::Instant;

use bytes::Bytes;
use tokio::io::unix::AsyncFd;
use tokio::io::Interest;
use tokio::sync::mpsc;

use crate::edge::{Event, Shared, Via};
use crate::wire;

const FRAME_RPC: &[u8] = b"Frame";
const READ_BATCH: usize = 64; // messages read before the thread's other tasks get a turn

// zmq.h's numbers (stable across libzmq 4.x)
const ZMQ_FD: c_int = 14;
const ZMQ_EVENTS: c_int = 15;
const ZMQ_DONTWAIT: c_int = 1;
const ZMQ_SNDMORE: c_int = 2;
const ZMQ_POLLIN: c_int = 1;

/// zmq_msg_t: 64 opaque bytes, pointer-aligned.
#[repr(C, align(8))]
struct ZmqMsg([u8; 64]);

type GetSockOpt = unsafe extern "C" fn(*mut c_void, c_int, *mut c_void, *mut usize) -> c_int;
type MsgInit = unsafe extern "C" fn(*mut ZmqMsg) -> c_int;
type MsgRecv = unsafe extern "C" fn(*mut ZmqMsg, *mut c_void, c_int) -> c_int;
type MsgData = unsafe extern "C" fn(*mut ZmqMsg) -> *mut c_void;
type MsgSize = unsafe extern "C" fn(*const ZmqMsg) -> usize;
type MsgMore = unsafe extern "C" fn(*const ZmqMsg) -> c_int;
type Send = unsafe extern "C" fn(*mut c_void, *const c_void, usize, c_int) -> c_int;
type Errno = unsafe extern "C" fn() -> c_int;
type Version = unsafe extern "C" fn(*mut c_int, *mut c_int, *mut c_int);

/// The libzmq functions this module calls.
struct Api {
    getsockopt: GetSockOpt,
    msg_init: MsgInit,
    msg_recv: MsgRecv,
    msg_data: MsgData,
    msg_size: MsgSize,
    msg_more: MsgMore,
    msg_close: MsgInit,
    send: Send,
    errno: Errno,
}

impl Api {
    /// libzmq's functions from the library at `path`, which must already be loaded (pyzmq's) and
    /// be of `version` (pyzmq's zmq_version_info()).
    fn open(path: &str, version: (i32, i32, i32)) -> Result<Api, String> {
        let name = CString::new(path).map_err(|_| format!("{path:?} is not a library path"))?;
        // SAFETY: RTLD_NOLOAD only returns a library this process has loaded already; it stays
        // loaded (its reference count is raised) for the process's life.
        let library = unsafe { libc::dlopen(name.as_ptr(), libc::RTLD_NOW | libc::RTLD_NOLOAD) };
        if library.is_null() {
            return Err(format!("libzmq at {path} is not loaded in this process"));
        }
        let symbol = |name: &str| -> Result<*mut c_void, String> {
            let c_name = CString::new(name).expect("a symbol name has no NUL");
            // SAFETY: a valid handle and a NUL-terminated name
            let found = unsafe { libc::dlsym(library, c_name.as_ptr()) };
            if found.is_null() {
                Err(format!("{path} has no {name}"))
            } else {
                Ok(found)
            }
        };
        // SAFETY: each symbol is libzmq's function of that name, whose C signature zmq.h gives
        // and the types above repeat.
        unsafe {
            let zmq_version = function::<Version>(symbol("zmq_version")?);
            let (mut major, mut minor, mut patch) = (0, 0, 0);
            zmq_version(&mut major, &mut minor, &mut patch);
            if (major, minor, patch) != version {
                return Err(format!(
                    "{path} is libzmq {major}.{minor}.{patch}, pyzmq's is {}.{}.{}",
                    version.0, version.1, version.2
                ));
            }
            Ok(Api {
                getsockopt: function(symbol("zmq_getsockopt")?),
                msg_init: function(symbol("zmq_msg_init")?),
                msg_recv: function(symbol("zmq_msg_recv")?),
                msg_data: function(symbol("zmq_msg_data")?),
                msg_size: function(symbol("zmq_msg_size")?),
                msg_more: function(symbol("zmq_msg_more")?),
                msg_close: function(symbol("zmq_msg_close")?),
                send: function(symbol("zmq_send")?),
                errno: function(symbol("zmq_errno")?),
            })
        }
    }
}

/// A function pointer of type `F` from a symbol's address.
///
/// # Safety
/// `F` must be the function type of the symbol at `address`.
unsafe fn function<F: Copy>(address: *mut c_void) -> F {
    assert_eq!(std::mem::size_of::<F>(), std::mem::size_of::<*mut c_void>());
    std::mem::transmute_copy(&address)
}

/// The front's ROUTER socket, used from the edge's thread only from its handover on.
pub struct Socket {
    api: Api,
    handle: *mut c_void,
}

// SAFETY: a libzmq socket may move between threads when only one uses it at a time: from the
// handover on only the edge's socket task does (front/zmq_service.py stops reading it), and the
// handover itself crosses a channel (a full memory barrier).
unsafe impl std::marker::Send for Socket {}

impl Socket {
    /// pyzmq's socket at `address` (Socket.underlying), through the libzmq at `path` of `version`.
    ///
    /// # Safety
    /// `address` must be a live libzmq socket of that library that nothing else uses from now on
    /// and that stays open until the edge stops.
    pub unsafe fn adopt(
        address: usize,
        path: &str,
        version: (i32, i32, i32),
    ) -> Result<Socket, String> {
        Ok(Socket {
            api: Api::open(path, version)?,
            handle: address as *mut c_void,
        })
    }

    fn errno(&self) -> c_int {
        // SAFETY: libzmq's zmq_errno takes nothing
        unsafe { (self.api.errno)() }
    }

    fn int_option(&self, option: c_int) -> Result<c_int, c_int> {
        loop {
            let mut value: c_int = 0;
            let mut size = std::mem::size_of::<c_int>();
            // SAFETY: an int option into an int of its size
            let rc = unsafe {
                (self.api.getsockopt)(
                    self.handle,
                    option,
                    (&mut value as *mut c_int).cast(),
                    &mut size,
                )
            };
            if rc == 0 {
                return Ok(value);
            }
            let errno = self.errno();
            if errno != libc::EINTR {
                return Err(errno);
            }
        }
    }

    /// Whether a message waits; asking also clears the descriptor's signal (ZMQ_EVENTS).
    fn waiting(&self) -> Result<bool, c_int> {
        Ok(self.int_option(ZMQ_EVENTS)? & ZMQ_POLLIN != 0)
    }

    /// The next message's frames; None when none waits.
    fn recv(&self) -> Result<Option<Vec<Bytes>>, c_int> {
        let mut parts = Vec::with_capacity(4);
        loop {
            let mut msg = ZmqMsg([0; 64]);
            // SAFETY: an initialised message received into, read, then closed
            let (rc, part, more) = unsafe {
                (self.api.msg_init)(&mut msg);
                let rc = (self.api.msg_recv)(&mut msg, self.handle, ZMQ_DONTWAIT);
                let (part, more) = if rc >= 0 {
                    let data = (self.api.msg_data)(&mut msg) as *const u8;
                    let size = (self.api.msg_size)(&msg);
                    let part = if size == 0 {
                        Bytes::new()
                    } else {
                        Bytes::copy_from_slice(std::slice::from_raw_parts(data, size))
                    };
                    (part, (self.api.msg_more)(&msg) != 0)
                } else {
                    (Bytes::new(), false)
                };
                (self.api.msg_close)(&mut msg);
                (rc, part, more)
            };
            if rc < 0 {
                match self.errno() {
                    libc::EINTR => continue,
                    libc::EAGAIN if parts.is_empty() => return Ok(None),
                    errno => return Err(errno),
                }
            }
            parts.push(part);
            if !more {
                return Ok(Some(parts));
            }
        }
    }

    /// Sends a message's frames without waiting: past the high-water mark, or to a peer gone, the
    /// ROUTER socket drops it, as the Python front's send does.
    fn send(&self, parts: &[Bytes]) {
        for (i, part) in parts.iter().enumerate() {
            let flags = ZMQ_DONTWAIT | if i + 1 < parts.len() { ZMQ_SNDMORE } else { 0 };
            loop {
                // SAFETY: the part's bytes, valid for the call (zmq_send copies them)
                let rc = unsafe {
                    (self.api.send)(self.handle, part.as_ptr().cast(), part.len(), flags)
                };
                if rc >= 0 {
                    break;
                }
                if self.errno() != libc::EINTR {
                    return; // a ROUTER drops a whole message that cannot go: nothing more to send
                }
            }
        }
    }
}

/// libzmq's descriptor of the socket's signals (edge-triggered): registered with tokio, never closed here.
struct SignalFd(RawFd);

impl AsRawFd for SignalFd {
    fn as_raw_fd(&self) -> RawFd {
        self.0
    }
}

/// Reads the socket's requests and writes their replies until the edge stops (its runtime ends
/// this task); each request answered in its own task, in arrival order.
pub async fn serve_socket(shared: Arc<Shared>, socket: Socket) {
    let Ok(fd) = socket.int_option(ZMQ_FD) else {
        return;
    };
    // SAFETY: libzmq keeps the descriptor open while the socket is: until the front closes the
    // socket, after the edge (and this AsyncFd with it) has stopped
    let Ok(signals) =
        (unsafe { AsyncFd::register_with_interest(SignalFd(fd), Interest::READABLE) })
    else {
        return;
    };
    let (replier, mut replies) = mpsc::unbounded_channel::<Vec<Bytes>>();
    loop {
        while let Ok(reply) = replies.try_recv() {
            socket.send(&reply);
        }
        let mut read = 0;
        // the descriptor only tells of new signals, and a send may take one: always ask first
        while read < READ_BATCH {
            let received = match socket.waiting() {
                Ok(true) => socket.recv(),
                Ok(false) => break,
                Err(errno) => Err(errno),
            };
            match received {
                Ok(Some(parts)) => {
                    read += 1;
                    tokio::spawn(answer_message(shared.clone(), parts, replier.clone()));
                }
                Ok(None) => break,
                Err(_) => return, // the socket is closed (the front stopping)
            }
        }
        if read == READ_BATCH {
            tokio::task::yield_now().await;
            continue;
        }
        tokio::select! {
            ready = signals.readable() => match ready {
                Ok(mut guard) => guard.clear_ready(),
                Err(_) => return,
            },
            Some(reply) = replies.recv() => socket.send(&reply),
        }
    }
}

/// The request's envelope (identity, and REQ's empty delimiter) and its body, as
/// front/zmq_service.py splits them.
fn split_envelope(parts: &[Bytes]) -> (usize, &[Bytes]) {
    let body = &parts[1..];
    if matches!(body.len(), 3 | 4) && body[0].is_empty() {
        (2, &body[1..])
    } else {
        (1, body)
    }
}

/// One request's reply frames: the worker's for a routed session's Frame, else the front's Python's.
async fn answer_message(
    shared: Arc<Shared>,
    parts: Vec<Bytes>,
    replier: mpsc::UnboundedSender<Vec<Bytes>>,
) {
    let t0 = Instant::now();
    let reply = match routed(&shared, &parts, t0).await {
        Some(reply) => reply,
        None => {
            let (_, body) = split_envelope(&parts);
            let key = body.get(2).cloned().unwrap_or_default();
            let _with_python = frame_session(body).map(|id| shared.hand_to_python(id));
            let answer = shared.ask(|token| Event::Zmq { token, parts }).await;
            if answer.let_in {
                shared.let_in(&key, (answer.key_id, answer.tenant));
            }
            answer.frames // none when the edge is stopping
        }
    };
    let _ = replier.send(reply);
}

/// The session a Frame request's body names; None for another request or an unreadable one.
fn frame_session(body: &[Bytes]) -> Option<&str> {
    if !matches!(body.len(), 2 | 3) || body[0] != FRAME_RPC {
        return None;
    }
    wire::session_id(&body[1]).ok().filter(|id| !id.is_empty())
}

/// The reply to a Frame of a routed session from a caller let in; None for anything else.
async fn routed(shared: &Shared, parts: &[Bytes], t0: Instant) -> Option<Vec<Bytes>> {
    let (envelope, body) = split_envelope(parts);
    let session_id = frame_session(body)?;
    let payload = &body[1];
    if payload.len() > shared.max_message_bytes() {
        return None;
    }
    let key: &[u8] = body.get(2).map_or(b"", |k| k);
    let (_, tenant) = shared.known_caller(key)?;
    let answered = shared
        .routed_frame(session_id, &tenant, payload, t0, Via::Zmq)
        .await?;
    let mut reply = parts[..envelope].to_vec();
    match answered {
        Ok(body) => reply.extend([Bytes::from_static(b"0"), body]),
        Err(status) => {
            shared.record_error(status.code, Via::Zmq);
            reply.extend([
                Bytes::from(status.code.to_string()),
                Bytes::from(status.message),
            ]);
        }
    }
    Some(reply)
}
