"""`scripts/cluster.sh up --nodes 2` prints one JSON object and returns with the cluster running,
over TLS and with keys: the JSON names the CA to trust and the admin key's file, never a key;
`down` stops every process of it, the nodes' own workers included."""

from __future__ import annotations

import json
import os
import socket
import ssl
import subprocess
import urllib.request
from pathlib import Path
from urllib.parse import urlsplit

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc

from camdirector.deploy.services import descendants, is_running

ROOT = Path(__file__).resolve().parents[2]


def listening(address: str) -> bool:
    host, _, port = address.rpartition(":")
    try:
        with socket.create_connection((host, int(port)), timeout=0.5):
            return True
    except OSError:
        return False


def test_cluster_sh_up_prints_the_cluster_and_down_leaves_nothing(tmp_path):
    folder = tmp_path / "c"
    up = subprocess.run(
        [str(ROOT / "scripts" / "cluster.sh"), "up", "--nodes", "2", "--dir", str(folder)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    if up.returncode != 0 and "is not installed" in up.stderr and os.environ.get("CAMDIRECTOR_REQUIRE_CLUSTER") != "1":
        pytest.skip(up.stderr)
    assert up.returncode == 0, up.stderr
    (line,) = up.stdout.splitlines()  # one JSON object, nothing else
    cluster = json.loads(line)
    assert {"grpc", "http", "nodes", "redis", "postgres", "ca_file", "admin_key_file", "zmq_server_key"} <= set(cluster)
    assert "cdk_" not in up.stdout + up.stderr  # the key's file is named, the key never shown
    assert [n["node_id"] for n in cluster["nodes"]] == ["node-1", "node-2"]
    nodes = [n["pid"] for n in cluster["nodes"]]
    processes = nodes + descendants(nodes)
    try:
        for node in cluster["nodes"]:
            assert {"pid", "grpc", "http", "zmq", "node_id"} <= set(node)
            assert is_running(node["pid"], " serve ")  # the node's own serve process, still running
        ca = Path(cluster["ca_file"])
        with grpc.secure_channel(cluster["grpc"], grpc.ssl_channel_credentials(ca.read_bytes())) as channel:
            reply = health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(), timeout=10)
        assert reply.status == health_pb2.HealthCheckResponse.SERVING
        key_file = Path(cluster["admin_key_file"])
        assert key_file.stat().st_mode & 0o777 == 0o600
        whoami = urllib.request.Request(
            f"https://{cluster['http']}/v1/whoami", headers={"Authorization": f"Bearer {key_file.read_text().strip()}"}
        )
        with urllib.request.urlopen(whoami, timeout=10, context=ssl.create_default_context(cafile=str(ca))) as reply:
            assert json.load(reply)["role"] == "admin"
        assert len(processes) > len(nodes)  # the nodes' worker processes too
    finally:
        down = subprocess.run(
            [str(ROOT / "scripts" / "cluster.sh"), "down", "--dir", str(folder)], capture_output=True, text=True, timeout=120
        )
    assert down.returncode == 0, down.stderr
    assert not [pid for pid in processes if is_running(pid, "")]
    addresses = [
        cluster["grpc"],
        cluster["http"],
        urlsplit(cluster["redis"]).netloc,
        urlsplit(cluster["postgres"]).netloc.rpartition("@")[2],
    ]
    addresses += [n[k] for n in cluster["nodes"] for k in ("grpc", "http")]
    assert not [a for a in addresses if listening(a)]
    assert not (folder / "cluster.json").exists()
