"""The checks a served camdirector gets from outside, as its users reach it: a session of each rig
over gRPC and ZeroMQ, a level added over REST, an overview job, a monitor picture. Shared by
tests/test_installed_package.py (the installed package, plaintext on loopback, keys off) and
tests/deploy/test_image.py (the image in a container, TLS and keys on)."""

from __future__ import annotations

import io
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np
from PIL import Image

from camdirector.v1 import director_pb2 as pb
from tests.service.test_match_sessions import frames as match_frames
from tests.service.test_match_sessions import match_request
from tests.service.tracks_sessions import actor_frames, corridor_walk, obj_text, tracks_request
from tests.service.wire_client import GrpcRaw, ZmqRaw, two_target_request, walk

FRAMES = 45
TRACKS_START = (2.0, 0.0, 2.0)  # the actor's feet in tiny_levels.corridor() and l_room()


@dataclass
class Served:
    """Where a server answers and how a client gets in: `client` is an httpx client on its REST
    base URL (carrying the key and trusting the CA where those are on)."""

    grpc: str
    zmq: str
    client: httpx.Client
    log_tail: Callable[[], str]
    key: str | None = None
    ca_file: Path | None = None
    zmq_server_key: str | None = None

    def grpc_raw(self) -> GrpcRaw:
        return GrpcRaw(self.grpc, key=self.key, ca_file=self.ca_file)

    def zmq_raw(self) -> ZmqRaw:
        return ZmqRaw(self.zmq, key=self.key, server_key=self.zmq_server_key)


def wait_job(served: Served, path: str, timeout_s: float = 180.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = served.client.get(path).json()
        if job["status"] in ("succeeded", "failed", "cancelled"):
            return job
        time.sleep(0.1)
    raise AssertionError(f"{path} did not finish in {timeout_s} s: {job}\n{served.log_tail()}")


def assert_posed(updates: list[pb.CameraUpdate], answered: int) -> None:
    """`answered` frames with a finite pose, not all of them stale."""
    posed = [u for u in updates if u.HasField("pose")]
    assert len(posed) == answered, f"{len(posed)} of {len(updates)} frames have a pose"
    for u in posed:
        p, q = u.pose.position, u.pose.rotation
        values = (p.x, p.y, p.z, q.x, q.y, q.z, q.w, u.pose.vertical_fov_deg)
        assert all(math.isfinite(v) for v in values) and u.pose.vertical_fov_deg > 0.0, u.pose
    assert not all(u.stale for u in posed), "every frame was answered stale"


def session_of_rig(served: Served, rig: str, transport: str, level: str = "corridor") -> None:
    """One session of `rig` ("toric", "match" or "tracks" on `level`) streamed and closed."""
    raw = served.grpc_raw() if transport == "grpc" else served.zmq_raw()
    try:
        if rig == "toric":
            session_id = raw.call("CreateSession", two_target_request(seed=1)).session_id
            assert_posed(raw.stream(list(walk(session_id, FRAMES))), FRAMES)
        elif rig == "match":
            session_id = raw.call("CreateSession", match_request(delay_s=0.0)).session_id
            assert_posed(raw.stream(list(match_frames(session_id, FRAMES))), FRAMES)
        else:
            session_id = raw.call("CreateSession", tracks_request(level, TRACKS_START)).session_id
            times, feet = corridor_walk(FRAMES / 30.0)
            assert_posed(raw.stream(actor_frames(session_id, times, feet)), FRAMES)
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    finally:
        raw.close()


def add_level_over_rest(served: Served, name: str, mesh) -> None:
    """`mesh` (tiny_levels) uploaded as OBJ to POST /v1/levels; its job succeeds."""
    reply = served.client.post("/v1/levels", data={"name": name}, files={"level": (f"{name}.obj", obj_text(mesh).encode())})
    assert reply.status_code == 202, reply.text
    job = wait_job(served, f"/v1/level-jobs/{reply.json()['id']}")
    assert job["status"] == "succeeded", job


def tracks_session_on(served: Served, level: str) -> None:
    """A tracks session on `level`, the actor walking along x from TRACKS_START."""
    raw = served.grpc_raw()
    try:
        session_id = raw.call("CreateSession", tracks_request(level, TRACKS_START)).session_id
        times = np.arange(20) / 30.0
        feet = np.stack([2.0 + 1.4 * times, np.zeros_like(times), np.full_like(times, 2.0)], axis=1)
        assert_posed(raw.stream(actor_frames(session_id, times, feet)), 20)
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    finally:
        raw.close()


def post_overview_job(served: Served, bvh: bytes) -> str:
    reply = served.client.post("/v1/overview-jobs", files={"file": ("run.bvh", bvh)})
    assert reply.status_code == 202, reply.text
    return reply.json()["id"]


def assert_overview_done(served: Served, job_id: str) -> None:
    """The job succeeded with frames, a preview video and a contact sheet (rendered with EGL)."""
    job = wait_job(served, f"/v1/overview-jobs/{job_id}")
    assert job["status"] == "succeeded", job
    result = served.client.get(f"/v1/overview-jobs/{job_id}/result")
    assert result.status_code == 200 and len(result.json()["frames"]) > 0
    for name, media_type in (("preview.mp4", "video/mp4"), ("contact-sheet.png", "image/png")):
        artifact = served.client.get(f"/v1/overview-jobs/{job_id}/{name}")
        assert artifact.status_code == 200 and artifact.headers["content-type"] == media_type and len(artifact.content) > 1000


def monitor_picture(served: Served) -> None:
    """A live session's monitor view: a real JPEG rendered by the server, not its placeholder."""
    raw = served.grpc_raw()
    try:
        session_id = raw.call("CreateSession", two_target_request(seed=4)).session_id
        raw.stream(list(walk(session_id, 20)))
        view = served.client.get(f"/v1/sessions/{session_id}/view", timeout=60.0)
        assert view.status_code == 200 and view.headers["content-type"] == "image/jpeg", view.text[:500]
        assert "x-camdirector-placeholder" not in view.headers, view.headers["x-camdirector-placeholder"]
        picture = Image.open(io.BytesIO(view.content))
        assert picture.format == "JPEG" and len(view.content) > 2000
        assert np.asarray(picture.convert("L")).std() > 1.0, "a blank picture"
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    finally:
        raw.close()
