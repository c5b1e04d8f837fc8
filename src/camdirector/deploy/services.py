"""Debian's Redis, PostgreSQL and HAProxy started as plain child processes on loopback ports, for
the cluster (deploy/cluster.py) and the tests: each `start()`s, waits until it answers, gives its
URL, and `stop()`s. Nothing is installed here (scripts/system-deps.sh --cluster does that); a
missing binary is a `ServiceError` that says which package provides it.

PostgreSQL refuses to run as root, so as root its data folder is given to Debian's `postgres`
user and its commands run as that user (runuser)."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path

POSTGRES_BIN = Path("/usr/lib/postgresql/15/bin")


class ServiceError(RuntimeError):
    """A service that cannot start (missing binary, port taken, bad configuration)."""


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (the caller binds it soon after)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _binary(name: str, package: str, folder: Path | None = None) -> str:
    path = str(folder / name) if folder is not None and (folder / name).exists() else shutil.which(name)
    if path is None:
        raise ServiceError(f"{name} is not installed (Debian package {package}; scripts/system-deps.sh --cluster)")
    return path


# /proc/net/tcp's states (include/net/tcp_states.h) a failing test's report names
_TCP_STATES = {"01": "ESTABLISHED", "06": "TIME_WAIT", "08": "CLOSE_WAIT", "0A": "LISTEN"}


def tcp_state(address: str) -> str:
    """Whether a socket listens on HOST:PORT's port (from /proc/net/tcp and tcp6: gRPC listens on
    an IPv6 socket for 127.0.0.1): "LISTEN", the states of the sockets on it, or "nothing" (a port
    refused: closed, or shut down)."""
    port = f"{int(address.rpartition(':')[2]):04X}"
    try:
        rows = [line.split() for table in ("tcp", "tcp6") for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]]
    except OSError:
        return "unknown"
    states = sorted({_TCP_STATES.get(row[3], row[3]) for row in rows if row[1].endswith(f":{port}")})
    return "LISTEN" if "LISTEN" in states else ", ".join(states) or "nothing"


def process_state(pid: int) -> str:
    """A process's scheduler state and the kernel function it sleeps in (/proc: "S (sleeping) in
    do_epoll_wait"), or "gone", for a failing start's report."""
    try:
        state = next(line for line in Path(f"/proc/{pid}/status").read_text().splitlines() if line.startswith("State:"))
        wchan = Path(f"/proc/{pid}/wchan").read_text().strip()
    except (OSError, StopIteration):
        return "gone"
    return f"{state.split(':', 1)[1].strip()} in {wchan or '-'}"


