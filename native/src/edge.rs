//! The compiled gRPC edge (issue 43, step 5; docs/frame_path.md, "The compiled gRPC edge"): the
//! node's public gRPC port served by hyper's HTTP/2 on one tokio thread inside the front process.
//!
//! - `StreamFrames` and the unary `Frame` are answered here. A frame of a session the front has *routed* here (its
//!   worker, its tenant, its rate) goes straight to that worker over the worker's frame socket
//!   (infra/channels.py's framing, op `frame`) and its reply straight back to the client: no Python
//!   in the front touches it. Where the front holds the sessions itself (`serve --workers 0`), this
//!   thread computes the frame through the front's table (`InlineTable`), with no hop at all.
//!   Everything else about a stream is asked of the front's Python through `Event`s (front/edge.py
//!   answers them): the caller's key when the stream opens, its first frame (the session adopted,
//!   restored, counted as streaming), any frame of a session not routed here (restoring, moved, or
//!   one the front's table hands back), and the stream's end. Python stays the judge of who may
//!   do what; this only repeats its per-frame checks (revoked key, one session a stream, the
//!   tenant's frame rate) with the state Python hands it.
//! - Every other call (the unary RPCs, health, reflection) is passed through, headers, messages
//!   and trailers as they are, to the front's grpc.aio server on a private Unix socket.
//! - With the node's certificate the port is TLS (rustls, ring's primitives, ALPN h2), as grpc.aio's
//!   `ssl_server_credentials` serves it: TLS 1.2 and 1.3, no client certificate.
//!
//! A frame answered here leaves a `FrameRecord` and its session's count for the front's metrics
//! and dashboard (`Shared::drain`), read off the frame path.

use std::collections::{HashMap, HashSet};
use std::io::Write;
use std::net::SocketAddr;
use std::os::fd::FromRawFd;
use std::os::unix::net::UnixStream as StdUnixStream;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use bytes::{Buf, BufMut, Bytes, BytesMut};
use http::{HeaderMap, HeaderName, HeaderValue, Request, Response};
use http_body::{Body, Frame};
use http_body_util::combinators::BoxBody;
use http_body_util::BodyExt;
use hyper::body::Incoming;
use hyper::client::conn::http2::SendRequest;
use hyper::service::service_fn;
use hyper_util::rt::{TokioExecutor, TokioIo};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, UnixStream};
use tokio::sync::{mpsc, oneshot};

use crate::idle_resets::IdleResetsDropped;
use crate::{wire, zmq_edge};

pub const STREAM_FRAMES: &str = "/camdirector.v1.Director/StreamFrames";
pub const UNARY_FRAME: &str = "/camdirector.v1.Director/Frame";
const CALLERS_KEPT: usize = 4096; // callers let in remembered (Shared::caller); all forgotten when full

/// gRPC status codes (grpc.StatusCode's numbers).
pub const OK: u8 = 0;
const CANCELLED: u8 = 1;
const INVALID_ARGUMENT: u8 = 3;
const RESOURCE_EXHAUSTED: u8 = 8;
const UNIMPLEMENTED: u8 = 12;
const INTERNAL: u8 = 13;
const UNAVAILABLE: u8 = 14;
const DATA_LOSS: u8 = 15;
const UNAUTHENTICATED: u8 = 16;

/// infra/channels.py: REQUEST "!IBHQ", REPLY "!IBBdBHQ", OPS.index("frame"), the reply's flags.
const REQUEST_HEADER_BYTES: usize = 15;
const REPLY_HEADER_BYTES: usize = 25;
const OP_FRAME: u8 = 3;
pub const HAS_METRICS: u8 = 1;

const GRPC_PREFIX_BYTES: usize = 5; // a gRPC message's compressed flag (u8) and length (u32)
const REPLIES_QUEUED: usize = 16; // a stream's replies buffered while its client reads slowly
const CONNECTION_WINDOW_BYTES: u32 = 4 << 20; // a connection's HTTP/2 receive window, bytes
const STREAM_WINDOW_BYTES: u32 = 1 << 20; // a stream's, bytes
const TLS_HANDSHAKE: Duration = Duration::from_secs(10); // a client not through its handshake by then is dropped
const WORKER_DIED: &str = "the worker holding this session died; retry: it is being restored";

type BoxError = Box<dyn std::error::Error + Send + Sync>;
pub type EdgeBody = BoxBody<Bytes, BoxError>;

/// The edge's settings, from ServerSettings (front/edge.py).
pub struct Config {
    pub max_message_bytes: usize, // a larger message ends its stream RESOURCE_EXHAUSTED, bytes
    pub metadata: Vec<(String, String)>, // sent with every stream's headers (grpc_service.SERVER_METADATA)
    pub rate_limit: bool,                // the tenant's frame rate is enforced (authentication on)
    pub max_fps: f64,                    // ServerSettings.tenant_max_fps, frames/s
    pub resend_frames: f64, // frames a session may send at once after a DATA_LOSS (router.RESEND_BURST_S), frames
}

/// A gRPC status: its code (the numbers above) and message.
#[derive(Debug, Clone)]
pub struct Status {
    pub code: u8,
    pub message: String,
}

impl Status {
    fn new(code: u8, message: impl Into<String>) -> Self {
        Status {
            code,
            message: message.into(),
        }
    }
}

/// What the front's Python is asked; each but `Closed` is answered through `Shared::answer`.
pub enum Event {
    /// The caller's `authorization` metadata, when a stream opens: its key and tenant, or a refusal.
    Auth {
        token: u64,
        authorization: Option<String>,
    },
    /// A stream's first frame: the stream opened on its session, then the frame answered.
    Open {
        token: u64,
        session_id: String,
        tenant: String,
        payload: Bytes,
    },
    /// A frame of a session not routed here, answered by the front's router (`unary`: a Frame call's).
    Frame {
        unary: bool,
        token: u64,
        session_id: String,
        tenant: String,
        payload: Bytes,
    },
    /// A stream that had opened on its session ended.
    Closed { session_id: String },
    /// A ZeroMQ request the edge does not answer itself (zmq_edge.rs), its frames as received:
    /// answered with the reply's frames (`Answer::frames`).
    Zmq { token: u64, parts: Vec<Bytes> },
}

