"""Toy job kinds and waiting helpers of the job tests. The kinds are module-level so that job
processes import them by reference."""

from __future__ import annotations

import os
import time
from pathlib import Path

from camdirector.infra.job_errors import JobError
from camdirector.jobs import JobKind, JobRegistry


def echo_job(params, input_dir: Path, output_dir: Path, progress) -> dict:
    progress(0.5)
    (output_dir / "echo.txt").write_bytes((input_dir / "in.txt").read_bytes() * 2)
    return {"echo": 1.0}


def wait_job(params, input_dir: Path, output_dir: Path, progress) -> dict:
    """Runs until the file params["release"] exists (at most 60 s); marks params["started"]."""
    Path(params["started"]).with_suffix(f".{os.getpid()}").touch()
    deadline = time.monotonic() + 60.0
    while not Path(params["release"]).exists():
        if time.monotonic() > deadline:
            raise JobError("never released")
        progress(0.25)
        time.sleep(0.02)
    (output_dir / "done.txt").write_text("done")
    return {}


def failing_job(params, input_dir, output_dir, progress) -> dict:
    (output_dir / "partial.txt").write_text("half")
    if params["how"] == "job_error":
        raise JobError("the clip is upside down")
    if params["how"] == "exception":
        raise ZeroDivisionError("division by zero")
    os._exit(3)


TOY_KINDS = (JobKind("echo", echo_job), JobKind("wait", wait_job), JobKind("fail", failing_job))
KINDS = JobRegistry(TOY_KINDS)


def wait_until(predicate, timeout_s: float = 20.0, what: str = "condition"):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def started_pids(marker: Path) -> list[int]:
    return [int(p.suffix[1:]) for p in marker.parent.glob(marker.name + ".*")]


def wait_params(tmp_path: Path, name: str) -> dict:
    return {"started": str(tmp_path / f"{name}-started"), "release": str(tmp_path / f"{name}-release")}


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie counts as dead
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except OSError:
        return False
