"""A cluster of two nodes behind HAProxy, with keys and TLS, for the module that routes through it;
helpers to reach it as a client does (grpcs:// and https:// trusting the cluster's CA, a key on
every call) and to see where sessions live."""

from __future__ import annotations

import json
import ssl
import urllib.error
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


def trusting(cluster: Cluster) -> ssl.SSLContext:
    """A client's TLS context that trusts the cluster's CA alone."""
    return ssl.create_default_context(cafile=str(cluster.ca_file))


def https(
    cluster: Cluster,
    address: str,
    path: str,
    key: str,
    method: str = "GET",
    body: dict | None = None,
    headers: dict | None = None,
) -> tuple[int, dict]:
    """(status, JSON answer) of one REST call to HOST:PORT over TLS with `key`; an error status is
    an answer too. OSError when nothing answers (a killed node)."""
    request = urllib.request.Request(
        f"https://{address}{path}",
        method=method,
        data=None if body is None else json.dumps(body).encode(),
        headers={"Authorization": f"Bearer {key}", "Content-Type": "application/json", **(headers or {})},
    )
    try:
        with urllib.request.urlopen(request, timeout=10, context=trusting(cluster)) as reply:
            return reply.status, json.load(reply)
    except urllib.error.HTTPError as refused:
        return refused.code, json.load(refused)


def make_key(cluster: Cluster, role: str, address: str | None = None) -> dict:
    """A new key of tenant `default` (its record and, under "key", the key itself), made by the
    admin through `address` (default the balancer)."""
    status, made = https(
        cluster, address or cluster.http, "/v1/keys", cluster.admin_key, "POST", {"role": role, "name": f"tests/deploy {role}"}
    )
    assert status == 201, made
    return made


def channel(cluster: Cluster, address: str, key: str) -> grpc.Channel:
    """A channel to HOST:PORT over TLS (the cluster's CA) that sends `key` with every call."""
    credentials = grpc.composite_channel_credentials(
        grpc.ssl_channel_credentials(cluster.ca_file.read_bytes()), grpc.access_token_call_credentials(key)
    )
    return grpc.secure_channel(address, credentials)


@pytest.fixture(scope="module")
def engine_key(cluster) -> str:
    """A key of role `engine`: what a game streams with."""
    return make_key(cluster, "engine")["key"]


@pytest.fixture
def stub(cluster, engine_key):
    """A Director stub on the balancer's gRPC address, as an engine."""
    with channel(cluster, cluster.grpc, engine_key) as opened:
        yield pbg.DirectorStub(opened)


def route(key: str) -> list[tuple[str, str]]:
    """The metadata the SDKs send with every call of a session."""
    return [(ROUTE_HEADER, key)]


def new_keys(n: int) -> list[str]:
    return [uuid.uuid4().hex for _ in range(n)]


def sessions_by_node(cluster: Cluster) -> dict[str, set[str]]:
    """{node_id: session ids it holds} from each live node's REST listing (the admin's)."""
    held = {}
    for node in cluster.nodes:
        try:
            status, listing = https(cluster, node.http, "/v1/sessions", cluster.admin_key)
            assert status == 200, listing
            held[node.node_id] = {s["session_id"] for s in listing["sessions"]}
        except OSError:
            held[node.node_id] = set()  # a node killed by a test
    return held


def node_of(held: dict[str, set[str]], session_id: str) -> str:
    (node,) = [name for name, ids in held.items() if session_id in ids]
    return node
