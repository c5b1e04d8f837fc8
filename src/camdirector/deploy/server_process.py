"""A `camdirector serve` child process on free loopback ports, for the demo, benchmarks,
evaluation and tests: started, waited for (its one JSON ready line names the bound addresses),
and stopped."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

from camdirector.deploy.services import tcp_state


def worker_pids(server_pid: int) -> list[int]:
    """The server's worker processes: its children started by multiprocessing's `spawn` (which
    leaves out a resource tracker, were one running), sorted by pid."""
    pids = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            cmdline = Path(f"/proc/{entry}/cmdline").read_bytes()
        except OSError:  # gone meanwhile
            continue
        parent = int(stat.rsplit(")", 1)[1].split()[1])  # the name in parentheses may hold spaces
        if parent == server_pid and b"spawn_main" in cmdline:
            pids.append(int(entry))
    return sorted(pids)


class ServerProcess:
    """Pass transports=("grpc",) to turn the others off; extra `args` go to `camdirector serve`.
    The server's log goes to a file in a temporary folder (a pipe could fill and stall it).

    python: the interpreter that runs `-m camdirector serve` (another checkout's venv runs its own
    server); command: the whole command instead (an installed console script); base_env: the
    environment to start from instead of this process's, `env` updating it; cwd: the folder it
    runs in.

    auth: False starts it with `--no-auth` (tests and benchmarks about other things); True with
    authentication on, `admin_key` then holding the admin key it made and `zmq_server_key` its
    CURVE public key (docs/security.md)."""

    def __init__(
        self,
        *args: str,
        transports: Collection[str] = ("grpc", "zmq", "http"),
        env: Mapping[str, str] | None = None,
        python: str = sys.executable,
        command: list[str] | None = None,
        base_env: Mapping[str, str] | None = None,
        cwd: str | Path | None = None,
        auth: bool = False,
    ):
        self._dir = tempfile.TemporaryDirectory(prefix="camdirector-server-")
        self.log_path = Path(self._dir.name) / "server.log"
        # 0600: without --data-dir it lies in the data folder, which the server keeps private
        self._log = open(self.log_path, "w+", opener=lambda path, flags: os.open(path, flags, 0o600))
        bind = {"grpc": "127.0.0.1:0", "zmq": "tcp://127.0.0.1:*", "http": "127.0.0.1:0"}
        cmd = list(command) if command is not None else [python, "-m", "camdirector", "serve"]
        for name, address in bind.items():
            cmd += [f"--{name}", address if name in transports else ""]
        if "--data-dir" not in args:
            cmd += ["--data-dir", self._dir.name]
        # its data folder: where a test finds what the server wrote (a recording is named by its id)
        self.data_dir = Path(args[args.index("--data-dir") + 1] if "--data-dir" in args else self._dir.name)
        if not auth:
            cmd.append("--no-auth")
        self.proc = subprocess.Popen(
            [*cmd, *args],
            stdout=subprocess.PIPE,
            stderr=self._log,
            text=True,
            env={**(os.environ if base_env is None else base_env), **(env or {})},
            cwd=cwd,
        )
        stdout = self.proc.stdout
        assert stdout is not None  # stdout=PIPE
        self._stdout = stdout
        line = stdout.readline()
        if not line:
            self.proc.wait(15)
            raise RuntimeError(f"the server did not start: {self.log_tail()}")
        self.ready: dict[str, Any] = json.loads(line)  # the server's JSON ready line
        self.grpc: str | None = self.ready.get("grpc")
        self.zmq: str | None = self.ready.get("zmq")
        self.http: str | None = self.ready.get("http")
        self.zmq_server_key: str | None = self.ready.get("zmq_server_key")
        key_file = self.ready.get("admin_key_file")
        self.admin_key: str | None = Path(key_file).read_text().strip() if key_file else None

    def url(self, transport: str) -> str | None:
        """The SDK's URL for "grpc" or "zmq"; None for ZeroMQ when the server was started without it."""
        if transport == "grpc":
            return f"grpcs://{self.grpc}" if self.ready.get("tls") else f"grpc://{self.grpc}"
        return self.zmq

    def log_tail(self, chars: int = 4000) -> str:
        self._log.flush()
        return self.log_path.read_text()[-chars:]

    def alive(self) -> bool:
        return self.proc.poll() is None

    def worker_pids(self) -> list[int]:
        """Its worker processes' pids (worker_pids), sorted."""
        return worker_pids(self.proc.pid)

    def kill_worker_mid_request(self, stopped_s: float = 0.1) -> int:
        """SIGKILLs its first worker with requests in flight to it (stopped for `stopped_s` first,
        so a streaming client's frames wait on it); returns the pid. A worker killed between two
        frames costs its sessions no UNAVAILABLE at all: the next frame waits for its successor."""
        pid = self.worker_pids()[0]
        os.kill(pid, signal.SIGSTOP)
        time.sleep(stopped_s)
        os.kill(pid, signal.SIGKILL)
        return pid

    def stop(self) -> int:
        """Stops the server (SIGTERM, then SIGKILL after 15 s); returns its exit code."""
        if self.alive():
            self.proc.terminate()
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._stdout.close()
        self._log.close()
        self._dir.cleanup()
        return self.proc.returncode

    def __enter__(self) -> ServerProcess:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc: object) -> None:
        if exc_type is not None and exc_type is not KeyboardInterrupt:
            # what the server was doing when its caller failed goes with the failure (a test's
            # captured stderr); the log itself is removed with its folder
            state = "running" if self.alive() else f"exited with {self.proc.returncode}"
            ports = {name: tcp_state(address) for name, address in (("grpc", self.grpc), ("http", self.http)) if address}
            print(
                f"camdirector serve (pid {self.proc.pid}) {state}, its ports {ports}; its log ends:\n{self.log_tail()}",
                file=sys.stderr,
            )
        self.stop()