/// Which call a frame answered here came by: a StreamFrames stream, a gRPC Frame call, a ZeroMQ Frame request.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Via {
    Stream = 0,
    Unary = 1,
    Zmq = 2,
}

/// Python's answer to an `Event`.
pub struct Answer {
    pub status: Status,
    pub body: Bytes,
    pub key_id: Option<String>, // Auth: the caller's key (None: authentication off)
    pub tenant: String,         // Auth: the caller's tenant
    pub opened: bool, // Open: the stream counts as open on its session (Closed due at its end)
    pub frames: Vec<Bytes>, // Zmq: the reply's frames, envelope included
    pub let_in: bool, // Zmq: the caller (key_id, tenant) may send frames, remembered as Auth's are
}

impl Answer {
    fn refused(status: Status) -> Self {
        Answer {
            status,
            body: Bytes::new(),
            key_id: None,
            tenant: String::new(),
            opened: false,
            frames: Vec::new(),
            let_in: false,
        }
    }
}

/// One frame answered here, for the front's Prometheus histograms (front/metrics.py).
pub struct FrameRecord {
    pub via: Via,
    pub elapsed_s: f64, // from its message read to its reply queued, s
    pub compute_ms: f64,
    pub flags: u8, // the reply's flags (infra/channels.py)
    pub names: Bytes,
    pub values: Vec<f64>,
}

/// What happened here since the last `drain`.
#[derive(Default)]
pub struct Drained {
    pub frames: Vec<FrameRecord>,
    pub errors: Vec<(u8, Via)>, // the status code of each call ended here with an error
    pub sessions: HashMap<String, (u64, u8)>, // frames answered here, and bit `1 << via` of each Via they came by, by session
}

/// A session's rate bucket as the router hands it over (router._admit_frame): `tokens` and
/// `resend` frames, last filled `age_s` ago (None: full).
pub struct Bucket {
    pub tokens: f64,
    pub resend: f64,
    pub age_s: Option<f64>,
}

/// A session routed here: where its frames go and its tenant's rate (router._admit_frame's bucket).
struct Route {
    slot: usize,
    tenant: String,
    tokens: f64,
    resend: f64,
    at: Option<Instant>, // None: a full bucket
}

impl Route {
    /// router._admit_frame's token bucket, with the same message.
    fn admit(&mut self, config: &Config, session_id: &str) -> Result<(), Status> {
        let rate = config.max_fps;
        let now = Instant::now();
        self.tokens = match self.at {
            Some(at) => rate.min(self.tokens + now.duration_since(at).as_secs_f64() * rate),
            None => rate,
        };
        self.at = Some(now);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
        } else if self.resend >= 1.0 {
            self.resend -= 1.0;
        } else {
            return Err(Status::new(
                RESOURCE_EXHAUSTED,
                format!(
                    "session {session_id} sends more than {} frames a second, its tenant's limit",
                    python_g(rate)
                ),
            ));
        }
        Ok(())
    }

    /// Gives back the frame `admit` took: a frame the front's Python answers after all, which
    /// takes it from its own bucket (router._admit_frame).
    fn refund(&mut self, config: &Config) {
        self.tokens = (self.tokens + 1.0).min(config.max_fps);
    }
}

/// A float as Python's `{:g}` writes the usual rates (60 -> "60", 7.5 -> "7.5").
fn python_g(value: f64) -> String {
    if value.fract() == 0.0 && value.abs() < 1e15 {
        format!("{}", value as i64)
    } else {
        format!("{value}")
    }
}

/// A worker's reply (infra/channels.py REPLY and its tail).
struct WorkerReply {
    status: u8,
    flags: u8,
    compute_ms: f64,
    names: Bytes,
    values: Vec<f64>,
    body: Bytes,
}

impl WorkerReply {
    /// A whole reply (header, stage names, stage times, body) and its request's id.
    fn parse(mut reply: Bytes) -> Result<(u32, WorkerReply), String> {
        if reply.len() < REPLY_HEADER_BYTES {
            return Err(format!("a reply of {} bytes has no header", reply.len()));
        }
        let stages = reply[14] as usize;
        let names_len = u16::from_be_bytes([reply[15], reply[16]]) as usize;
        let body_len = u64::from_be_bytes(reply[17..25].try_into().unwrap()) as usize;
        if reply.len() != REPLY_HEADER_BYTES + names_len + 8 * stages + body_len {
            return Err(format!(
                "a reply of {} bytes is not what its header says",
                reply.len()
            ));
        }
        let id = reply.get_u32();
        let status = reply.get_u8();
        let flags = reply.get_u8();
        let compute_ms = reply.get_f64();
        reply.advance(3 + 8); // stages, names length, body length: read above
        let names = reply.split_to(names_len);
        let values = (0..stages).map(|_| reply.get_f64()).collect();
        Ok((
            id,
            WorkerReply {
                status,
                flags,
                compute_ms,
                names,
                values,
                body: reply,
            },
        ))
    }
}

/// The front's own session table (`serve --workers 0`), answering a frame on the edge's thread:
/// no hop, no wake-up of another process (front/worker_pool.py, WorkerPool.answer_inline).
pub trait InlineTable: Send + Sync {
    /// The reply to a frame request of `session_id`, in a worker's framing; Ok(None) when the
    /// front's loop must answer it (its session is not held, or is bound to the loop's thread);
    /// Err(what went wrong) when the call itself failed.
    fn frame(&self, session_id: &str, payload: &[u8]) -> Result<Option<Bytes>, String>;
    /// One piece of the table's idle work (a deferred map update's maps, a snapshot due, the
    /// collector's next run), done when this thread has nothing else to do, as a worker does it
    /// between requests; whether more waits.
    fn idle(&self) -> bool;
}