def _wait_port(port: int, proc: subprocess.Popen | None, timeout_s: float, what: str, log: Path) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise ServiceError(f"{what} exited with code {proc.returncode}: {_tail(log)}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    # a CI run's HAProxy ran and logged nothing while its port refused for 10 s: say what it was doing
    running = "" if proc is None else f" (pid {proc.pid}: {process_state(proc.pid)}; the port: {tcp_state(f':{port}')})"
    raise ServiceError(f"{what} did not listen on 127.0.0.1:{port} within {timeout_s:g} s{running}: {_tail(log)}")


def _tail(path: Path, chars: int = 2000) -> str:
    try:
        return path.read_text(errors="replace")[-chars:]
    except OSError:
        return "(no log)"


def is_running(pid: int, marker: str) -> bool:
    """Whether `pid` runs (a zombie does not) a command line that holds `marker`: a pid that another
    program took since is not ours to stop. A zombie that is this process's child is reaped."""
    try:
        os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        pass  # not our child: init reaps it
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return False
    return stat.rpartition(")")[2].split()[0] != "Z" and marker in cmdline


def _wait_exit(processes: list[tuple[int, str]], seconds: float) -> list[tuple[int, str]]:
    """Waits up to `seconds` for the processes to end; returns those still running."""
    deadline = time.monotonic() + seconds
    running = [(pid, marker) for pid, marker in processes if is_running(pid, marker)]
    while running and time.monotonic() < deadline:
        time.sleep(0.05)
        running = [(pid, marker) for pid, marker in running if is_running(pid, marker)]
    return running


def stop_processes(processes: list[tuple[int, str]], timeout_s: float = 15.0, grace_s: float = 0.0) -> None:
    """Stops each (pid, marker) that still runs with `marker` in its command line, all at once:
    after grace_s for them to end by themselves, SIGTERM, then SIGKILL to those still running
    after timeout_s. For processes started by another invocation (the cluster's `down`), which no
    Popen object holds."""
    running = _wait_exit(processes, grace_s)
    for pid, _ in running:
        with contextlib.suppress(ProcessLookupError):  # ended since it was looked at
            os.kill(pid, signal.SIGTERM)
    for pid, _ in _wait_exit(running, timeout_s):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    _wait_exit(running, 5.0)


def signal_tree(pids: list[int], sig: int) -> list[int]:
    """Sends `sig` to each pid and every process below them, parents first; returns the pids
    signalled. SIGSTOP and SIGCONT of a whole service (a hung machine, the chaos benchmark's): a
    service's children (PostgreSQL's backends, a node's workers) serve its connections too."""
    signalled = []
    for pid in [*pids, *descendants(pids)]:
        with contextlib.suppress(ProcessLookupError):  # ended since it was looked at
            os.kill(pid, sig)
            signalled.append(pid)
    return signalled


def descendants(pids: list[int]) -> list[int]:
    """Every process below the given ones (children, their children, ...), from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rpartition(")")[2].split()[1])
            except (OSError, IndexError, ValueError):
                continue  # ended meanwhile
            children.setdefault(ppid, []).append(int(entry.name))
    found, todo = [], [c for pid in pids for c in children.get(pid, [])]
    while todo:
        pid = todo.pop()
        found.append(pid)
        todo += children.get(pid, [])
    return found


class RedisServer:
    """redis-server on 127.0.0.1:`port` (0: a free one). Without `persist`, nothing is written
    to disk (the tests'); with it, an append-only file fsynced every second, so a restarted Redis
    still holds the job queue's messages (the cluster's: docs/jobs.md)."""

    def __init__(self, folder: Path, port: int = 0, persist: bool = False):
        self.folder = Path(folder)
        self.port = port or free_port()
        self.persist = persist
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self, timeout_s: float = 10.0) -> RedisServer:
        self.folder.mkdir(parents=True, exist_ok=True)
        log = self.folder / "redis.log"
        self.proc = subprocess.Popen(
            [
                _binary("redis-server", "redis-server"),
                "--port",
                str(self.port),
                "--bind",
                "127.0.0.1",
                "--dir",
                str(self.folder),
                "--save",
                "",
                "--appendonly",
                "yes" if self.persist else "no",
                "--protected-mode",
                "yes",
                "--logfile",
                str(log),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        _wait_port(self.port, self.proc, timeout_s, "redis-server", log)
        return self

    def stop(self) -> None:
        """SIGTERM (Redis writes its append-only file out and exits), SIGKILL after 5 s. `start`
        again serves on the same port, with the same data where `persist` kept it."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGCONT)  # a paused Redis cannot act on SIGTERM
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


class PostgresServer:
    """A PostgreSQL cluster of its own in `folder`, on 127.0.0.1:`port` (0: a free one), with a
    database and a user both named `camdirector` (trust authentication: loopback only). As root
    the cluster's folder is a new one under the system's temporary folder instead, which the
    `postgres` user can reach (a test's folder often is not: its parents are root's alone)."""

    def __init__(self, folder: Path, port: int = 0, *, existing: bool = False):
        """existing: `folder` is the `.folder` of a cluster started before (by another process),
        used as it is, to stop it."""
        self._as_postgres = os.geteuid() == 0
        own_folder = self._as_postgres and not existing
        self.folder = Path(tempfile.mkdtemp(prefix="camdirector-pg-")) if own_folder else Path(folder)
        self.port = port or free_port()
        self.data = self.folder / "pgdata"

    @property
    def url(self) -> str:
        return f"postgresql://camdirector@127.0.0.1:{self.port}/camdirector"

    def _run(self, *cmd: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess:
        argv = (["runuser", "-u", "postgres", "--"] if self._as_postgres else []) + list(cmd)
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s)
        if done.returncode != 0:
            raise ServiceError(f"{Path(cmd[0]).name} failed: {(done.stderr or done.stdout)[-2000:]}")
        return done

    def start(self, timeout_s: float = 60.0) -> PostgresServer:
        initdb = _binary("initdb", "postgresql", POSTGRES_BIN)
        pg_ctl = _binary("pg_ctl", "postgresql", POSTGRES_BIN)
        self.folder.mkdir(parents=True, exist_ok=True)
        if self._as_postgres:
            shutil.chown(self.folder, "postgres", "postgres")
            os.chmod(self.folder, 0o700)
        if not (self.data / "PG_VERSION").exists():
            self._run(initdb, "-D", str(self.data), "-A", "trust", "-U", "camdirector", "--no-sync", "-E", "UTF8")
        options = f"-p {self.port} -k {self.folder} -c listen_addresses=127.0.0.1 -c fsync=off"
        self._run(
            pg_ctl,
            "-D",
            str(self.data),
            "-o",
            options,
            "-l",
            str(self.folder / "postgres.log"),
            "-w",
            "-t",
            str(int(timeout_s)),
            "start",
            timeout_s=timeout_s + 5,
        )
        createdb = _binary("createdb", "postgresql", POSTGRES_BIN)
        done = subprocess.run(
            (["runuser", "-u", "postgres", "--"] if self._as_postgres else [])
            + [createdb, "-h", "127.0.0.1", "-p", str(self.port), "-U", "camdirector", "camdirector"],
            capture_output=True,
            text=True,
            timeout=30,
        )
        if done.returncode != 0 and "already exists" not in done.stderr:
            raise ServiceError(f"createdb failed: {done.stderr[-2000:]}")
        return self

    def postmaster_pid(self) -> int | None:
        """The running server's pid (its postmaster.pid file's first line), None when stopped."""
        try:
            return int((self.data / "postmaster.pid").read_text().split()[0])
        except (OSError, IndexError, ValueError):
            return None

    def stop(self, keep_data: bool = False) -> None:
        """Stops the server (fast shutdown: open connections are cut). As root its folder is
        removed too, unless `keep_data`: then `start` serves the same databases again."""
        if (pid := self.postmaster_pid()) is not None:
            signal_tree([pid], signal.SIGCONT)  # a paused server cannot shut down
        if (self.data / "postmaster.pid").exists():
            try:
                self._run(
                    _binary("pg_ctl", "postgresql", POSTGRES_BIN), "-D", str(self.data), "-m", "fast", "-w", "stop", timeout_s=30
                )
            except ServiceError:
                pass
        if self._as_postgres and not keep_data:
            shutil.rmtree(self.folder, ignore_errors=True)
