"""The HTTP address (/healthz, /metrics, /v1/sessions) and gRPC health checking and reflection."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc

from camdirector.v1 import director_pb2 as pb
from tests.service.wire_client import GrpcRaw, two_target_request, walk


def _get(server, path: str) -> str:
    return urllib.request.urlopen(f"http://{server.http}{path}", timeout=10).read().decode()


def test_healthz_metrics_and_sessions(server):
    client = GrpcRaw(server.grpc)
    session_id = client.call("CreateSession", two_target_request()).session_id
    client.stream(list(walk(session_id, 12)))
    health = json.loads(_get(server, "/healthz"))
    assert health["status"] == "ok" and health["workers"] == 2 and health["sessions"] >= 1
    assert health["loop_lag_ms"] >= 0.0  # the frame loop's health (front/loop_watch.py)
    sessions = json.loads(_get(server, "/v1/sessions"))["sessions"]
    mine = next(s for s in sessions if s["session_id"] == session_id)
    assert mine["frames"] == 12 and mine["transports"] == ["grpc"]
    metrics = _get(server, "/metrics")
    for name in (
        "camdirector_sessions ",
        'camdirector_frames_total{transport="grpc"}',
        'camdirector_stage_seconds_bucket{le="0.001",stage="motion"}',
        "camdirector_frame_compute_seconds_count",
        'camdirector_request_seconds_count{rpc="StreamFrames"',
    ):
        assert name in metrics, name
    client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    client.close()


def test_grpc_health_and_reflection(server):
    with grpc.insecure_channel(server.grpc) as channel:
        health = health_pb2_grpc.HealthStub(channel)
        for service in ("", "camdirector.v1.Director"):
            assert health.Check(health_pb2.HealthCheckRequest(service=service)).status == health_pb2.HealthCheckResponse.SERVING
        stub = reflection_pb2_grpc.ServerReflectionStub(channel)
        replies = list(stub.ServerReflectionInfo(iter([reflection_pb2.ServerReflectionRequest(list_services="")])))
        names = {s.name for s in replies[0].list_services_response.service}
        assert "camdirector.v1.Director" in names and "grpc.health.v1.Health" in names


def test_wrong_method_answers_405_naming_every_allowed_method(server):
    """Starlette names only the first matching route's methods; a path served by two routes
    (GET and POST /v1/levels, GET and DELETE of a job) must name both."""
    for path, method, allowed in (
        ("/v1/levels", "PUT", "GET, POST"),
        ("/v1/overview-jobs/abc", "POST", "DELETE, GET"),
        ("/healthz", "DELETE", "GET"),
    ):
        request = urllib.request.Request(f"http://{server.http}{path}", method=method)
        try:
            urllib.request.urlopen(request, timeout=10)
        except urllib.error.HTTPError as error:
            assert error.code == 405 and error.headers["Allow"] == allowed, (path, error.headers["Allow"])
        else:
            raise AssertionError(f"{method} {path} was accepted")
    with urllib.request.urlopen(f"http://{server.http}/metrics", timeout=10) as reply:
        assert reply.headers["Content-Type"].startswith("text/plain")