/// Where a slot's sessions are held: a worker process, or the front's own table.
enum Host {
    Worker(Link),
    Inline(Box<dyn InlineTable>),
}

/// The edge's end of one worker's frame socket.
struct Link {
    requests: mpsc::UnboundedSender<Bytes>,
    pending: Arc<Mutex<HashMap<u32, oneshot::Sender<WorkerReply>>>>,
    alive: Arc<AtomicBool>,
    next_id: AtomicU32,
}

impl Link {
    /// The worker's reply to a frame request; None when the worker went away first.
    async fn frame(&self, session_id: &str, payload: &[u8]) -> Option<WorkerReply> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let (sender, reply) = oneshot::channel();
        self.pending.lock().unwrap().insert(id, sender);
        let mut request =
            BytesMut::with_capacity(REQUEST_HEADER_BYTES + session_id.len() + payload.len());
        request.put_u32(id);
        request.put_u8(OP_FRAME);
        request.put_u16(session_id.len() as u16);
        request.put_u64(payload.len() as u64);
        request.put_slice(session_id.as_bytes());
        request.put_slice(payload);
        if self.requests.send(request.freeze()).is_err() {
            self.pending.lock().unwrap().remove(&id);
            return None;
        }
        reply.await.ok()
    }
}

/// Writes the requests queued for a worker, those queued meanwhile in the same write.
async fn write_requests(
    mut socket: tokio::net::unix::OwnedWriteHalf,
    mut requests: mpsc::UnboundedReceiver<Bytes>,
) {
    let mut batch = BytesMut::new();
    while let Some(first) = requests.recv().await {
        batch.clear();
        batch.extend_from_slice(&first);
        while let Ok(more) = requests.try_recv() {
            batch.extend_from_slice(&more);
        }
        if socket.write_all(&batch).await.is_err() {
            return;
        }
    }
}

/// Reads a worker's replies and settles their requests; at its end of file, fails those in flight.
async fn read_replies(
    mut socket: tokio::net::unix::OwnedReadHalf,
    pending: Arc<Mutex<HashMap<u32, oneshot::Sender<WorkerReply>>>>,
    alive: Arc<AtomicBool>,
) {
    let mut buffer = BytesMut::with_capacity(1 << 16);
    loop {
        while buffer.len() >= REPLY_HEADER_BYTES {
            let stages = buffer[14] as usize;
            let names_len = u16::from_be_bytes([buffer[15], buffer[16]]) as usize;
            let body_len = u64::from_be_bytes(buffer[17..25].try_into().unwrap()) as usize;
            let total = REPLY_HEADER_BYTES + names_len + 8 * stages + body_len;
            if buffer.len() < total {
                buffer.reserve(total - buffer.len());
                break;
            }
            let (id, reply) = WorkerReply::parse(buffer.split_to(total).freeze())
                .expect("a reply cut at its header's length");
            let settled = pending.lock().unwrap().remove(&id);
            if let Some(sender) = settled {
                let _ = sender.send(reply);
            }
        }
        match socket.read_buf(&mut buffer).await {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
    }
    alive.store(false, Ordering::Release);
    pending.lock().unwrap().clear(); // their callers see the worker gone
}

/// A caller let in, by the SHA-256 of its authorization metadata: (key id, tenant).
pub(crate) type Caller = (Option<String>, String);

/// A key's SHA-256: callers are remembered by it, not by the key itself.
fn digest(key: &[u8]) -> [u8; 32] {
    ring::digest::digest(&ring::digest::SHA256, key)
        .as_ref()
        .try_into()
        .expect("SHA-256 is 32 bytes")
}

/// The edge's state, shared by its thread's tasks and the front's Python.
pub struct Shared {
    config: Config,
    routes: Mutex<HashMap<String, Route>>,
    hosts: Mutex<Vec<Option<Arc<Host>>>>,
    revoked: Mutex<HashSet<String>>,
    callers: Mutex<HashMap<[u8; 32], Caller>>,
    events: Mutex<Vec<Event>>,
    wake: StdUnixStream, // one byte written when `events` stops being empty (Python's loop reads the other end)
    asked: Mutex<HashMap<u64, oneshot::Sender<Answer>>>,
    next_token: AtomicU64,
    drained: Mutex<Drained>,
    // frames handed to the front's Python and not yet answered, by session: while a session has
    // any, its later frames go there too, so that none reaches the worker before an earlier one
    with_python: Mutex<HashMap<String, u32>>,
    upstream_path: String,
    upstream: tokio::sync::Mutex<Option<SendRequest<EdgeBody>>>,
    // an inline table may have idle work: set by each frame one answers, cleared when they say
    // none waits, and while a piece is done until the thread has looked at its sockets again
    idle_ready: AtomicBool,
    stopping: AtomicBool, // Edge::stop has begun: no more calls into the front's Python from idle moments
}

/// A frame of `session_id` with the front's Python, from its handover until this is dropped
/// (answered, or the edge stopping): Shared::with_python.
pub(crate) struct WithPython<'a> {
    shared: &'a Shared,
    session_id: String,
}

impl Drop for WithPython<'_> {
    fn drop(&mut self) {
        let mut held = self.shared.with_python.lock().unwrap();
        if let Some(count) = held.get_mut(&self.session_id) {
            *count -= 1;
            if *count == 0 {
                held.remove(&self.session_id);
            }
        }
    }
}

