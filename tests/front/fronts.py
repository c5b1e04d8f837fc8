"""What the compiled edge's tests (test_grpc_edge.py, test_zmq_edge.py) share: a real server on each
front (and one whose edge computes the frames of the sessions its front holds, `--workers 0`), a
counter read off its /metrics, and a camera without its timings (which differ run to run)."""

from __future__ import annotations

import re
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


def without_timings(update: pb.CameraUpdate) -> pb.CameraUpdate:
    update.ClearField("compute_ms")
    update.diagnostics.ClearField("stage_ms")
    return update
