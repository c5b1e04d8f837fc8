"""The multi-node topology on one machine, on loopback ports, from Debian's packages and the venv:
Redis (session checkpoints, the job queue), PostgreSQL (job and level records, and the API keys),
N nodes (`camdirector serve`, sharing one data folder), queue workers (`camdirector job-worker`)
and HAProxy in front (deploy/haproxy.py). docs/scaling.md describes it.

It runs as a cluster should be deployed: every node checks keys (docs/security.md), and every
hop is TLS. `up` makes a CA and a certificate for 127.0.0.1 and localhost in DIR/tls
(deploy/tls.py), which the balancer and every node present; clients connect to the balancer with
grpcs:// and https:// trusting DIR/tls/ca.pem (`ca_file`). The nodes share the keys through
PostgreSQL: node-1 starts alone and, finding no key, makes the admin key (DIR/data/admin.key,
`admin_key_file`) and the ZeroMQ CURVE key pair in the data folder; the others start once it is
ready, and find both (nodes started together would each make their own).

    python -m camdirector.deploy.cluster up --nodes N [--dir DIR]   (scripts/cluster.sh up ...)
    python -m camdirector.deploy.cluster down [--dir DIR]
    python -m camdirector.deploy.cluster add-node [--dir DIR]
    python -m camdirector.deploy.cluster status [--dir DIR]

`up` prints one JSON object (the balancer's `grpc` and `http`, `nodes`, `redis`, `postgres`,
`ca_file`, `admin_key_file` (a path: the key itself is never printed), `zmq_server_key`, ...) and
returns with everything running; the same object is kept in DIR/cluster.json, which `down`,
`add-node` and `status` read. From Python, `Cluster.up(nodes, folder)` gives the same cluster with
`kill_node`, `restart_node`, `add_node` and `down` (the failover benchmark's handle), and the
faults of load_tests/chaos.py: `pause`/`resume` (SIGSTOP/SIGCONT) of Redis, PostgreSQL or a node,
`stop_redis`/`start_redis` and `stop_postgres`/`start_postgres` keeping their data, and
`kill_balancer`/`start_balancer` (the same configuration and ports).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

from camdirector.access.keys import ADMIN_KEY_FILE
from camdirector.deploy.haproxy import Backend, BalancerSettings, HAProxy
from camdirector.deploy.services import (
    PostgresServer,
    RedisServer,
    ServiceError,
    _tail,
    descendants,
    is_running,
    signal_tree,
    stop_processes,
)
from camdirector.deploy.tls import TlsFiles, make_tls_files

DEFAULT_FOLDER = Path("/tmp/camdirector-cluster")
STATE_FILE = "cluster.json"


class ClusterError(RuntimeError):
    """A cluster that cannot start or be found."""


@dataclass(frozen=True)
class ClusterSettings:
    # Worker processes per node. On one machine every node shares its cores, so one each by
    # default; on a machine of its own a node wants one per core (serve's default). [0, 256]
    workers_per_node: int = 1
    # `camdirector job-worker` processes taking jobs off the Redis queue (started only where that
    # command exists). [0, 64]
    queue_workers: int = 1
    start_timeout_s: float = 60.0  # the longest one node may take to print its ready line, s. [1, 600]
    healthy_timeout_s: float = 30.0  # the longest HAProxy may take to see every node healthy, s. [1, 600]
    node_args: tuple[str, ...] = ()  # more `camdirector serve` flags for every node (e.g. --max-sessions 128)
    balancer: BalancerSettings = field(default_factory=BalancerSettings)

    def __post_init__(self):
        checks = [
            (0 <= self.workers_per_node <= 256, "workers_per_node must be in [0, 256]"),
            (0 <= self.queue_workers <= 64, "queue_workers must be in [0, 64]"),
            (1 <= self.start_timeout_s <= 600, "start_timeout_s must be in [1, 600]"),
            (1 <= self.healthy_timeout_s <= 600, "healthy_timeout_s must be in [1, 600]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ClusterSettings:
        return cls(**{**d, "node_args": tuple(d["node_args"]), "balancer": BalancerSettings(**d["balancer"])})


@dataclass(frozen=True)
class NodeInfo:
    node_id: str  # "node-K", its --node-id and its server name in HAProxy
    server_id: int  # K: HAProxy's server id, which places the node on the hash ring
    pid: int  # the node's `camdirector serve` (front) process
    grpc: str  # HOST:PORT
    http: str  # HOST:PORT
    zmq: str  # tcp://HOST:PORT, for ZeroMQ clients, which connect to a node directly
    live: str  # HOST:PORT of its liveness port, which the balancer checks (front/live_check.py)

    @property
    def backend(self) -> Backend:
        live_port = int(self.live.rpartition(":")[2])
        return Backend(name=self.node_id, server_id=self.server_id, grpc=self.grpc, http=self.http, live_port=live_port)


def _serve_command() -> list[str]:
    return [sys.executable, "-m", "camdirector.__main__"]  # this venv's camdirector


class Cluster:
    """A running cluster, its state in `folder`/cluster.json. Make one with `up` or `attach`."""

    def __init__(self, folder: Path, settings: ClusterSettings, state: dict):
        self.folder = Path(folder)
        self.settings = settings
        self.state = state
        # the processes this object started: held so that none is collected while it runs (Popen
        # warns then), and reaped by `down`; a cluster attached to holds none
        self._children: list[subprocess.Popen] = []
        balancer = state.get("balancer")
        self.haproxy: HAProxy | None = None
        if balancer is not None:
            self.haproxy = HAProxy(
                self.folder,
                self.tls,
                dataclasses.replace(settings.balancer, grpc_port=balancer["grpc_port"], http_port=balancer["http_port"]),
            )
            self.haproxy.pid = balancer["pid"]  # started by another process: known by its pid alone
            self.haproxy.backends = [n.backend for n in self.nodes]

    # What the cluster is -------------------------------------------------------------------------
    @property
    def nodes(self) -> list[NodeInfo]:
        return [NodeInfo(**n) for n in self.state.get("nodes", [])]

    @property
    def grpc(self) -> str:
        """The balancer's gRPC HOST:PORT."""
        return self.state["grpc"]

    @property
    def http(self) -> str:
        """The balancer's HTTP HOST:PORT (REST)."""
        return self.state["http"]

    @property
    def redis(self) -> str:
        return self.state["redis"]

    @property
    def postgres(self) -> str:
        return self.state["postgres"]

    @property
    def data_dir(self) -> Path:
        """The data folder every node and queue worker shares (uploads, artifacts, levels)."""
        return self.folder / "data"

    @property
    def tls(self) -> TlsFiles:
        """The CA, and the certificate the balancer and every node present."""
        return TlsFiles(*(Path(p) for p in self.state["tls"]))

    @property
    def ca_file(self) -> Path:
        """What a client trusts to reach the balancer or a node."""
        return self.tls.ca_cert

    @property
    def admin_key(self) -> str:
        """The admin key of tenant `default`, read from its file (mode 0600)."""
        return Path(self.state["admin_key_file"]).read_text().strip()

    @property
    def zmq_server_key(self) -> str:
        """The nodes' CURVE public key (Z85), which a ZeroMQ client needs (`zmq_server_key`)."""
        return self.state["zmq_server_key"]

    def as_dict(self) -> dict:
        """What `up` prints: the state less its bookkeeping (pids of services, settings, the TLS files)."""
        private = ("settings", "balancer", "redis_pid", "postgres_folder", "postgres_port", "tls")
        return {k: v for k, v in self.state.items() if k not in private}

    def _save(self) -> None:
        tmp = self.folder / (STATE_FILE + ".tmp")
        tmp.write_text(json.dumps(self.state, indent=1))
        tmp.replace(self.folder / STATE_FILE)

    # Starting and stopping -------------------------------------------------------------------------
    @classmethod
    def up(cls, nodes: int = 2, folder: Path = DEFAULT_FOLDER, settings: ClusterSettings = ClusterSettings()) -> Cluster:
        """Starts Redis, PostgreSQL, `nodes` nodes, the queue workers and HAProxy; returns once
        HAProxy has seen every node pass a health check. Whatever started is stopped again when
        a part fails (ClusterError or ServiceError, with the failing part's log)."""
        if not 1 <= nodes <= 256:
            raise ValueError("nodes must be in [1, 256]")
        folder = Path(folder).resolve()
        if (folder / STATE_FILE).exists():
            old = cls.attach(folder)
            if old.running_pids():
                raise ClusterError(
                    f"a cluster already runs in {folder} (pids {old.running_pids()}): scripts/cluster.sh down --dir {folder}"
                )
            old.down()  # what is left of one that died: its PostgreSQL, its state file
        folder.mkdir(parents=True, exist_ok=True)
        started = time.monotonic()
        cluster = cls(
            folder,
            settings,
            {"folder": str(folder), "nodes": [], "queue_workers": [], "notes": [], "settings": settings.as_dict()},
        )
        try:
            cluster._start(nodes)
        except BaseException:
            cluster.down()
            raise
        cluster.state["up_s"] = round(time.monotonic() - started, 2)
        cluster._save()
        return cluster

    def _start(self, nodes: int) -> None:
        # whether this checkout has `camdirector job-worker` (the Redis queue's worker), found meanwhile
        has_job_worker = subprocess.Popen(
            [*_serve_command(), "job-worker", "--help"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        self._children.append(has_job_worker)
        redis = RedisServer(self.folder / "redis", persist=True).start()
        assert redis.proc is not None  # start() launched it
        self._children.append(redis.proc)
        self.state.update(redis=redis.url, job_queue=redis.url.rpartition("/")[0] + "/1", redis_pid=redis.proc.pid)
        self._save()
        postgres = PostgresServer(self.folder / "postgres")
        self.state.update(postgres=postgres.url, postgres_folder=str(postgres.folder), postgres_port=postgres.port)
        self._save()
        postgres.start()
        tls = make_tls_files(self.folder / "tls")
        self.state.update(tls=[str(p) for p in dataclasses.astuple(tls)], ca_file=str(tls.ca_cert))
        has_queue_workers = has_job_worker.wait(60) == 0
        if not has_queue_workers:
            self.state["notes"].append("no queue workers: this checkout has no `camdirector job-worker`")
        self.data_dir.mkdir(exist_ok=True)
        # node-1 first: it makes the admin key and the CURVE key pair (the module docstring)
        for numbers in ([1], range(2, nodes + 1)):
            for node in self._start_nodes(numbers):
                self.state["nodes"].append(dataclasses.asdict(node))
        self._save()
        if has_queue_workers:
            for k in range(1, self.settings.queue_workers + 1):
                self.state["queue_workers"].append({"pid": self._start_queue_worker(k).pid})
        self._save()
        self.haproxy = haproxy = HAProxy(self.folder, tls, self.settings.balancer).start([n.backend for n in self.nodes])
        assert haproxy.proc is not None  # start() launched it
        self._children.append(haproxy.proc)
        self.state.update(
            grpc=haproxy.grpc,
            http=haproxy.http,
            balancer={
                "pid": haproxy.pid,
                "grpc_port": haproxy.grpc_port,
                "http_port": haproxy.http_port,
                "config": str(haproxy.config_path),
                "socket": str(haproxy.socket_path),
            },
        )
        self._save()
        haproxy.wait_until({n.node_id: "UP" for n in self.nodes}, self.settings.healthy_timeout_s)

    def _start_nodes(self, numbers, addresses: NodeInfo | None = None) -> list[NodeInfo]:
        """Starts nodes node-K for K in numbers all at once; returns them once each is ready.
        `addresses`: the one node of `numbers` listens where this one did (a restart)."""
        launched = []
        for k in numbers:
            name = f"node-{k}"
            out, log = self.folder / f"{name}.out", self.folder / f"{name}.log"
            out.unlink(missing_ok=True)  # a restarted node's ready line is a new one
            cmd = [
                *_serve_command(),
                "serve",
                "--grpc",
                addresses.grpc if addresses else "127.0.0.1:0",
                "--zmq",
                addresses.zmq if addresses else "tcp://127.0.0.1:*",
                "--http",
                addresses.http if addresses else "127.0.0.1:0",
                "--live",
                addresses.live if addresses else "127.0.0.1:0",
                "--workers",
                str(self.settings.workers_per_node),
                "--node-id",
                name,
                "--data-dir",
                str(self.data_dir),
                "--tls-cert",
                str(self.tls.cert),
                "--tls-key",
                str(self.tls.key),
                "--checkpoint-store",
                self.state["redis"],
                "--job-store",
                self.state["postgres"],
                "--job-queue",
                self.state["job_queue"],
                *self.settings.node_args,
            ]
            # stdout to a file, not a pipe: the node outlives this process, and a pipe would close
            with open(out, "wb") as stdout, open(log, "ab") as stderr:
                proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=stdout, stderr=stderr, start_new_session=True)
            self._children.append(proc)
            launched.append((k, name, proc, out, log))
        nodes = []
        for k, name, proc, out, log in launched:
            try:
                ready = self._wait_ready(proc, out, log, name)
                self._check_access(name, ready)
            except ClusterError:
                for _, _, other, _, _ in launched:
                    other.kill()
                    other.wait()
                raise
            nodes.append(
                NodeInfo(
                    node_id=name,
                    server_id=k,
                    pid=proc.pid,
                    grpc=ready["grpc"],
                    http=ready["http"],
                    zmq=ready["zmq"],
                    live=ready["live"],
                )
            )
        return nodes

    def _check_access(self, name: str, ready: dict) -> None:
        """Notes the admin key's file and the CURVE key the first node announces; ClusterError
        when a node serves without TLS or keys, or with another CURVE key than its peers (ZeroMQ
        clients of the cluster know one)."""
        if not (ready.get("tls") and ready.get("auth")):
            raise ClusterError(f"{name} serves without TLS or without keys: {ready}")
        self.state.setdefault("zmq_server_key", ready["zmq_server_key"])
        if ready["zmq_server_key"] != self.state["zmq_server_key"]:
            raise ClusterError(
                f"{name} announces the CURVE key {ready['zmq_server_key']}, its peers "
                f"{self.state['zmq_server_key']}: their shared data folder's zmq/ was made twice"
            )
        key_file = ready.get("admin_key_file", self.state.get("admin_key_file"))
        if key_file is None:  # a folder used before: PostgreSQL kept its keys, the data folder the file
            key_file = str(self.data_dir / ADMIN_KEY_FILE)
            if not Path(key_file).is_file():
                raise ClusterError(
                    f"the keys in {self.state['postgres']} include an admin key, but {key_file} "
                    f"is gone: scripts/cluster.sh down, then remove {self.folder}"
                )
        self.state["admin_key_file"] = key_file

    def _wait_ready(self, proc: subprocess.Popen, out: Path, log: Path, name: str) -> dict:
        deadline = time.monotonic() + self.settings.start_timeout_s
        while time.monotonic() < deadline:
            for line in out.read_text().splitlines():
                if line.startswith("{") and json.loads(line).get("event") == "ready":
                    return json.loads(line)
            if proc.poll() is not None:
                raise ClusterError(f"{name} exited with code {proc.returncode}: {_tail(log)}")
            time.sleep(0.05)
        raise ClusterError(f"{name} printed no ready line within {self.settings.start_timeout_s:g} s: {_tail(log)}")

    def _start_queue_worker(self, k: int) -> subprocess.Popen:
        with open(self.folder / f"queue-worker-{k}.log", "ab") as log:
            proc = subprocess.Popen(
                [
                    *_serve_command(),
                    "job-worker",
                    "--job-queue",
                    self.state["job_queue"],
                    "--job-store",
                    self.state["postgres"],
                    "--data-dir",
                    str(self.data_dir),
                ],
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=log,
                start_new_session=True,
            )
        self._children.append(proc)
        return proc

    def _processes(self) -> list[tuple[int, str]]:
        """(pid, marker) of every process of the cluster but PostgreSQL, the marker a part of its
        command line that no other process has: the cluster's folder, or for redis-server (which
        rewrites its command line to its address) that address."""
        pids = [n["pid"] for n in self.state.get("nodes", [])] + [w["pid"] for w in self.state.get("queue_workers", [])]
        if "balancer" in self.state:
            pids.append(self.state["balancer"]["pid"])
        processes = [(pid, str(self.folder)) for pid in pids]
        if "redis_pid" in self.state:
            processes.append((self.state["redis_pid"], f"redis-server {urlsplit(self.state['redis']).netloc}"))
        return processes

    def running_pids(self) -> list[int]:
        return [pid for pid, marker in self._processes() if is_running(pid, marker)]

    def down(self) -> None:
        """Stops every process of the cluster (SIGTERM, SIGKILL after 15 s) and PostgreSQL, and
        removes the state file; the logs stay in the folder. The nodes' own processes (workers,
        job forkserver) end with their node; any still running 5 s after it are stopped too."""
        processes = self._processes()
        below = descendants([pid for pid, marker in processes if is_running(pid, marker)])
        stop_processes(processes)
        stop_processes([(pid, "") for pid in below], grace_s=5.0)
        if "postgres_folder" in self.state:
            PostgresServer(Path(self.state["postgres_folder"]), self.state["postgres_port"], existing=True).stop()
        (self.folder / STATE_FILE).unlink(missing_ok=True)

    @classmethod
    def attach(cls, folder: Path = DEFAULT_FOLDER) -> Cluster:
        """The cluster whose state is in folder/cluster.json (started by another process)."""
        folder = Path(folder).resolve()
        try:
            state = json.loads((folder / STATE_FILE).read_text())
        except FileNotFoundError:
            raise ClusterError(f"no cluster in {folder} (no {STATE_FILE})") from None
        return cls(folder, ClusterSettings.from_dict(state["settings"]), state)

    # Changing it -----------------------------------------------------------------------------------
    def kill_node(self, index: int, sig: int = signal.SIGKILL) -> int:
        """Sends `sig` to node `index`'s serve process (0-based, in `nodes`' order); returns its
        pid. The node stays in the balancer, whose health checks mark it down."""
        pid = self.nodes[index].pid
        os.kill(pid, sig)
        try:
            os.waitpid(pid, 0)  # our child when this process started the cluster
        except ChildProcessError:
            pass
        return pid

    def restart_node(self, index: int) -> NodeInfo:
        """Starts node `index` again (after `kill_node`) on the same ports, as its host's
        supervisor would; returns it once HAProxy has seen it healthy."""
        old = self.nodes[index]
        if is_running(old.pid, str(self.folder)):
            raise ClusterError(f"{old.node_id} still runs (pid {old.pid}): kill it first")
        (node,) = self._start_nodes([old.server_id], addresses=old)
        self.state["nodes"][index] = dataclasses.asdict(node)
        self._save()
        if self.haproxy is not None:
            self.haproxy.wait_until({node.node_id: "UP"}, self.settings.healthy_timeout_s)
        return node

    def pause(self, part: str) -> list[int]:
        """SIGSTOPs "redis", "postgres" or a node ("node-K") with every process below it: a hung
        process or machine, whose connections stay open and silent. Returns the pids; `resume`."""
        return signal_tree([self._pid_of(part)], signal.SIGSTOP)

    def resume(self, part: str) -> list[int]:
        """SIGCONTs what `pause(part)` stopped (the processes below it as they are now)."""
        return signal_tree([self._pid_of(part)], signal.SIGCONT)

    def _pid_of(self, part: str) -> int:
        if part == "redis":
            return self.state["redis_pid"]
        if part == "postgres":
            pid = self._postgres().postmaster_pid()
            if pid is None:
                raise ClusterError(f"PostgreSQL of {self.folder} does not run")
            return pid
        for node in self.nodes:
            if node.node_id == part:
                return node.pid
        raise ValueError(f"no part {part!r}: redis, postgres or one of {[n.node_id for n in self.nodes]}")

    def _postgres(self) -> PostgresServer:
        return PostgresServer(Path(self.state["postgres_folder"]), self.state["postgres_port"], existing=True)

    def stop_redis(self) -> None:
        """Stops Redis (SIGTERM: it writes its append-only file out); `start_redis` brings it back."""
        signal_tree([self.state["redis_pid"]], signal.SIGCONT)  # a paused Redis cannot act on SIGTERM
        stop_processes([(self.state["redis_pid"], f"redis-server {urlsplit(self.redis).netloc}")], timeout_s=5.0)

    def start_redis(self) -> None:
        """Starts Redis again on its port, from its append-only file (the checkpoints and the job
        queue it held at `stop_redis`, up to the last second's writes)."""
        redis = RedisServer(self.folder / "redis", urlsplit(self.redis).port or 0, persist=True).start()
        assert redis.proc is not None  # start() launched it
        self._children.append(redis.proc)
        self.state["redis_pid"] = redis.proc.pid
        self._save()

    def stop_postgres(self) -> None:
        """Stops PostgreSQL (fast shutdown), keeping its data; `start_postgres` brings it back."""
        self._postgres().stop(keep_data=True)

    def start_postgres(self) -> None:
        """Starts PostgreSQL again on its port, with the data it had."""
        self._postgres().start()

    def kill_balancer(self) -> None:
        """SIGKILLs HAProxy: every client connection through it breaks at once."""
        balancer = self.balancer()
        assert balancer.pid is not None  # started or attached: it has one
        os.kill(balancer.pid, signal.SIGKILL)
        try:
            os.waitpid(balancer.pid, 0)
        except ChildProcessError:
            pass  # started by another process

    def start_balancer(self) -> None:
        """Starts HAProxy again with the same configuration and ports (after `kill_balancer`);
        returns once it listens."""
        balancer = self.balancer()
        balancer.start(balancer.backends)
        assert balancer.proc is not None  # start() launched it
        self._children.append(balancer.proc)
        self.state["balancer"]["pid"] = balancer.pid
        self._save()

    def add_node(self) -> NodeInfo:
        """Starts one more node and adds it to the running HAProxy (runtime API, no reload: every
        open stream stays where it is); returns it once HAProxy has seen it healthy."""
        (node,) = self._start_nodes([max(n.server_id for n in self.nodes) + 1])
        self.state["nodes"].append(dataclasses.asdict(node))
        self._save()
        balancer = self.balancer()
        balancer.add(node.backend)
        balancer.wait_until({node.node_id: "UP"}, self.settings.healthy_timeout_s)
        return node

    def balancer(self) -> HAProxy:
        """The cluster's HAProxy; ClusterError for a cluster that never got as far as starting it."""
        if self.haproxy is None:
            raise ClusterError(f"the cluster in {self.folder} has no balancer (it did not come up)")
        return self.haproxy

    def __enter__(self) -> Cluster:
        return self

    def __exit__(self, *exc) -> None:
        self.down()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="cluster.sh", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    commands = {
        name: sub.add_parser(name, help=text)
        for name, text in (
            ("up", "start the cluster and print its addresses as one JSON object"),
            ("down", "stop everything the cluster in --dir runs"),
            ("add-node", "start one more node and add it to the balancer; prints it as JSON"),
            ("status", "the cluster's JSON and what HAProxy thinks of each node"),
        )
    }
    for p in commands.values():
        p.add_argument("--dir", type=Path, default=DEFAULT_FOLDER, help=f"the cluster's folder (default {DEFAULT_FOLDER})")
    commands["up"].add_argument("--nodes", type=int, default=2, help="nodes to start [1, 256]")
    commands["up"].add_argument(
        "--workers-per-node", type=int, default=ClusterSettings.workers_per_node, help="worker processes per node"
    )
    commands["up"].add_argument(
        "--queue-workers", type=int, default=ClusterSettings.queue_workers, help="`camdirector job-worker` processes"
    )
    args = parser.parse_args(argv)
    try:
        if args.command == "up":
            settings = ClusterSettings(workers_per_node=args.workers_per_node, queue_workers=args.queue_workers)
            print(json.dumps(Cluster.up(args.nodes, args.dir, settings).as_dict()), flush=True)
        elif args.command == "down":
            Cluster.attach(args.dir).down()
        elif args.command == "add-node":
            print(json.dumps(dataclasses.asdict(Cluster.attach(args.dir).add_node())), flush=True)
        else:
            cluster = Cluster.attach(args.dir)
            print(
                json.dumps(
                    {
                        **cluster.as_dict(),
                        "running_pids": cluster.running_pids(),
                        "balancer_sees": cluster.balancer().server_states(),
                    }
                ),
                flush=True,
            )
    except (ClusterError, ServiceError, ValueError) as exc:
        print(f"cluster.sh {args.command}: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