impl Shared {
    /// Notes a frame of `session_id` handed to the front's Python until the result is dropped.
    pub(crate) fn hand_to_python(&self, session_id: &str) -> WithPython<'_> {
        *self
            .with_python
            .lock()
            .unwrap()
            .entry(session_id.to_owned())
            .or_insert(0) += 1;
        WithPython {
            shared: self,
            session_id: session_id.to_owned(),
        }
    }

    fn push(&self, event: Event) {
        let mut events = self.events.lock().unwrap();
        let was_empty = events.is_empty();
        events.push(event);
        drop(events);
        if was_empty {
            let _ = (&self.wake).write(&[1]); // full: Python has bytes to read already
        }
    }

    pub(crate) async fn ask(&self, make: impl FnOnce(u64) -> Event) -> Answer {
        let token = self.next_token.fetch_add(1, Ordering::Relaxed);
        let (sender, answer) = oneshot::channel();
        self.asked.lock().unwrap().insert(token, sender);
        self.push(make(token));
        answer
            .await
            .unwrap_or_else(|_| Answer::refused(Status::new(UNAVAILABLE, "the server is stopping")))
    }

    /// Python's answer to the event of `token`.
    pub fn answer(&self, token: u64, answer: Answer) {
        if let Some(sender) = self.asked.lock().unwrap().remove(&token) {
            let _ = sender.send(answer);
        }
    }

    pub fn take_events(&self) -> Vec<Event> {
        std::mem::take(&mut *self.events.lock().unwrap())
    }

    pub fn drain(&self) -> Drained {
        std::mem::take(&mut *self.drained.lock().unwrap())
    }

    /// Routes the session's frames here, to the worker of `slot`, for `tenant`'s callers.
    pub fn route(&self, session_id: String, slot: usize, tenant: String, bucket: Bucket) {
        let at = bucket.age_s.map(|age| {
            Instant::now()
                .checked_sub(Duration::from_secs_f64(age.max(0.0)))
                .unwrap_or_else(Instant::now)
        });
        let (tokens, resend) = (bucket.tokens, bucket.resend);
        let route = Route {
            slot,
            tenant,
            tokens,
            resend,
            at,
        };
        self.routes.lock().unwrap().insert(session_id, route);
    }

    /// The session's rate state (tokens, resend tokens) when it was routed here.
    pub fn unroute(&self, session_id: &str) -> Option<(f64, f64)> {
        let route = self.routes.lock().unwrap().remove(session_id)?;
        Some((
            if route.at.is_some() {
                route.tokens
            } else {
                self.config.max_fps
            },
            route.resend,
        ))
    }

    pub fn revoke(&self, key_id: String) {
        // under the callers' lock, as `let_in` checks: a caller let in while this runs is either
        // forgotten here or refused there
        let mut callers = self.callers.lock().unwrap();
        callers.retain(|_, (key, _)| key.as_deref() != Some(key_id.as_str()));
        self.revoked.lock().unwrap().insert(key_id);
    }

    /// The caller's (key id, tenant) when its key may stream frames: asked of the front's Python
    /// (Guard.authorize_async, from its cache of keys) the first time, then remembered until the
    /// key is revoked. Err(the front's refusal) otherwise.
    async fn caller(&self, authorization: Option<String>) -> Result<Caller, Status> {
        let key = authorization.as_deref().unwrap_or("").as_bytes().to_vec();
        if let Some(known) = self.known_caller(&key) {
            return Ok(known);
        }
        let answer = self
            .ask(|token| Event::Auth {
                token,
                authorization,
            })
            .await;
        if answer.status.code != OK {
            return Err(answer.status);
        }
        let caller = (answer.key_id, answer.tenant);
        self.let_in(&key, caller.clone());
        Ok(caller)
    }

    /// A caller let in before, by its key (gRPC's authorization metadata, ZeroMQ's key frame: the
    /// same `Bearer KEY`); None when unknown.
    pub(crate) fn known_caller(&self, key: &[u8]) -> Option<Caller> {
        self.callers.lock().unwrap().get(&digest(key)).cloned()
    }

    /// Remembers a caller the front's Python let in (until its key is revoked).
    pub(crate) fn let_in(&self, key: &[u8], caller: Caller) {
        let mut callers = self.callers.lock().unwrap();
        if let Some(key_id) = &caller.0 {
            if self.revoked.lock().unwrap().contains(key_id) {
                return; // revoked while the front's answer was on its way
            }
        }
        if callers.len() >= CALLERS_KEPT {
            callers.clear();
        }
        callers.insert(digest(key), caller);
    }

    /// The worker of `slot`'s frame socket (a successor's replaces its predecessor's).
    pub fn set_worker(&self, slot: usize, socket: StdUnixStream) -> std::io::Result<()> {
        socket.set_nonblocking(true)?;
        let (reader, writer) = UnixStream::from_std(socket)?.into_split();
        let (requests, queued) = mpsc::unbounded_channel();
        let link = Link {
            requests,
            pending: Arc::new(Mutex::new(HashMap::new())),
            alive: Arc::new(AtomicBool::new(true)),
            next_id: AtomicU32::new(0),
        };
        tokio::spawn(write_requests(writer, queued));
        tokio::spawn(read_replies(
            reader,
            link.pending.clone(),
            link.alive.clone(),
        ));
        self.set_host(slot, Host::Worker(link));
        Ok(())
    }

    /// The front's own table holds the sessions of `slot` (`serve --workers 0`).
    pub fn set_inline(&self, slot: usize, table: Box<dyn InlineTable>) {
        self.set_host(slot, Host::Inline(table));
    }

    fn set_host(&self, slot: usize, host: Host) {
        let mut hosts = self.hosts.lock().unwrap();
        if hosts.len() <= slot {
            hosts.resize(slot + 1, None);
        }
        hosts[slot] = Some(Arc::new(host));
    }

    /// Called by the edge's thread whenever it is about to sleep: one piece of each inline table's
    /// idle work (InlineTable::idle). A frame that arrives meanwhile waits for that piece at most,
    /// as a worker's does (worker/main.py). When more waits, the next piece comes only after the
    /// thread has polled its sockets again (a task that yields once), so frames already there go
    /// first.
    fn idle_moment(self: &Arc<Self>) {
        if self.stopping.load(Ordering::Acquire) || !self.idle_ready.swap(false, Ordering::AcqRel) {
            return;
        }
        let mut more = false;
        for slot in 0.. {
            // one slot's host at a time, its lock let go before the call into Python
            let Some(host) = self.hosts.lock().unwrap().get(slot).cloned() else {
                break;
            };
            if let Some(Host::Inline(table)) = host.as_deref() {
                more |= table.idle();
            }
        }
        if more {
            let shared = self.clone();
            tokio::spawn(async move {
                tokio::task::yield_now().await; // after the sockets' poll (tokio's defer list)
                shared.idle_ready.store(true, Ordering::Release);
            });
        }
    }

    pub(crate) fn record_error(&self, code: u8, via: Via) {
        self.drained.lock().unwrap().errors.push((code, via));
    }

    pub(crate) fn max_message_bytes(&self) -> usize {
        self.config.max_message_bytes
    }

    /// A frame of a session routed here, answered by its worker; None when it is not routed here
    /// for this tenant or its worker is gone (the front's Python answers it).
    pub(crate) async fn routed_frame(
        &self,
        session_id: &str,
        tenant: &str,
        payload: &[u8],
        t0: Instant,
        via: Via,
    ) -> Option<Result<Bytes, Status>> {
        if self.with_python.lock().unwrap().contains_key(session_id) {
            return None; // after its earlier frames, through the front's Python
        }
        let host = {
            let mut routes = self.routes.lock().unwrap();
            let route = routes.get_mut(session_id).filter(|r| r.tenant == tenant)?;
            let host = self
                .hosts
                .lock()
                .unwrap()
                .get(route.slot)
                .cloned()
                .flatten()?;
            if let Host::Worker(link) = &*host {
                if !link.alive.load(Ordering::Acquire) {
                    return None;
                }
            }
            if self.config.rate_limit {
                if let Err(status) = route.admit(&self.config, session_id) {
                    return Some(Err(status));
                }
            }
            host
        };
        let reply = match &*host {
            Host::Worker(link) => match link.frame(session_id, payload).await {
                Some(reply) => reply,
                None => return Some(Err(Status::new(UNAVAILABLE, WORKER_DIED))),
            },
            // on this thread, with no route's lock held: the table takes Python's lock, and
            // Python's thread may be waiting on one of ours
            Host::Inline(table) => {
                let answered = table.frame(session_id, payload);
                self.idle_ready.store(true, Ordering::Release); // the frame may have left work for later
                match answered {
                    Ok(Some(bytes)) => match WorkerReply::parse(bytes) {
                        Ok((_, reply)) => reply,
                        Err(message) => return Some(Err(Status::new(INTERNAL, message))),
                    },
                    Ok(None) => {
                        if self.config.rate_limit {
                            if let Some(route) = self.routes.lock().unwrap().get_mut(session_id) {
                                route.refund(&self.config);
                            }
                        }
                        return None;
                    }
                    Err(message) => return Some(Err(Status::new(INTERNAL, message))),
                }
            }
        };
        if reply.status != OK {
            if reply.status == DATA_LOSS {
                // the updates since are on their way again, at once (router.frame)
                if let Some(route) = self.routes.lock().unwrap().get_mut(session_id) {
                    route.resend = self.config.resend_frames;
                }
            }
            return Some(Err(Status::new(
                reply.status,
                String::from_utf8_lossy(&reply.body).into_owned(),
            )));
        }
        let mut drained = self.drained.lock().unwrap();
        let session = drained
            .sessions
            .entry(session_id.to_owned())
            .or_insert((0, 0));
        session.0 += 1;
        session.1 |= 1 << via as u8;
        drained.frames.push(FrameRecord {
            via,
            elapsed_s: t0.elapsed().as_secs_f64(),
            compute_ms: reply.compute_ms,
            flags: reply.flags,
            names: reply.names,
            values: reply.values,
        });
        Some(Ok(reply.body))
    }

    async fn upstream(&self) -> Result<SendRequest<EdgeBody>, BoxError> {
        let mut held = self.upstream.lock().await;
        if let Some(sender) = held.as_ref().filter(|s| !s.is_closed()) {
            return Ok(sender.clone());
        }
        let socket = UnixStream::connect(&self.upstream_path).await?;
        let (sender, connection) = hyper::client::conn::http2::Builder::new(TokioExecutor::new())
            .adaptive_window(true)
            .handshake(TokioIo::new(socket))
            .await?;
        tokio::spawn(connection);
        *held = Some(sender.clone());
        Ok(sender)
    }
}

