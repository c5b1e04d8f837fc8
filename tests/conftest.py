"""Fixtures shared by the whole suite: a real `camdirector serve` process, and the shared data."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data; skipped with a reason where absent, a failure under CI (.ci/run)."""
    if not SHARED_DATA.is_dir():
        if os.environ.get("CAMDIRECTOR_REQUIRE_SHARED_DATA") == "1":
            pytest.fail(f"{SHARED_DATA} is required (CAMDIRECTOR_REQUIRE_SHARED_DATA=1)")
        pytest.skip(f"{SHARED_DATA} is absent: third-party levels and clips are not in this clone")
    return SHARED_DATA


class ServerProcess:
    """A real server started as `python -m camdirector.server.cli serve` on free loopback ports."""

    def __init__(self, *args: str, env: dict | None = None):
        cmd = [sys.executable, "-m", "camdirector.server.cli", "serve", "--grpc", "127.0.0.1:0",
               "--zmq", "tcp://127.0.0.1:*", "--http", "127.0.0.1:0", *args]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env={**os.environ, **(env or {})})
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"server did not start: {self.proc.stderr.read()}")
        self.ready = json.loads(line)
        self.grpc = self.ready.get("grpc")
        self.zmq = self.ready.get("zmq")
        self.http = self.ready.get("http")

    def url(self, transport: str) -> str:
        return f"grpc://{self.grpc}" if transport == "grpc" else self.zmq

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> int:
        if self.alive():
            self.proc.terminate()
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode


@pytest.fixture(scope="session")
def server(tmp_path_factory):
    """One shared server with two worker processes for the integration tests."""
    data_dir = tmp_path_factory.mktemp("server-data")
    srv = ServerProcess("--workers", "2", "--data-dir", str(data_dir), "--max-sessions", "32",
                        "--max-message-bytes", str(4 * 1024 * 1024), "--max-triangles", "200000")
    yield srv
    assert srv.stop() == 0, "server did not exit cleanly"


@pytest.fixture
def server_factory():
    """Starts servers with custom flags; stops them after the test."""
    started = []

    def start(*args: str, env: dict | None = None) -> ServerProcess:
        srv = ServerProcess(*args, env=env)
        started.append(srv)
        return srv

    yield start
    for srv in started:
        srv.stop()
