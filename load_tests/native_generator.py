"""The compiled load generator (driver/load_driver.cpp): what load_tests.stream and
load_tests.capacity stream with under `--generator native`.

Why: the Python generator costs about 140 us of CPU a frame on the two cores the server it
measures runs on (at 63 sessions, a third of the machine), so capacity measured the generator as
much as the server (docs/frame_path.md, "The order of work", step 6). The driver streams the same
frames the same way (one in flight per session, paced by the wall clock, staggered over one
period; one gRPC channel, or one ZeroMQ DEALER socket per session) and reports what
load_tests.stream reports; this module builds it with CMake on first use (into driver/build/,
incremental, one build at a time across processes) and runs it.
"""

from __future__ import annotations

import fcntl
import json
import shutil
import struct
import subprocess
import tempfile
import time
from pathlib import Path

from camdirector.v1 import director_pb2 as pb

DRIVER_DIR = Path(__file__).resolve().parent / "driver"
BUILD_DIR = DRIVER_DIR / "build"
BUILD_TIMEOUT_S = 600  # a clean build takes about 25 s on two cores
START_IN_S = 0.2  # from the driver's start to the first frame: it reads the frames and connects meanwhile, s
RUN_SLACK_S = 60.0  # beyond the frames' own duration, before a driver that hangs is stopped, s
_COMPUTE_FIELD = pb.CameraUpdate.DESCRIPTOR.fields_by_name["compute_ms"].number
_STALE_FIELD = pb.CameraUpdate.DESCRIPTOR.fields_by_name["stale"].number
_built: Path | None = None


def missing_toolchain() -> str | None:
    """What is missing to build the driver (scripts/system-deps.sh --tests installs it), or None."""
    for tool in ("cmake", "c++", "pkg-config"):
        if shutil.which(tool) is None:
            return f"no {tool}"
    if subprocess.run(["pkg-config", "--exists", "grpc++"]).returncode != 0:
        return "no pkg-config package grpc++"
    return None


def build() -> Path:
    """The driver, built (or brought up to date) with CMake; RuntimeError saying what failed."""
    global _built
    if _built is not None:
        return _built
    missing = missing_toolchain()
    if missing is not None:
        raise RuntimeError(f"the native load generator cannot be built here ({missing}): scripts/system-deps.sh --tests")
    BUILD_DIR.mkdir(exist_ok=True)
    with open(BUILD_DIR / ".build-lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        for cmd in (
            ["cmake", "-S", str(DRIVER_DIR), "-B", str(BUILD_DIR), "-DCMAKE_BUILD_TYPE=Release"],
            ["cmake", "--build", str(BUILD_DIR)],
        ):
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
            if done.returncode != 0:
                raise RuntimeError(f"{' '.join(cmd)} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    _built = BUILD_DIR / "load_driver"
    return _built


def stream(
    transport: str,
    address: str,
    session_ids: list[str],
    frames: list[bytes],
    period_s: float,
    warmup_frames: int,
    key: str | None = None,
    stride: int = 0,
) -> dict:
    """Streams `frames` (serialized FrameUpdates without a session id) into each session,
    `period_s` apart (0: closed loop), the first session's first frame START_IN_S after the
    driver is started; session i from the (i * stride)-th frame on, each as many (the driver's
    --stride). Returns the driver's report: `received` (frames answered, per session), `rtt_ms` and
    `compute_ms` of the frames after each session's first `warmup_frames`, `late`, `stale`,
    `errors` (one per failed session), `wall_s` and `cpu_s` (the driver's own CPU)."""
    driver = build()
    with tempfile.NamedTemporaryFile(suffix=".frames") as file:
        file.write(b"".join(struct.pack("<I", len(f)) + f for f in frames))
        file.flush()
        cmd = [
            str(driver),
            "--transport", transport,
            "--address", address,
            "--frames", file.name,
            "--sessions", ",".join(session_ids),
            "--period-s", repr(period_s),
            "--start-s", repr(time.perf_counter() + START_IN_S),
            "--warmup", str(warmup_frames),
            "--compute-field", str(_COMPUTE_FIELD),
            "--stale-field", str(_STALE_FIELD),
        ]  # fmt: skip
        if key is not None:
            cmd += ["--key", key]
        if stride:
            cmd += ["--stride", str(stride)]
        duration_s = (len(frames) - (len(session_ids) - 1) * stride) * (period_s or 0.05)
        try:
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=duration_s + RUN_SLACK_S)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"load_driver did not finish {duration_s + RUN_SLACK_S:.0f} s after it started") from None
    if done.returncode != 0:
        raise RuntimeError(f"load_driver exited {done.returncode}: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout)