/// A stream's response body: what its task queues.
struct QueuedBody(mpsc::Receiver<Frame<Bytes>>);

impl Body for QueuedBody {
    type Data = Bytes;
    type Error = BoxError;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, BoxError>>> {
        self.0.poll_recv(cx).map(|frame| frame.map(Ok))
    }
}

/// gRPC's percent-encoding of grpc-message.
fn percent_encoded(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    for byte in message.bytes() {
        if (0x20..=0x7e).contains(&byte) && byte != b'%' {
            out.push(byte as char);
        } else {
            out.push_str(&format!("%{byte:02X}"));
        }
    }
    out
}

fn trailers(status: &Status) -> HeaderMap {
    let mut map = HeaderMap::new();
    map.insert("grpc-status", HeaderValue::from(u16::from(status.code)));
    if !status.message.is_empty() {
        if let Ok(value) = HeaderValue::from_str(&percent_encoded(&status.message)) {
            map.insert("grpc-message", value);
        }
    }
    map
}

fn grpc_headers(response: &mut Response<EdgeBody>, metadata: &[(String, String)]) {
    let headers = response.headers_mut();
    headers.insert("content-type", HeaderValue::from_static("application/grpc"));
    for (name, value) in metadata {
        if let (Ok(name), Ok(value)) = (
            HeaderName::try_from(name.as_str()),
            HeaderValue::from_str(value),
        ) {
            headers.insert(name, value);
        }
    }
}

