"""One version: every distribution's pyproject.toml and the C/C++ SDK's CMake project agree, and a
running server says it in `--version`, /healthz and each gRPC call's initial metadata."""
from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import grpc
import httpx

import camdirector_client
from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc as pbg
from camdirector.version import PROTOCOL, VERSION

ROOT = Path(__file__).resolve().parents[1]


def test_every_distribution_has_the_one_version():
    versions = {path: tomllib.loads((ROOT / path).read_text())["project"]["version"]
                for path in ("pyproject.toml", "proto/pyproject.toml", "client_sdk/python/pyproject.toml")}
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
            metadata = dict(future.initial_metadata())   # sent even when the call is refused
            assert future.exception().code() == grpc.StatusCode.INVALID_ARGUMENT   # an empty scene
        assert metadata["camdirector-version"] == VERSION and metadata["camdirector-protocol"] == str(PROTOCOL)
