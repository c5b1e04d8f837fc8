"""Server settings: one typed object, defaults with unit and limit, validated once.

Precedence: command-line flag > environment variable ``CAMDIRECTOR_<FIELD>`` (upper case) >
default. ``ServerSettings.from_env()`` reads the environment; the CLI overlays its flags.
"""
from __future__ import annotations

import dataclasses
import os
import re
import socket
from dataclasses import dataclass, field
from pathlib import Path


def _default_data_dir() -> str:
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local", "share")
    return os.path.join(base, "camdirector")


FRAME_PATHS = ("python", "compiled")  # ServerSettings.frame_path's values
FRONTS = ("python", "compiled")  # ServerSettings.grpc_front's and zmq_front's values


@dataclass(frozen=True)
class ServerSettings:
    # Transport addresses; an empty string turns that transport off.
    grpc_addr: str = "127.0.0.1:50051"       # HOST:PORT
    zmq_addr: str = "tcp://127.0.0.1:5555"   # tcp://HOST:PORT
    http_addr: str = "127.0.0.1:8080"        # HOST:PORT, /healthz, /metrics, REST
    # HOST:PORT of the liveness port a balancer checks (front/live_check.py: plain HTTP, GET /live);
    # "" (the default) serves none. Bind it where the balancer reaches it and clients do not.
    live_addr: str = ""
    # Worker processes holding sessions; 0 runs sessions inside the front process. [0, 256]
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    max_sessions: int = 64                   # open sessions at once, all workers together. [1, 100000]
    # Threads one ANTICIPATION map update may share (native/src/maps.rs; the maps' bits do not
    # depend on it); 0: the machine's cores with workers 0 (the front holds the sessions on one
    # thread), else 1 (the workers already share the cores). [0, 64]
    map_threads: int = 0
    max_objects: int = 4096                  # scene objects per session. [1, 1e6]
    max_triangles: int = 2_000_000           # triangles per session scene, all meshes. [1, 1e8]
    max_message_bytes: int = 64 * 1024 * 1024  # largest request on any transport, bytes. [1 KiB, 1 GiB]
    session_resume_s: float = 60.0           # an idle session without a stream is reclaimed after this, s. [0.1, 86400]
    reap_interval_s: float = 1.0             # how often idle sessions are looked for, s. [0.01, 60]
    data_dir: str = field(default_factory=_default_data_dir)  # recordings and later artifacts
    record_all: bool = False                 # record every session, not only those that ask
    max_concurrent_jobs: int = 1             # offline jobs (motion overviews) running at once. [1, 64]
    max_queued_jobs: int = 16                # offline jobs waiting; more answer HTTP 429. [0, 100000]
    max_upload_bytes: int = 64 * 1024 * 1024  # largest job upload, bytes (HTTP 413 above). [1 KiB, 4 GiB]
    max_json_body_bytes: int = 64 * 1024     # largest body of an HTTP route but uploads and login (4 KiB), bytes (413 above). [1 KiB, 16 MiB]
    job_retention_s: float = 7 * 86400.0     # finished offline jobs are removed this long after they ended; 0 keeps them, s. [0, 1e9]
    # Where job records live: "" is SQLite in data_dir (one node); postgresql://... is shared by many nodes.
    job_store: str = ""
    # Where jobs wait to run: "" is this process's own runner (one node); redis://... is a queue that
    # queue workers on any node take jobs from (`camdirector job-worker`).
    job_queue: str = ""
    # Session checkpoints (worker/checkpoint_stores.py): "" is a folder in data_dir (survives a worker's
    # death and a restart of this node); redis://... lets any node restore any session; "off" keeps none.
    checkpoint_store: str = ""
    checkpoint_every_frames: int = 60        # a session's state is snapshotted every this many frames. [1, 100000]
    checkpoint_keep_s: float = 600.0         # a checkpoint no node has written for this long is removed, s. [1, 1e7]
    checkpoint_wait_ms: float = 10.0         # a write's result is waited for this long, then the frame goes on without it, ms. [0, 1000]
    node_id: str = ""                        # this node's name in checkpoints' ownership ("": host name and pid)
    # Access (access/, docs/security.md). Keys live in the records database: SQLite in data_dir, or job_store's PostgreSQL.
    auth: bool = True                        # every call needs a key; False (--no-auth) lets anyone in
    tls_cert: str = ""                       # PEM certificate chain: gRPC and HTTP over TLS ("" plaintext)
    tls_key: str = ""                        # its PEM private key
    insecure: bool = False                   # allow plaintext on a non-loopback address (behind a trusted proxy)
    # Each tenant's share, with authentication on (every tenant the same); beyond it RESOURCE_EXHAUSTED /
    # HTTP 429 with a message.
    tenant_max_sessions: int = 64            # sessions a tenant has open on this node. [1, 100000]
    tenant_max_fps: float = 240.0            # frames a second into one session (a bucket of 1 s of frames). [1, 10000]
    tenant_max_upload_bytes: int = 4 * 1024 ** 3  # bytes of uploads a tenant's jobs hold at once (inputs kept with jobs). [1 KiB, 1 TiB]
    tenant_max_queued_jobs: int = 16         # jobs a tenant has queued or running at once. [1, 100000]
    tenant_max_live_views: int = 16          # live monitor streams a tenant's viewers hold open on this node. [1, 64]
    # Where a session's pose outputs may send UDP datagrams (worker/codec.py): IPv4 networks, CIDR; any other
    # destination is refused at CreateSession. Comma-separated in the environment. [1, 64 networks]
    pose_output_allow: tuple[str, ...] = ("127.0.0.0/8",)
    # Python modules imported at start by the front and every worker (infra/plugins.py): a studio's own
    # match director registers itself (pipeline/match/director_registry.py). Comma-separated in the environment.
    plugins: tuple[str, ...] = ()
    # Where a session's per-frame work runs: "compiled" (camdirector._native; so far the TORIC rig's
    # frames in every visibility mode, the same bits on any x86-64 machine; TRACKS and MATCH in
    # Python: docs/frame_path.md) or "python", the reference it agrees with within 1e-9 m
    # and rad. Recordings replay bit for bit on the path that made them (`camdirector replay --frame-path`).
    frame_path: str = "compiled"
    # What serves the gRPC port: "compiled", the gRPC edge (native/src/edge.rs: HTTP/2 in Rust, TLS
    # with tls_cert, a routed session's frames straight to its worker, every other call passed to
    # grpc.aio; front/edge.py), or "python" (grpc.aio alone).
    grpc_front: str = "compiled"
    # What reads the ZeroMQ socket: "compiled", the same edge (native/src/zmq_edge.rs: a routed
    # session's Frame requests straight to its worker, every other request to zmq_service.py), or
    # "python" (zmq_service.py alone). Needs pyzmq's libzmq loaded as a shared library; where it
    # is not (a static build), the socket stays Python's and the start says so in the log.
    zmq_front: str = "compiled"

    def __post_init__(self):
        checks = [
            (0 <= self.workers <= 256, "workers must be in [0, 256]"),
            (1 <= self.max_sessions <= 100_000, "max_sessions must be in [1, 100000]"),
            (0 <= self.map_threads <= 64, "map_threads must be in [0, 64]"),
            (1 <= self.max_objects <= 1_000_000, "max_objects must be in [1, 1000000]"),
            (1 <= self.max_triangles <= 100_000_000, "max_triangles must be in [1, 1e8]"),
            (1024 <= self.max_message_bytes <= 1 << 30, "max_message_bytes must be in [1 KiB, 1 GiB]"),
            (1024 <= self.max_json_body_bytes <= 1 << 24, "max_json_body_bytes must be in [1 KiB, 16 MiB]"),
            (0.1 <= self.session_resume_s <= 86_400, "session_resume_s must be in [0.1, 86400]"),
            (0.01 <= self.reap_interval_s <= 60, "reap_interval_s must be in [0.01, 60]"),
            (not self.zmq_addr or self.zmq_addr.startswith(("tcp://", "ipc://")),
             "zmq_addr must start with tcp:// or ipc://"),
            (self.checkpoint_store in ("", "off") or self.checkpoint_store.startswith("redis://"),
             "checkpoint_store must be empty (a folder in data_dir), off, or a redis:// URL"),
            (1 <= self.checkpoint_every_frames <= 100_000, "checkpoint_every_frames must be in [1, 100000]"),
            (1 <= self.checkpoint_keep_s <= 1e7, "checkpoint_keep_s must be in [1, 1e7]"),
            (0 <= self.checkpoint_wait_ms <= 1000, "checkpoint_wait_ms must be in [0, 1000]"),
            (not self.job_store or self.job_store.startswith(("postgresql://", "postgres://")),
             "job_store must be empty (SQLite in data_dir) or a postgresql:// URL"),
            (not self.job_queue or self.job_queue.startswith("redis://"),
             "job_queue must be empty (this process's runner) or a redis:// URL"),
            (bool(self.tls_cert) == bool(self.tls_key), "tls_cert and tls_key go together"),
            (1 <= self.tenant_max_sessions <= 100_000, "tenant_max_sessions must be in [1, 100000]"),
            (1 <= self.tenant_max_fps <= 10_000, "tenant_max_fps must be in [1, 10000]"),
            (1024 <= self.tenant_max_upload_bytes <= 1 << 40, "tenant_max_upload_bytes must be in [1 KiB, 1 TiB]"),
            (1 <= self.tenant_max_queued_jobs <= 100_000, "tenant_max_queued_jobs must be in [1, 100000]"),
            (1 <= self.tenant_max_live_views <= 64, "tenant_max_live_views must be in [1, 64]"),
            (1 <= len(self.pose_output_allow) <= 64 and all(map(_ipv4_network, self.pose_output_allow)),
             "pose_output_allow must be 1 to 64 IPv4 networks (CIDR, like 127.0.0.0/8 or 10.1.2.3/32)"),
            (all(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*", m) for m in self.plugins),
             "plugins must be Python module names (a.b.c)"),
            (self.frame_path in FRAME_PATHS, f"frame_path must be one of {', '.join(FRAME_PATHS)}, not {self.frame_path!r}"),
            (self.grpc_front in FRONTS, f"grpc_front must be one of {', '.join(FRONTS)}, not {self.grpc_front!r}"),
            (self.zmq_front in FRONTS, f"zmq_front must be one of {', '.join(FRONTS)}, not {self.zmq_front!r}"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)

    @property
    def compiled_frame_path(self) -> bool:
        """Whether sessions run their rigs' compiled twins (frame_path "compiled")."""
        return self.frame_path == "compiled"

    @property
    def map_threads_per_update(self) -> int:
        """The threads one map update shares (map_threads, 0 resolved)."""
        if self.map_threads:
            return self.map_threads
        return (os.cpu_count() or 1) if self.workers == 0 else 1

    @property
    def grpc_edge(self) -> bool:
        """Whether the compiled gRPC edge serves the gRPC port (grpc_front "compiled")."""
        return bool(self.grpc_addr) and self.grpc_front == "compiled"

    @property
    def zmq_edge(self) -> bool:
        """Whether the compiled edge reads the ZeroMQ socket (zmq_front "compiled")."""
        return bool(self.zmq_addr) and self.zmq_front == "compiled"

    @property
    def edge(self) -> bool:
        """Whether the compiled edge runs (for gRPC, ZeroMQ or both): workers get frame sockets."""
        return self.grpc_edge or self.zmq_edge

    @property
    def tls(self) -> bool:
        return bool(self.tls_cert)

    def plaintext_exposed(self) -> list[str]:
        """The transports that would carry keys and scenes in clear beyond this machine: bound
        to a non-loopback address without TLS (gRPC, HTTP) or without CURVE (ZeroMQ, which has
        CURVE whenever authentication is on)."""
        return [f"{name} on {address}" for name, address, encrypted in self._beyond_loopback() if not encrypted]

    def network_exposed(self) -> list[str]:
        """The transports bound to a non-loopback address, encrypted or not (without keys, anyone
        who reaches one is an admin)."""
        return [f"{name} on {address}" for name, address, _ in self._beyond_loopback()]

    def _beyond_loopback(self) -> list[tuple[str, str, bool]]:
        """(name, address, encrypted) of each transport that is on and bound beyond this machine."""
        transports = (("grpc", self.grpc_addr, self.tls), ("http", self.http_addr, self.tls),
                      ("zmq", self.zmq_addr.removeprefix("tcp://"), self.auth))
        return [(name, address, encrypted) for name, address, encrypted in transports
                if address and not address.startswith("ipc://") and not _loopback(address)]

    @property
    def node_name(self) -> str:
        return self.node_id or f"{socket.gethostname()}-{os.getpid()}"

    @property
    def recordings_dir(self) -> Path:
        return Path(self.data_dir) / "recordings"

    @classmethod
    def from_env(cls, environ=None, **overrides) -> ServerSettings:
        """Settings from CAMDIRECTOR_* variables, then `overrides` (flags; None means not given)."""
        environ = os.environ if environ is None else environ
        values = {}
        for f in dataclasses.fields(cls):
            raw = environ.get(f"CAMDIRECTOR_{f.name.upper()}")
            if raw is not None:
                values[f.name] = _parse(str(f.type), raw, f.name)  # a str: annotations are postponed
        values.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**values)


def _loopback(address: str) -> bool:
    """Whether HOST:PORT names a loopback host (literally: a name is not resolved)."""
    import ipaddress

    host = address.rpartition(":")[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _ipv4_network(cidr: str) -> bool:
    import ipaddress

    try:
        ipaddress.IPv4Network(cidr)
    except ValueError:  # not CIDR, host bits set, or IPv6
        return False
    return True


def _parse(type_name: str, raw: str, name: str):
    try:
        if type_name == "int":
            return int(raw)
        if type_name == "float":
            return float(raw)
        if type_name == "tuple[str, ...]":
            return tuple(part.strip() for part in raw.split(",") if part.strip())
        if type_name == "bool":
            if raw.lower() in ("1", "true", "yes", "on"):
                return True
            if raw.lower() in ("0", "false", "no", "off", ""):
                return False
            raise ValueError(raw)
        return raw
    except ValueError:
        raise ValueError(f"CAMDIRECTOR_{name.upper()}: cannot read {raw!r} as {type_name}") from None