/// A stream's gRPC messages, as their bytes, from its request body.
struct Messages {
    body: Incoming,
    buffer: BytesMut,
    limit: usize,
}

impl Messages {
    /// The next message; Ok(None) when the client has sent its last.
    async fn next(&mut self) -> Result<Option<Bytes>, Status> {
        loop {
            if self.buffer.len() >= GRPC_PREFIX_BYTES {
                if self.buffer[0] != 0 {
                    return Err(Status::new(
                        UNIMPLEMENTED,
                        "compressed messages are not accepted: send them uncompressed",
                    ));
                }
                let length = u32::from_be_bytes(self.buffer[1..5].try_into().unwrap()) as usize;
                if length > self.limit {
                    return Err(Status::new(
                        RESOURCE_EXHAUSTED,
                        format!(
                            "SERVER: Received message larger than max ({length} vs. {})",
                            self.limit
                        ),
                    ));
                }
                if self.buffer.len() >= GRPC_PREFIX_BYTES + length {
                    self.buffer.advance(GRPC_PREFIX_BYTES);
                    return Ok(Some(self.buffer.split_to(length).freeze()));
                }
            }
            match self.body.frame().await {
                None if self.buffer.is_empty() => return Ok(None),
                None => {
                    return Err(Status::new(
                        INVALID_ARGUMENT,
                        "the stream ended inside a message",
                    ))
                }
                Some(Err(_)) => return Err(Status::new(CANCELLED, "the client went away")),
                Some(Ok(frame)) => {
                    if let Ok(data) = frame.into_data() {
                        self.buffer.extend_from_slice(&data);
                    }
                }
            }
        }
    }
}

fn grpc_message(payload: &[u8]) -> Bytes {
    let mut framed = BytesMut::with_capacity(GRPC_PREFIX_BYTES + payload.len());
    framed.put_u8(0);
    framed.put_u32(payload.len() as u32);
    framed.put_slice(payload);
    framed.freeze()
}

/// One StreamFrames call (`unary` false), as grpc_service.DirectorGrpc.stream_frames answers it,
/// or one Frame call (`unary`), as its unary handler does: the caller's key checked as it opens,
/// then each frame answered in turn until the client's last (a Frame call's one). Its status, and
/// whether the front's Python gave it (and counted it in its metrics).
async fn answer_call(
    shared: &Shared,
    authorization: Option<String>,
    messages: &mut Messages,
    replies: &mpsc::Sender<Frame<Bytes>>,
    session: &mut Option<String>,
    unary: bool,
) -> (Status, bool) {
    let (key_id, tenant) = match shared.caller(authorization).await {
        Ok(caller) => caller,
        Err(status) => return (status, true),
    };
    let call = Call {
        shared,
        key_id: &key_id,
        tenant: &tenant,
        unary,
    };
    match call.answer_frames(messages, replies, session).await {
        Ok(()) => (Status::new(OK, ""), false),
        Err(ended) => ended,
    }
}

/// A call's caller, once let in.
struct Call<'a> {
    shared: &'a Shared,
    key_id: &'a Option<String>,
    tenant: &'a str,
    unary: bool,
}

impl Call<'_> {
    /// The call's frames; Err((status, given by Python)) when one ends it.
    async fn answer_frames(
        &self,
        messages: &mut Messages,
        replies: &mpsc::Sender<Frame<Bytes>>,
        session: &mut Option<String>,
    ) -> Result<(), (Status, bool)> {
        let mut answered = 0;
        loop {
            let payload = match messages.next().await {
                Ok(Some(payload)) => payload,
                Ok(None) if self.unary && answered == 0 => {
                    return Err((
                        Status::new(INTERNAL, "the call carried no request message"),
                        false,
                    ))
                }
                Ok(None) => return Ok(()),
                Err(status) => return Err((status, false)),
            };
            let reply = self.answer(payload, session).await?;
            if replies
                .send(Frame::data(grpc_message(&reply)))
                .await
                .is_err()
            {
                return Err((Status::new(CANCELLED, "the client went away"), false));
            }
            answered += 1;
            if self.unary {
                return Ok(());
            }
        }
    }

    /// One frame's reply.
    async fn answer(
        &self,
        payload: Bytes,
        session: &mut Option<String>,
    ) -> Result<Bytes, (Status, bool)> {
        let ours = |status| Err((status, false));
        let t0 = Instant::now();
        if let Some(key_id) = self.key_id {
            if self.shared.revoked.lock().unwrap().contains(key_id) {
                return ours(Status::new(
                    UNAUTHENTICATED,
                    format!("key {key_id} was revoked"),
                ));
            }
        }
        let session_id = match wire::session_id(&payload) {
            Ok("") => return ours(Status::new(INVALID_ARGUMENT, "session_id is empty")),
            Ok(id) => id.to_owned(),
            Err(()) => {
                return ours(Status::new(
                    INVALID_ARGUMENT,
                    "payload is not a serialized camdirector.v1.FrameUpdate",
                ))
            }
        };
        let tenant = self.tenant.to_owned();
        if !self.unary {
            match session.as_deref() {
                None => {
                    let _with_python = self.shared.hand_to_python(&session_id);
                    let answer = self
                        .shared
                        .ask(|token| Event::Open {
                            token,
                            session_id: session_id.clone(),
                            tenant,
                            payload,
                        })
                        .await;
                    if answer.opened {
                        *session = Some(session_id);
                    }
                    return if answer.status.code == OK {
                        Ok(answer.body)
                    } else {
                        Err((answer.status, true))
                    };
                }
                Some(open) if open != session_id => {
                    return ours(Status::new(
                        INVALID_ARGUMENT,
                        format!("a stream carries one session: got '{session_id}' on the stream of '{open}'"),
                    ));
                }
                Some(_) => {}
            }
        }
        let via = if self.unary { Via::Unary } else { Via::Stream };
        match self
            .shared
            .routed_frame(&session_id, &tenant, &payload, t0, via)
            .await
        {
            Some(Ok(body)) => Ok(body),
            Some(Err(status)) => ours(status),
            None => {
                let unary = self.unary;
                let _with_python = self.shared.hand_to_python(&session_id);
                let answer = self
                    .shared
                    .ask(|token| Event::Frame {
                        unary,
                        token,
                        session_id,
                        tenant,
                        payload,
                    })
                    .await;
                if answer.status.code == OK {
                    Ok(answer.body)
                } else {
                    Err((answer.status, true))
                }
            }
        }
    }
}

