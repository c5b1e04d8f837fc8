"""Fixtures for the C/C++ SDK's tests: its CMake build (once per test session, incremental in
client_sdk/cpp/build/), a runner for its programs, `sdk_check stream` in the background, and a TCP
proxy that can cut connections."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import socket
import subprocess
import threading
from pathlib import Path

import pytest

from tests.cuttable_proxy import CuttableProxy

ROOT = Path(__file__).resolve().parents[3]
SDK_DIR = ROOT / "client_sdk" / "cpp"
BUILD_DIR = SDK_DIR / "build"
BUILD_TIMEOUT_S = 1200  # a clean build on two busy cores: the generated wire code is most of it
PROGRAMS = ("engine_loop", "convert_check", "sdk_check", "c_api_check", "unit_tests")


def _missing_toolchain() -> str | None:
    """What is missing to build the SDK, or None."""
    for tool in ("cmake", "ctest", "c++", "protoc", "grpc_cpp_plugin", "pkg-config"):
        if shutil.which(tool) is None:
            return f"no {tool}"
    for package in ("grpc++", "protobuf"):
        if subprocess.run(["pkg-config", "--exists", package]).returncode != 0:
            return f"no pkg-config package {package}"
    return None


def _required() -> bool:
    """CI (.ci/run sets CAMDIRECTOR_REQUIRE_CPP_SDK=1) must build and run these tests."""
    return os.environ.get("CAMDIRECTOR_REQUIRE_CPP_SDK") == "1"


@pytest.fixture(scope="session")
def sdk_bin() -> Path:
    """The build folder holding engine_loop, convert_check and sdk_check, built with CMake.

    Skipped with the reason when the toolchain is missing (scripts/system-deps.sh installs it as
    root), a failure under CI. Concurrent test runs in one checkout take turns (a file lock)."""
    missing = _missing_toolchain()
    if missing is not None:
        reason = f"the C++ SDK cannot be built here ({missing}): scripts/system-deps.sh installs the toolchain"
        if _required():
            pytest.fail(reason + " (required: CAMDIRECTOR_REQUIRE_CPP_SDK=1)")
        pytest.skip(reason)
    BUILD_DIR.mkdir(exist_ok=True)
    with open(BUILD_DIR / ".build-lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        for cmd in (
            ["cmake", "-S", str(SDK_DIR), "-B", str(BUILD_DIR), "-DCMAKE_BUILD_TYPE=Release"],
            ["cmake", "--build", str(BUILD_DIR), "--parallel", str(os.cpu_count() or 2)],
        ):
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
            if done.returncode != 0:
                pytest.fail(f"{' '.join(cmd)} failed:\n{done.stdout[-4000:]}\n{done.stderr[-4000:]}")
    for program in PROGRAMS:
        assert (BUILD_DIR / program).is_file(), f"the build made no {program}"
    return BUILD_DIR


def run_json(binary: Path, *args: str, timeout_s: float = 60.0, stdin: str | None = None, env: dict | None = None) -> dict:
    """Runs one of the SDK's programs (with `env` over this process's environment); its last
    stdout line, parsed as JSON."""
    done = subprocess.run(
        [str(binary), *args], input=stdin, capture_output=True, text=True, timeout=timeout_s, env={**os.environ, **(env or {})}
    )
    assert done.returncode == 0, f"{binary.name} {' '.join(args)} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
    return json.loads(done.stdout.strip().splitlines()[-1])


READY_TIMEOUT_S = 30.0


class StreamRun:
    """`sdk_check stream ADDRESS --until EVENT [OPTIONS]` in the background (with `env` over this
    process's environment): waits for its ready line, then for its report."""

    def __init__(self, binary, address: str, until: str, timeout_s: float = 40.0, *options: str, env: dict | None = None):
        self.proc = subprocess.Popen(
            [str(binary), "stream", address, "--until", until, "--timeout", str(timeout_s), *options],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, **(env or {})},
        )
        self.lines: list[str] = []
        self._ready = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)
            if '"ready"' in line:
                self._ready.set()
        self._ready.set()

    def wait_ready(self) -> dict:
        assert self._ready.wait(READY_TIMEOUT_S), "sdk_check never started streaming"
        assert self.lines and '"ready"' in self.lines[0], f"no ready line: {self.lines} {self.proc.stderr.read()}"
        return json.loads(self.lines[0])

    def report(self, timeout_s: float = 90.0) -> dict:
        try:
            self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            pytest.fail(f"sdk_check stream did not finish: {self.lines}")
        assert self.proc.returncode == 0, self.proc.stderr.read()
        # the process has exited, but its last lines may still be in the pipe, unread
        self._reader.join(10.0)
        return json.loads(self.lines[-1])


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def proxy_to():
    """proxy_to("HOST:PORT") -> a CuttableProxy, closed after the test."""
    proxies: list[CuttableProxy] = []

    def start(upstream: str) -> CuttableProxy:
        proxies.append(CuttableProxy(upstream))
        return proxies[-1]

    yield start
    for p in proxies:
        p.close()
