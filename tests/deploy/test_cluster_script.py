"""`scripts/cluster.sh up --nodes 2` prints one JSON object and returns with the cluster running;
`down` stops every process of it, the nodes' own workers included."""
from __future__ import annotations

import json
import os
import socket
import subprocess
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
    up = subprocess.run([str(ROOT / "scripts" / "cluster.sh"), "up", "--nodes", "2", "--dir", str(folder)],
                        capture_output=True, text=True, timeout=120)
    if up.returncode != 0 and "is not installed" in up.stderr and os.environ.get("CAMDIRECTOR_REQUIRE_CLUSTER") != "1":
        pytest.skip(up.stderr)
    assert up.returncode == 0, up.stderr
    (line,) = up.stdout.splitlines()  # one JSON object, nothing else
    cluster = json.loads(line)
    assert {"grpc", "http", "nodes", "redis", "postgres"} <= set(cluster)
    assert [n["node_id"] for n in cluster["nodes"]] == ["node-1", "node-2"]
    nodes = [n["pid"] for n in cluster["nodes"]]
    processes = nodes + descendants(nodes)
    try:
        for node in cluster["nodes"]:
            assert {"pid", "grpc", "http", "zmq", "node_id"} <= set(node)
            assert is_running(node["pid"], " serve ")  # the node's own serve process, still running
        with grpc.insecure_channel(cluster["grpc"]) as channel:
            reply = health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(), timeout=10)
        assert reply.status == health_pb2.HealthCheckResponse.SERVING
        assert len(processes) > len(nodes)  # the nodes' worker processes too
    finally:
        down = subprocess.run([str(ROOT / "scripts" / "cluster.sh"), "down", "--dir", str(folder)],
                              capture_output=True, text=True, timeout=120)
    assert down.returncode == 0, down.stderr
    assert not [pid for pid in processes if is_running(pid, "")]
    addresses = [cluster["grpc"], cluster["http"], urlsplit(cluster["redis"]).netloc,
                 urlsplit(cluster["postgres"]).netloc.rpartition("@")[2]]
    addresses += [n[k] for n in cluster["nodes"] for k in ("grpc", "http")]
    assert not [a for a in addresses if listening(a)]
    assert not (folder / "cluster.json").exists()