async fn run_call(
    shared: Arc<Shared>,
    authorization: Option<String>,
    body: Incoming,
    replies: mpsc::Sender<Frame<Bytes>>,
    unary: bool,
) {
    let mut messages = Messages {
        body,
        buffer: BytesMut::new(),
        limit: shared.config.max_message_bytes,
    };
    let mut session = None;
    let (status, counted) = answer_call(
        &shared,
        authorization,
        &mut messages,
        &replies,
        &mut session,
        unary,
    )
    .await;
    if let Some(session_id) = session {
        shared.push(Event::Closed { session_id });
    }
    if status.code != OK && status.code != CANCELLED && !counted {
        shared.record_error(status.code, if unary { Via::Unary } else { Via::Stream });
    }
    let _ = replies.send(Frame::trailers(trailers(&status))).await;
}

/// A call other than StreamFrames, passed through to the front's grpc.aio server.
async fn pass_through(shared: Arc<Shared>, request: Request<Incoming>) -> Response<EdgeBody> {
    let (mut parts, body) = request.into_parts();
    let path = parts.uri.path_and_query().map_or("/", |p| p.as_str());
    parts.uri = match format!("http://localhost{path}").parse() {
        Ok(uri) => uri,
        Err(_) => return refusal(&shared, Status::new(INVALID_ARGUMENT, "not a gRPC path")),
    };
    let request = Request::from_parts(parts, body.map_err(|e| Box::new(e) as BoxError).boxed());
    let sent = async {
        let mut sender = shared.upstream().await?;
        sender.ready().await?;
        Ok::<_, BoxError>(sender.send_request(request).await?)
    };
    match sent.await {
        Ok(response) => response.map(|b| b.map_err(|e| Box::new(e) as BoxError).boxed()),
        Err(_) => refusal(
            &shared,
            Status::new(
                UNAVAILABLE,
                "the node's gRPC service is not answering; retry",
            ),
        ),
    }
}

/// A call refused before any message: gRPC's trailers-only response.
fn refusal(shared: &Shared, status: Status) -> Response<EdgeBody> {
    let mut response = Response::new(http_body_util::Empty::new().map_err(|e| match e {}).boxed());
    grpc_headers(&mut response, &shared.config.metadata);
    response.headers_mut().extend(trailers(&status));
    response
}

async fn serve(
    shared: Arc<Shared>,
    request: Request<Incoming>,
) -> Result<Response<EdgeBody>, std::convert::Infallible> {
    let unary = match request.uri().path() {
        STREAM_FRAMES => false,
        UNARY_FRAME => true,
        _ => return Ok(pass_through(shared, request).await),
    };
    let authorization = request
        .headers()
        .get("authorization")
        .and_then(|v| v.to_str().ok())
        .map(str::to_owned);
    let (replies, queued) = mpsc::channel(REPLIES_QUEUED);
    tokio::spawn(run_call(
        shared.clone(),
        authorization,
        request.into_body(),
        replies,
        unary,
    ));
    let mut response = Response::new(QueuedBody(queued).boxed());
    grpc_headers(&mut response, &shared.config.metadata);
    Ok(response)
}

/// One client connection's HTTP/2, until it closes.
async fn serve_connection<S>(shared: Arc<Shared>, stream: S)
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send + 'static,
{
    let service = service_fn(move |request| serve(shared.clone(), request));
    // A fixed window, not an adaptive one: h2 allows a connection's unread small DATA frames an
    // overhead of half its window (data_frame_budget), and a client streaming small frames ahead
    // of their answers (as grpc's do) tripped an adaptive window's first 64 KiB.
    let served = hyper::server::conn::http2::Builder::new(TokioExecutor::new())
        .initial_connection_window_size(CONNECTION_WINDOW_BYTES)
        .initial_stream_window_size(STREAM_WINDOW_BYTES)
        .serve_connection(TokioIo::new(IdleResetsDropped::new(stream)), service)
        .await;
    // A client that hangs up is routine; any other end (an HTTP/2 protocol error, h2's limits on
    // reset streams) sent the client a GOAWAY, and the server's log is the one place that says why.
    match served {
        Err(error) if !hung_up(&error) => {
            eprintln!("camdirector gRPC edge: a client's connection ended on an error: {error:?}")
        }
        _ => {}
    }
}

/// Whether a connection's error is its client hanging up (closed, reset, cut mid-message).
fn hung_up(error: &hyper::Error) -> bool {
    use std::io::ErrorKind::{BrokenPipe, ConnectionAborted, ConnectionReset, UnexpectedEof};
    if error.is_closed() || error.is_incomplete_message() || error.is_canceled() {
        return true;
    }
    let mut source = std::error::Error::source(error);
    while let Some(cause) = source {
        if let Some(io) = cause.downcast_ref::<std::io::Error>() {
            return matches!(
                io.kind(),
                BrokenPipe | ConnectionAborted | ConnectionReset | UnexpectedEof
            );
        }
        source = cause.source();
    }
    false
}

