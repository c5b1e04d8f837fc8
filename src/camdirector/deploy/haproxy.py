"""Debian's HAProxy (2.6) in front of the nodes: its configuration, and a launcher like the services
of deploy/services.py, with the runtime API that adds a node to the running balancer.

One gRPC frontend (HTTP/2 over TLS) sends every call that carries the `x-camdirector-route`
header to one node by a consistent hash of that header, so all the calls of a session reach the
node that holds it; calls without it go round robin. One HTTPS frontend spreads the nodes' REST
APIs the same way (a REST call about a session that carries the session's route header reaches the
node that holds it; the rest go round robin: the job and level resources are the same on every
node).

TLS ends at HAProxy, which encrypts again to each node (`ssl verify required ca-file`: a node
must show a certificate of the cluster's CA for `BalancerSettings.node_tls_name`, or it gets no
traffic and fails its checks). Passing TLS through (TCP mode) would hide the HTTP/2 streams from
HAProxy: it could route only whole connections, and one gRPC connection carries the calls of many
sessions (an SDK client opens one channel for all its sessions), each of which must reach its own
node by its route header. So HAProxy reads the headers in the clear, in its own memory only; on
the wire every hop is encrypted. Keys pass through untouched: HAProxy forwards the
`authorization` header and checks nothing, and every node checks every call against the keys
the nodes share in PostgreSQL (access/).

Health checks ask each node's liveness port (front/live_check.py: `GET /live` over TLS, the node's
certificate verified as for its traffic, answered by a thread of the node's own, not by the event
loop that answers frames), both backends the same port. Before, they went over TLS to the gRPC and
HTTP ports themselves (a hand-built HTTP/2 call of grpc.health.v1.Health/Check for the gRPC
backend), answered by the loop: their timeout had to stay above a busy loop's slowest answer plus a
handshake (400 ms), and a hung node stayed in for up to 1.4 s. The thread answers in about a
millisecond however busy the node, so checks come every 300 ms and a hung node is out within 1.2 s
(docs/scaling.md, "The balancer's checks"). The liveness port still fails a node whose loop is
blocked for seconds (it answers 503 then). What it does not see is a node whose gRPC or HTTP port
alone stopped answering while its loop runs: both are served by that loop, and a node whose server
fails to start exits.
"""

from __future__ import annotations

import csv
import socket
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from camdirector.deploy.services import ServiceError, _binary, _tail, _wait_port, free_port, stop_processes
from camdirector.deploy.tls import TlsFiles, files_in

ROUTE_HEADER = "x-camdirector-route"  # the metadata header the SDKs set on every call of a session
GRPC_BACKEND, HTTP_BACKEND = "nodes_grpc", "nodes_http"
UNIX_PATH_MAX = 107  # bytes in a unix socket's path, Linux's sun_path less the final NUL


