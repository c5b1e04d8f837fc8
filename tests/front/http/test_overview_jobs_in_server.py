"""Overview jobs through a real `camdirector serve`: submitted over REST, run, fetched, and a queued
job still there after the server restarts on the same data directory."""

from __future__ import annotations

import json
import time
import urllib.request
import uuid

from camdirector.deploy.server_process import ServerProcess


def _post_clip(http: str, clip: bytes, **fields) -> dict:
    boundary = uuid.uuid4().hex
    parts = [f'--{boundary}\r\nContent-Disposition: form-data; name="{k}"\r\n\r\n{v}\r\n'.encode() for k, v in fields.items()]
    parts.append(
        f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="clip.bvh"\r\n'
        f"Content-Type: application/octet-stream\r\n\r\n".encode()
        + clip
        + b"\r\n"
    )
    body = b"".join(parts) + f"--{boundary}--\r\n".encode()
    request = urllib.request.Request(
        f"http://{http}/v1/overview-jobs",
        data=body,
        method="POST",
        headers={"Content-Type": f"multipart/form-data; boundary={boundary}"},
    )
    with urllib.request.urlopen(request, timeout=30) as reply:
        assert reply.status == 202
        return json.loads(reply.read())


def _status(http: str, job_id: str) -> dict:
    return json.loads(urllib.request.urlopen(f"http://{http}/v1/overview-jobs/{job_id}", timeout=10).read())


def _wait(http: str, job_id: str, timeout_s: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        status = _status(http, job_id)
        if status["status"] in ("succeeded", "failed", "cancelled"):
            return status
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} did not finish: {status}")


def test_a_job_runs_in_the_server_and_a_queued_one_survives_a_restart(shared_data, tmp_path):
    clip = (shared_data / "mocap/bandai_namco/dataset-1_run_active_001.bvh").read_bytes()
    server = ServerProcess("--workers", "0", "--data-dir", str(tmp_path), "--max-concurrent-jobs", "1")
    first = _post_clip(server.http, clip)
    second = _post_clip(server.http, clip, seed="3")  # queued behind the first
    server.stop()  # SIGTERM while the first runs or waits: both must survive
    server = ServerProcess("--workers", "0", "--data-dir", str(tmp_path))
    try:
        for job in (first, second):
            assert _wait(server.http, job["id"])["status"] == "succeeded"
        result = json.loads(
            urllib.request.urlopen(f"http://{server.http}/v1/overview-jobs/{second['id']}/result", timeout=10).read()
        )
        assert len(result["frames"]) == 72 and result["shots"]
        video = urllib.request.urlopen(f"http://{server.http}/v1/overview-jobs/{first['id']}/preview.mp4", timeout=10)
        assert video.read(12)[4:8] == b"ftyp"
    finally:
        server.stop()