/// Accepts gRPC connections until the edge stops, each served in its own task.
async fn accept(
    shared: Arc<Shared>,
    listener: TcpListener,
    tls: Option<tokio_rustls::TlsAcceptor>,
    mut stopped: oneshot::Receiver<()>,
) {
    loop {
        let accepted = tokio::select! {
            _ = &mut stopped => return,
            accepted = listener.accept() => accepted,
        };
        let Ok((stream, _)) = accepted else { continue };
        let _ = stream.set_nodelay(true);
        let shared = shared.clone();
        let tls = tls.clone();
        tokio::spawn(async move {
            match tls {
                None => serve_connection(shared, stream).await,
                Some(acceptor) => {
                    let handshake = tokio::time::timeout(TLS_HANDSHAKE, acceptor.accept(stream));
                    if let Ok(Ok(stream)) = handshake.await {
                        serve_connection(shared, stream).await;
                    }
                }
            }
        });
    }
}

/// The TLS side of the port: the node's certificate chain and key (PEM), ALPN h2.
fn tls_acceptor(cert_pem: &[u8], key_pem: &[u8]) -> std::io::Result<tokio_rustls::TlsAcceptor> {
    use rustls::pki_types::pem::PemObject;
    use rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let invalid = |what: &str, e: &dyn std::fmt::Display| {
        std::io::Error::new(std::io::ErrorKind::InvalidData, format!("{what}: {e}"))
    };
    let certs = CertificateDer::pem_slice_iter(cert_pem)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| invalid("the TLS certificate", &e))?;
    let key = PrivateKeyDer::from_pem_slice(key_pem).map_err(|e| invalid("the TLS key", &e))?;
    // ring's primitives offer no post-quantum key exchange (hence rustls's deprecation); aws-lc-rs,
    // which does, would add a long C build to every build of the wheel. grpc.aio's TLS offers none either.
    #[allow(deprecated)]
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut config = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| invalid("TLS", &e))?
        .with_no_client_auth()
        .with_single_cert(certs, key)
        .map_err(|e| invalid("the TLS certificate and key", &e))?;
    config.alpn_protocols = vec![b"h2".to_vec()];
    Ok(tokio_rustls::TlsAcceptor::from(Arc::new(config)))
}

/// The edge: its thread, its gRPC listening socket and its shared state.
pub struct Edge {
    pub shared: Arc<Shared>,
    pub address: Option<SocketAddr>, // the gRPC port's (None: gRPC is not served here)
    runtime: Option<tokio::runtime::Runtime>,
    stop: Option<oneshot::Sender<()>>,
}

impl Edge {
    /// Starts the edge's thread, serving gRPC on `address` (HOST:PORT; port 0 picks one) when
    /// given. `upstream_path`: the front's grpc.aio server's Unix socket; `wake`: the socket whose
    /// other end the front's event loop reads (Shared::push); `tls`: the certificate chain and
    /// private key, PEM, to serve TLS with.
    pub fn start(
        config: Config,
        address: Option<&str>,
        upstream_path: String,
        wake: StdUnixStream,
        tls: Option<(&[u8], &[u8])>,
    ) -> std::io::Result<Edge> {
        let tls = tls.map(|(cert, key)| tls_acceptor(cert, key)).transpose()?;
        wake.set_nonblocking(true)?;
        let parked: Arc<OnceLock<Arc<Shared>>> = Arc::new(OnceLock::new());
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("camdirector-edge")
            .on_thread_park({
                let parked = parked.clone();
                move || {
                    if let Some(shared) = parked.get() {
                        shared.idle_moment();
                    }
                }
            })
            .enable_all()
            .build()?;
        let listener = address
            .map(|address| runtime.block_on(TcpListener::bind(address)))
            .transpose()?;
        let address = listener.as_ref().map(TcpListener::local_addr).transpose()?;
        let shared = Arc::new(Shared {
            config,
            routes: Mutex::new(HashMap::new()),
            hosts: Mutex::new(Vec::new()),
            revoked: Mutex::new(HashSet::new()),
            callers: Mutex::new(HashMap::new()),
            events: Mutex::new(Vec::new()),
            wake,
            asked: Mutex::new(HashMap::new()),
            next_token: AtomicU64::new(0),
            drained: Mutex::new(Drained::default()),
            with_python: Mutex::new(HashMap::new()),
            upstream_path,
            upstream: tokio::sync::Mutex::new(None),
            idle_ready: AtomicBool::new(false),
            stopping: AtomicBool::new(false),
        });
        let _ = parked.set(shared.clone());
        let (stop, stopped) = oneshot::channel::<()>();
        if let Some(listener) = listener {
            runtime.spawn(accept(shared.clone(), listener, tls, stopped));
        }
        Ok(Edge {
            shared,
            address,
            runtime: Some(runtime),
            stop: Some(stop),
        })
    }

    /// Serves the front's ZeroMQ socket from now on (zmq_edge.rs).
    pub fn serve_zmq(&self, socket: zmq_edge::Socket) {
        let runtime = self.runtime.as_ref().expect("the edge has stopped");
        runtime.spawn(zmq_edge::serve_socket(self.shared.clone(), socket));
    }

    /// Runs `f` inside the edge's runtime (tokio's sockets must be made there).
    pub fn enter<T>(&self, f: impl FnOnce() -> T) -> T {
        let _guard = self.runtime.as_ref().expect("the edge has stopped").enter();
        f()
    }

    /// Stops listening and ends every connection: the edge's thread is gone when this returns.
    pub fn stop(&mut self) {
        self.shared.stopping.store(true, Ordering::Release);
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_timeout(Duration::from_secs(1));
        }
        for (_, sender) in self.shared.asked.lock().unwrap().drain() {
            drop(sender);
        }
    }
}

/// A worker's frame socket from the file descriptor Python hands over (its own from then on).
///
/// # Safety
/// `fd` must be an open Unix stream socket that nothing else will close.
pub unsafe fn socket_from_fd(fd: i32) -> StdUnixStream {
    StdUnixStream::from_raw_fd(fd)
}