@dataclass(frozen=True)
class BalancerSettings:
    host: str = "127.0.0.1"  # where the frontends listen (loopback: nothing else reaches them)
    grpc_port: int = 0  # the gRPC frontend's port; 0 picks a free one
    http_port: int = 0  # the REST frontend's port; 0 picks a free one
    # A node that stops answering (hung, SIGSTOPped, its machine lost) is out after
    # check_interval_s + fall x check_timeout_s + (fall - 1) x check_fast_interval_s at worst:
    # 1.2 s with these, 0.7 s at best (docs/scaling.md, "The balancer's checks").
    check_interval_s: float = 0.3  # between two health checks of a node in a steady state, s. [0.05, 60]
    check_fast_interval_s: float = 0.1  # between checks while a node is going up or down, s. [0.05, 60]
    # A check unanswered this long fails, s: far above the liveness thread's answer (a few ms on 2
    # busy cores, front/live_check.py), below a hung node's silence. 200 ms made the container
    # cluster's node-kill test lose frames in some runs (cause not found; docs/scaling.md). [0.05, 60]
    check_timeout_s: float = 0.4
    fall: int = 2  # failed checks in a row that mark a node down: one slow check alone does not. [1, 100]
    rise: int = 2  # passed checks in a row that mark it up again. [1, 100]
    # After a reload (`haproxy -sf`) the old process keeps its open streams at most this long, then
    # cuts them (the SDKs reopen them on the new one), s. [1, 3600]
    hard_stop_after_s: float = 5.0
    # Every node's weight. HAProxy puts 16 points per unit of weight on the hash ring: at weight 1
    # (its default) the busiest node's share of the ring is 1.34x the mean at 10 nodes and 1.44x at
    # 100; at 256 (4096 points) 1.02x and 1.03x (load_tests/ring_sim.py). [1, 256]
    weight: int = 256
    # The longest a client or node may stay silent on an open connection or stream before HAProxy
    # closes it: a game paused longer than this reconnects (its session waits for it), s. [1, 86400]
    idle_timeout_s: float = 600.0
    connect_timeout_s: float = 1.0  # a loopback or LAN connect takes far less; more means the node is gone, s
    # Data sent to a node and not acknowledged this long closes HAProxy's connection to it (`tcp-ut`,
    # TCP_USER_TIMEOUT). A node gone without a word (its container killed, its machine lost) sends
    # no reset: without this its connections look open for the kernel's retransmission timeout,
    # about 15 minutes, and a stream HAProxy puts on one waits that long unanswered. Under the
    # SDK's frame_timeout_s (3 s), so the SDK's next try finds the connection gone; a live node's
    # kernel acknowledges within milliseconds however busy the node, s. [0.5, 60]
    unacknowledged_timeout_s: float = 2.0
    # The name every node's certificate holds, which HAProxy checks (verifyhost); deploy/tls.py's
    # certificates hold "localhost" and 127.0.0.1, and HAProxy checks a name only.
    node_tls_name: str = "localhost"

    def __post_init__(self):
        checks = [
            (0.05 <= self.check_interval_s <= 60, "check_interval_s must be in [0.05, 60]"),
            (0.05 <= self.check_fast_interval_s <= 60, "check_fast_interval_s must be in [0.05, 60]"),
            (0.05 <= self.check_timeout_s <= 60, "check_timeout_s must be in [0.05, 60]"),
            (1 <= self.fall <= 100 and 1 <= self.rise <= 100, "fall and rise must be in [1, 100]"),
            (1 <= self.hard_stop_after_s <= 3600, "hard_stop_after_s must be in [1, 3600]"),
            (1 <= self.weight <= 256, "weight must be in [1, 256] (HAProxy's range)"),
            (1 <= self.idle_timeout_s <= 86_400, "idle_timeout_s must be in [1, 86400]"),
            (0.05 <= self.connect_timeout_s <= 60, "connect_timeout_s must be in [0.05, 60]"),
            (0.5 <= self.unacknowledged_timeout_s <= 60, "unacknowledged_timeout_s must be in [0.5, 60]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)


@dataclass(frozen=True)
class Backend:
    """One node as the balancer sees it."""

    name: str  # the server's name in both backends, e.g. "node-1"
    server_id: int  # HAProxy's server id: a node's points on the hash ring are derived from it alone,
    # so the same id gives the same sessions on every balancer and after a restart
    grpc: str  # the node's gRPC HOST:PORT
    http: str  # the node's HTTP HOST:PORT
    live_port: int  # the node's liveness port (`serve --live`), on the same host: both backends' checks


# Both backends' check: GET /live as HTTP/1.1 over TLS. `connect default` takes the server's address,
# `port` and TLS; `proto h1` because the gRPC backend's `proto h2` would otherwise carry its checks too.
LIVE_CHECK = [
    "    option httpchk",
    "    http-check connect default proto h1",
    "    http-check send meth GET uri /live",
    "    http-check expect status 200",
]


def _ms(seconds: float) -> str:
    """A duration as HAProxy reads it: whole seconds as "600s", others in milliseconds."""
    return f"{round(seconds)}s" if seconds == round(seconds) else f"{round(seconds * 1000)}ms"


def _server_args(s: BalancerSettings, tls: TlsFiles, grpc: bool, dynamic: bool = False) -> str:
    """A node's TLS, health check and weight, all nodes the same: the traffic and the checks over TLS
    to a node that proves itself with the CA's certificate, gRPC's traffic (`grpc`) as HTTP/2, the
    checks as HTTP/1.1 to its liveness port (`_server_line` names it). A node marked down has its open streams cut
    (`on-marked-down shutdown-sessions`): a stream on a hung node would otherwise wait for it as long
    as it hangs; cut, the SDK opens it again through the balancer, which sends it to a live node
    (that restores the session from its checkpoint). A connection to a node that vanished is closed
    once what was sent on it goes unacknowledged (`tcp-ut`, BalancerSettings.unacknowledged_timeout_s),
    except on a node added while HAProxy runs (`dynamic`): HAProxy 2.6 refuses `tcp-ut` there."""
    args = (
        f"ssl verify required ca-file {tls.ca_cert} verifyhost {s.node_tls_name} "
        f"check check-ssl inter {_ms(s.check_interval_s)} fastinter {_ms(s.check_fast_interval_s)} "
        f"downinter {_ms(s.check_interval_s)} fall {s.fall} rise {s.rise} weight {s.weight} "
        "on-marked-down shutdown-sessions"
    )
    if not dynamic:
        args += f" tcp-ut {_ms(s.unacknowledged_timeout_s)}"
    return args + " proto h2 alpn h2" if grpc else args


def _server_line(backend: Backend, grpc: bool) -> str:
    """What `server` (or `add server`) says of one node in one backend beyond `_server_args`: its
    name, address, ring id and the port its checks go to (`port`)."""
    address = backend.grpc if grpc else backend.http
    return f"{backend.name} {address} id {backend.server_id} port {backend.live_port}"


# Where a node's address changes (a container started again), HAProxy 2.6 went on connecting to a
# restarted node's old address through the idle connections its nodes share: after 19 of 34
# restarts in the container cluster that node took no new session, each one sent there
# waiting out the connect timeout and going elsewhere. Kept with the client connection that opened
# them, connections end with it; a unary Frame's round trip measured the same (2.27 ms p50).
REUSE_PER_CLIENT = ["    http-reuse never"]


def render_config(
    settings: BalancerSettings,
    backends: list[Backend],
    *,
    tls: TlsFiles,
    stats_socket: str,
    grpc_port: int,
    http_port: int,
    resolvers: bool = False,
    user: str = "",
) -> str:
    """haproxy.cfg for these nodes, its frontends presenting `tls.bundle`, the nodes checked against
    `tls.ca_cert`. `resolvers`: node names are found again while it runs, through the nameservers of
    its /etc/resolv.conf: names that only a container network's DNS knows, and whose address
    changes when a container starts again (docker/compose.cluster.yaml); `user` ("" to stay who
    started it) the user HAProxy becomes once it has read its files."""
    grpc_server, http_server = _server_args(settings, tls, grpc=True), _server_args(settings, tls, grpc=False)
    if resolvers:
        # a name that does not resolve yet (its container is starting) leaves that node down, not HAProxy
        dns = " resolvers dns init-addr last,libc,none"
        grpc_server, http_server = grpc_server + dns, http_server + dns
    lines = [
        "# Written by camdirector.deploy.haproxy; see docs/scaling.md.",
        "global",
        f"    stats socket {stats_socket} mode 600 level admin",
        # node up/down and abnormal requests only: a 60 Hz stream must not write a line per frame
        "    log stderr format raw local0 notice",
        f"    hard-stop-after {_ms(settings.hard_stop_after_s)}",
        *([f"    user {user}", f"    group {user}"] if user else []),
        "",
    ]
    if resolvers:
        # Docker's resolv.conf names its DNS at 127.0.0.11, podman's the network's gateway: the file works on both
        lines += ["resolvers dns", "    parse-resolv-conf", "    hold valid 10s", ""]
    lines += [
        "defaults",
        "    mode http",
        "    log global",
        "    option httplog",
        "    option dontlog-normal",
        f"    timeout connect {_ms(settings.connect_timeout_s)}",
        f"    timeout client {_ms(settings.idle_timeout_s)}",
        f"    timeout server {_ms(settings.idle_timeout_s)}",
        f"    timeout check {_ms(settings.check_timeout_s)}",
        "    timeout http-request 10s",
        # a node that died since its last check refuses the connection: try it once more, then
        # another node (which restores the session from the checkpoint store)
        "    retries 2",
        "    option redispatch 1",
        *(REUSE_PER_CLIENT if resolvers else []),
        "",
        "frontend grpc",
        f"    bind {settings.host}:{grpc_port} ssl crt {tls.bundle} alpn h2",
        f"    default_backend {GRPC_BACKEND}",
        "",
        f"backend {GRPC_BACKEND}",
        f"    balance hdr({ROUTE_HEADER})",
        "    hash-type consistent",
        *LIVE_CHECK,
        f"    default-server {grpc_server}",
        *(f"    server {_server_line(b, grpc=True)}" for b in backends),
        "",
        "frontend http",
        f"    bind {settings.host}:{http_port} ssl crt {tls.bundle}",
        f"    default_backend {HTTP_BACKEND}",
        "",
        f"backend {HTTP_BACKEND}",
        f"    balance hdr({ROUTE_HEADER})",
        "    hash-type consistent",
        *LIVE_CHECK,
        f"    default-server {http_server}",
        *(f"    server {_server_line(b, grpc=False)}" for b in backends),
        "",
    ]
    return "\n".join(lines)


class RuntimeApi:
    """A running HAProxy's runtime API on the unix socket `socket_path` (management.txt section 9.3):
    the one this module starts, or one in a container (deploy/compose.py)."""

    def __init__(self, socket_path: Path):
        self.socket_path = Path(socket_path)

    def failure_context(self) -> str:
        """What an error about this HAProxy adds (its log's tail, where there is one)."""
        return ""

    def command(self, line: str, timeout_s: float = 5.0) -> str:
        """One runtime API command; returns HAProxy's answer."""
        with socket.socket(socket.AF_UNIX) as sock:
            sock.settimeout(timeout_s)
            sock.connect(str(self.socket_path))
            sock.sendall(line.encode() + b"\n")
            chunks = []
            while chunk := sock.recv(65536):  # HAProxy closes after one answer (non-interactive mode)
                chunks.append(chunk)
        return b"".join(chunks).decode(errors="replace")

    def server_states(self) -> dict[str, dict[str, str]]:
        """{backend: {server: status}}, status as `show stat` writes it: "UP", "DOWN", "UP 1/2"
        (going down), "DOWN 1/2" (going up), "MAINT"; "UP" only once a check has passed."""
        rows = csv.DictReader(self.command("show stat").lstrip("# ").splitlines())
        states: dict[str, dict[str, str]] = {}
        for row in rows:
            if row["svname"] in ("FRONTEND", "BACKEND"):
                continue
            # a server starts UP before its first check; trust UP only after a passed check
            passed = row["check_status"].lstrip("* ") == "L7OK"  # the gRPC or HTTP answer itself, not a connect
            status = row["status"] if passed or row["status"] != "UP" else "UP (not checked yet)"
            states.setdefault(row["pxname"], {})[row["svname"]] = status
        return states

    def wait_until(
        self, expected: dict[str, str], timeout_s: float = 30.0, backends: tuple[str, ...] = (GRPC_BACKEND, HTTP_BACKEND)
    ) -> float:
        """Waits until every named server has the given status ("UP" or "DOWN") in `backends`;
        returns the seconds it took. ServiceError after timeout_s."""
        start = time.monotonic()
        while True:
            states = self.server_states()
            wrong = {
                (backend, name): states.get(backend, {}).get(name)
                for backend in backends
                for name, status in expected.items()
                if states.get(backend, {}).get(name) != status
            }
            if not wrong:
                return time.monotonic() - start
            if time.monotonic() - start > timeout_s:
                raise ServiceError(
                    f"haproxy: after {timeout_s:g} s, servers not as expected {expected}: {wrong}; {self.failure_context()}"
                )
            time.sleep(0.05)


class HAProxy(RuntimeApi):
    """haproxy on `settings.host`, configured for `backends`, its runtime API on a unix socket in
    `folder`, TLS with `tls` (the module docstring). A child in a session of its own: it outlives
    the process that started it (the cluster's `up` returns); `pid` is what stops it."""

    def __init__(self, folder: Path, tls: TlsFiles, settings: BalancerSettings = BalancerSettings()):
        self.folder = Path(folder)
        self.tls = tls
        self.settings = settings
        self.grpc_port = settings.grpc_port or free_port()
        self.http_port = settings.http_port or free_port()
        super().__init__(self.folder / "haproxy.sock")
        self.config_path = self.folder / "haproxy.cfg"
        self.log_path = self.folder / "haproxy.log"
        self.backends: list[Backend] = []
        self.pid: int | None = None
        self.proc: subprocess.Popen | None = None  # None where another process started it
        if len(str(self.socket_path).encode()) > UNIX_PATH_MAX:
            raise ServiceError(
                f"the runtime API socket's path {self.socket_path} is longer than "
                f"{UNIX_PATH_MAX} bytes: use a shorter cluster folder"
            )

    @property
    def grpc(self) -> str:
        return f"{self.settings.host}:{self.grpc_port}"

    @property
    def http(self) -> str:
        return f"{self.settings.host}:{self.http_port}"

    def _write_config(self) -> None:
        self.config_path.write_text(
            render_config(
                self.settings,
                self.backends,
                tls=self.tls,
                stats_socket=str(self.socket_path),
                grpc_port=self.grpc_port,
                http_port=self.http_port,
            )
        )

    def start(self, backends: list[Backend], timeout_s: float = 10.0) -> HAProxy:
        """Writes the configuration, checks it (`haproxy -c`) and starts HAProxy; returns once
        both frontends listen (the nodes' health is `wait_healthy`'s)."""
        binary = _binary("haproxy", "haproxy", Path("/usr/sbin"))
        self.folder.mkdir(parents=True, exist_ok=True)
        self.backends = list(backends)
        self._write_config()
        checked = subprocess.run([binary, "-c", "-q", "-f", str(self.config_path)], capture_output=True, text=True)
        if checked.returncode != 0:
            raise ServiceError(f"haproxy rejected {self.config_path}: {checked.stderr[-2000:]}")
        with open(self.log_path, "ab") as log:
            self.proc = subprocess.Popen(
                [binary, "-f", str(self.config_path)], stdin=subprocess.DEVNULL, stdout=log, stderr=log, start_new_session=True
            )
        self.pid = self.proc.pid
        deadline = time.monotonic() + timeout_s
        _wait_port(self.grpc_port, self.proc, timeout_s, "haproxy", self.log_path)
        _wait_port(self.http_port, self.proc, timeout_s, "haproxy", self.log_path)
        self._wait_runtime_api(deadline)
        return self

    def _wait_runtime_api(self, deadline: float) -> None:
        """Waits until the runtime API's socket takes a connection: HAProxy binds it after the
        frontends (on a loaded CI machine a cluster's first `show stat` came before the socket
        existed: FileNotFoundError at connect). ServiceError at the deadline (time.monotonic)."""
        assert self.proc is not None  # started
        while True:
            if self.proc.poll() is not None:
                raise ServiceError(f"haproxy exited with code {self.proc.returncode}: {_tail(self.log_path)}")
            try:
                with socket.socket(socket.AF_UNIX) as sock:
                    sock.settimeout(0.2)
                    sock.connect(str(self.socket_path))
                return
            except OSError:
                if time.monotonic() > deadline:
                    raise ServiceError(
                        f"haproxy's runtime API {self.socket_path} took no connection: {_tail(self.log_path)}"
                    ) from None
                time.sleep(0.05)

    def failure_context(self) -> str:
        return _tail(self.log_path)

    def add(self, backend: Backend) -> None:
        """Adds a node to the running HAProxy through its runtime API: no reload, every open
        connection and stream stays where it is, and only the keys nearest to the new node's
        points on the ring move to it. The configuration file is rewritten too, so a restart of
        HAProxy keeps the node."""
        if any(b.name == backend.name or b.server_id == backend.server_id for b in self.backends):
            raise ServiceError(f"haproxy: a server named {backend.name} or with id {backend.server_id} exists")
        # a dynamic server takes nothing from `default-server`: the same arguments (but tcp-ut), spelt out
        for name, grpc in ((GRPC_BACKEND, True), (HTTP_BACKEND, False)):
            answer = self.command(
                f"add server {name}/{_server_line(backend, grpc)} {_server_args(self.settings, self.tls, grpc, dynamic=True)}"
            )
            if "New server registered" not in answer:
                raise ServiceError(f"haproxy: add server {name}/{backend.name}: {answer.strip()}")
            for verb in ("enable health", "enable server"):
                self.command(f"{verb} {name}/{backend.name}")
        self.backends.append(backend)
        self._write_config()

    def stop(self) -> None:
        if self.pid is not None:
            stop_processes([(self.pid, str(self.config_path))], timeout_s=5.0)


# Where docker/compose.cluster.yaml mounts the files of `python -m camdirector.deploy.tls docker/tls`.
COMPOSE_TLS_DIR = Path("/etc/camdirector/tls")
COMPOSE_LIVE_PORT = 8081  # each node container's liveness port (`serve --live 0.0.0.0:8081`), not published


def compose_config(nodes: int) -> str:
    """haproxy.cfg for docker/compose.cluster.yaml: services node-1..node-N (gRPC on 50051, HTTP on
    8080, liveness on COMPOSE_LIVE_PORT) found through the container network's DNS; the balancer on
    50051 and 8080 of its container. HAProxy starts as root there to read the bundle (its key is its
    owner's alone, mode 0600), then becomes the image's `haproxy` user."""
    backends = [Backend(f"node-{k}", k, f"node-{k}:50051", f"node-{k}:8080", COMPOSE_LIVE_PORT) for k in range(1, nodes + 1)]
    return render_config(
        BalancerSettings(host="0.0.0.0"),
        backends,
        tls=files_in(COMPOSE_TLS_DIR),
        stats_socket="/tmp/haproxy.sock",
        grpc_port=50051,
        http_port=8080,
        resolvers=True,
        user="haproxy",
    )


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="print docker/haproxy.cluster.cfg, docker/compose.cluster.yaml's haproxy.cfg")
    parser.add_argument("--compose-nodes", type=int, default=3, help="node services node-1..node-N")
    print(compose_config(parser.parse_args().compose_nodes), end="")
