"""A cluster of two nodes behind HAProxy for the module that routes through it, and helpers to
see where sessions live."""
from __future__ import annotations

import json
import urllib.request
import uuid

import grpc
import pytest

from camdirector.deploy.cluster import Cluster
from camdirector.deploy.haproxy import ROUTE_HEADER
from camdirector.v1 import director_pb2_grpc as pbg
from tests.conftest import service_or_skip


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """Redis, PostgreSQL, two nodes and HAProxy (deploy/cluster.py), for one test module."""
    started = service_or_skip(lambda: Cluster.up(2, tmp_path_factory.mktemp("cluster")))
    yield started
    started.down()


@pytest.fixture
def stub(cluster):
    """A Director stub on the balancer's gRPC address."""
    channel = grpc.insecure_channel(cluster.grpc)
    yield pbg.DirectorStub(channel)
    channel.close()


def route(key: str) -> list[tuple[str, str]]:
    """The metadata the SDKs send with every call of a session."""
    return [(ROUTE_HEADER, key)]


def new_keys(n: int) -> list[str]:
    return [uuid.uuid4().hex for _ in range(n)]


def sessions_by_node(cluster: Cluster) -> dict[str, set[str]]:
    """{node_id: session ids it holds} from each live node's REST listing."""
    held = {}
    for node in cluster.nodes:
        try:
            with urllib.request.urlopen(f"http://{node.http}/v1/sessions", timeout=5) as reply:
                held[node.node_id] = {s["session_id"] for s in json.load(reply)["sessions"]}
        except OSError:
            held[node.node_id] = set()  # a node killed by a test
    return held


def node_of(held: dict[str, set[str]], session_id: str) -> str:
    (node,) = [name for name, ids in held.items() if session_id in ids]
    return node
