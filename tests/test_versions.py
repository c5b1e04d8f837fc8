"""One version: every distribution's pyproject.toml and the C/C++ SDK's CMake project agree, and a
running server says it in `--version`, /healthz and each gRPC call's initial metadata. One
protocol: the SDKs' constants are the server's, and a client newer than its server is told so on
every transport (the `camdirector-protocol` metadata over gRPC; CreateSessionRequest.client_protocol
over gRPC and ZeroMQ)."""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import grpc
import httpx
import pytest
import zmq

import camdirector_client
from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc as pbg
from camdirector.version import PROTOCOL, VERSION
from tests.service.wire_client import two_target_request

ROOT = Path(__file__).resolve().parents[1]


def test_every_distribution_has_the_one_version():
    versions = {
        path: tomllib.loads((ROOT / path).read_text())["project"]["version"]
        for path in ("pyproject.toml", "proto/pyproject.toml", "client_sdk/python/pyproject.toml")
    }
    cmake = re.search(r"project\(camdirector_sdk VERSION ([0-9.]+)", (ROOT / "client_sdk/cpp/CMakeLists.txt").read_text())
    versions["client_sdk/cpp/CMakeLists.txt"] = cmake.group(1)  # and cd_version() (tests/client_sdk/cpp/test_install.py)
    assert set(versions.values()) == {VERSION}, versions
    assert camdirector_client.__version__ == VERSION
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert re.search(rf"^## {re.escape(VERSION)} .*\(protocol {PROTOCOL}\)$", changelog, re.M), "CHANGELOG's entry"


def test_a_server_says_its_version_everywhere():
    out = subprocess.run([sys.executable, "-m", "camdirector", "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == f"camdirector {VERSION} (protocol {PROTOCOL})"
    with ServerProcess("--workers", "0", transports=("grpc", "http")) as server:
        health = httpx.get(f"http://{server.http}/healthz").json()
        assert (health["version"], health["protocol"]) == (VERSION, PROTOCOL)
        with grpc.insecure_channel(server.grpc) as channel:
            future = pbg.DirectorStub(channel).CreateSession.future(pb.CreateSessionRequest(), timeout=10)
            metadata = dict(future.initial_metadata())  # sent even when the call is refused
            assert future.exception().code() == grpc.StatusCode.INVALID_ARGUMENT  # an empty scene
        assert metadata["camdirector-version"] == VERSION and metadata["camdirector-protocol"] == str(PROTOCOL)


def test_a_client_newer_than_its_server_is_told_so(monkeypatch):
    with ServerProcess("--workers", "0", transports=("grpc",)) as server:
        stub = pbg.DirectorStub(grpc.insecure_channel(server.grpc))
        for sent, code, words in (
            (str(PROTOCOL + 1), grpc.StatusCode.FAILED_PRECONDITION, "upgrade the server"),
            ("two", grpc.StatusCode.INVALID_ARGUMENT, "not a whole number"),
        ):
            future = stub.CreateSession.future(pb.CreateSessionRequest(), timeout=10, metadata=[("camdirector-protocol", sent)])
            assert future.exception().code() == code and words in future.exception().details()
        monkeypatch.setattr(camdirector_client.wire, "PROTOCOL", PROTOCOL + 1)  # an SDK from a later release
        with (
            camdirector_client.connect(f"grpc://{server.grpc}") as client,
            pytest.raises(camdirector_client.DirectorError) as refused,
        ):
            client.create_session(targets=[], objects=[])
        assert refused.value.code == grpc.StatusCode.FAILED_PRECONDITION
        assert f"protocol {PROTOCOL + 1}" in refused.value.message and "upgrade the server" in refused.value.message


def test_every_sdk_speaks_the_servers_protocol():
    sdks = {
        "client_sdk/python": camdirector_client.wire.PROTOCOL,
        "client_sdk/cpp (CD_PROTOCOL)": int(
            re.search(
                r"^#define CD_PROTOCOL (\d+)$", (ROOT / "client_sdk/cpp/include/camdirector/camdirector.h").read_text(), re.M
            ).group(1)
        ),
        "client_sdk/typescript": int(
            re.search(r"^export const PROTOCOL = (\d+);$", (ROOT / "client_sdk/typescript/src/wire.ts").read_text(), re.M).group(
                1
            )
        ),
    }
    assert set(sdks.values()) == {PROTOCOL}, sdks


def _create_over(server: ServerProcess, transport: str, request: pb.CreateSessionRequest) -> tuple[int, bytes]:
    """CreateSession of `request` with no SDK and no metadata: (status code, reply or message)."""
    payload = request.SerializeToString()
    if transport == "grpc":
        with grpc.insecure_channel(server.grpc) as channel:
            call = channel.unary_unary("/camdirector.v1.Director/CreateSession")
            try:
                return 0, call(payload, timeout=10)
            except grpc.RpcError as error:
                return error.code().value[0], error.details().encode()
    with zmq.Context() as ctx, ctx.socket(zmq.DEALER) as sock:
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(server.zmq)
        sock.send_multipart([b"CreateSession", payload])  # a --no-auth server: no key frame
        assert sock.poll(10_000), "no reply"
        code, body = sock.recv_multipart()
        return int(code), body


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
def test_a_request_of_a_newer_protocol_is_refused_on_every_transport(server, transport):
    code, message = _create_over(server, transport, two_target_request(client_protocol=PROTOCOL + 1))
    assert code == grpc.StatusCode.FAILED_PRECONDITION.value[0], (code, message)
    assert message.decode() == (
        f"this client speaks camdirector protocol {PROTOCOL + 1}, this server (camdirector "
        f"{VERSION}) protocol {PROTOCOL}: upgrade the server, or use a client of release {VERSION}"
    )
    for said in (PROTOCOL, 0):  # its own protocol, or none (a client from before the field)
        code, reply = _create_over(server, transport, two_target_request(client_protocol=said))
        assert code == 0, reply
        session_id = pb.CreateSessionResponse.FromString(reply).session_id
        with grpc.insecure_channel(server.grpc) as channel:
            pbg.DirectorStub(channel).CloseSession(pb.CloseSessionRequest(session_id=session_id), timeout=10)
