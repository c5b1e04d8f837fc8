"""What the compiled edge's tests (test_grpc_edge.py, test_zmq_edge.py) share: a real server on each
front (and one whose edge computes the frames of the sessions its front holds, `--workers 0`), a
counter read off its /metrics, and a camera without its timings (which differ run to run)."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator

import httpx

from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb

FRONTS = ("python", "compiled")
# the servers servers_on_each_front starts, by name: (workers, front)
SERVERS = {"python": ("1", "python"), "compiled": ("1", "compiled"), "inline": ("0", "compiled")}


def servers_on_each_front(flag: str, *args: str, transports: tuple[str, ...]) -> Iterator[dict[str, ServerProcess]]:
    """One server per front (`flag`: --grpc-front or --zmq-front) with a worker, and one whose
    compiled edge answers on its own thread from the front's table ("inline"), stopped after the
    caller's tests."""
    started = {
        name: ServerProcess("--workers", workers, flag, front, *args, transports=transports)
        for name, (workers, front) in SERVERS.items()
    }
    yield started
    for server in started.values():
        server.stop()


def metric(server: ServerProcess, name: str, headers: dict | None = None) -> float:
    """The value of an unlabelled metric; 0 when the server has not counted it yet."""
    text = httpx.get(f"http://{server.http}/metrics", headers=headers).text
    found = re.search(rf"^{name} (\S+)$", text, re.M)
    return float(found.group(1)) if found else 0.0


def edge_frames(server: ServerProcess) -> float:
    """camdirector_edge_frames_total once what the edge answered has reached the front's metrics
    (front/edge.py drains it every DRAIN_S)."""
    time.sleep(0.6)
    return metric(server, "camdirector_edge_frames_total")


def counted(server: ServerProcess, session_id: str) -> tuple[int, list[str]]:
    """The session's frames answered and the transports they came by, as the server describes it."""
    session = httpx.get(f"http://{server.http}/v1/sessions/{session_id}", params={"last": 1}).json()["session"]
    return session["frames"], session["transports"]


def without_timings(update: pb.CameraUpdate) -> pb.CameraUpdate:
    update.ClearField("compute_ms")
    update.diagnostics.ClearField("stage_ms")
    return update
