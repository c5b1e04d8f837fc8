"""docker/compose.cluster.yaml run as a studio runs it, each part in its own container on one
compose network (deploy/compose.py: Debian's podman-compose; the service image; HAProxy, Redis and
PostgreSQL from docker/stand-ins where no registry is reachable): every node healthy behind the
balancer, an overview job run by the queue worker's container, then load_tests.failover's run
with 12 sessions streaming through the balancer while the node container holding the most is
killed: none lost, every frame answered, every pose equal to an undisturbed run's; the container
started again rejoins the balancer and takes new sessions.

Skips with the reason where podman, runc, debootstrap or podman-compose is missing or the tests do
not run as root; under CI (CAMDIRECTOR_REQUIRE_PODMAN=1) that is a failure."""

from __future__ import annotations

import ssl
import uuid

import httpx
import pytest

import camdirector_client as cd
from camdirector.demo.client import session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.compose import ComposeCluster
from camdirector.geometry.camera import Lens
from load_tests import failover
from tests import served_checks as checks
from tests.deploy.test_image import ROOT, podman_or_skip

pytestmark = pytest.mark.timeout(1800)  # a fresh machine builds the image and the stand-ins first


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    podman_or_skip(compose=True)
    started = ComposeCluster.up(
        ROOT, tmp_path_factory.mktemp("compose-cluster"), project=f"camdirector-test-{uuid.uuid4().hex[:8]}"
    )
    yield started
    started.down()


def test_every_node_is_up_behind_the_balancer(cluster):
    states = cluster.balancer().server_states()
    assert {backend: set(servers.values()) for backend, servers in states.items()} == {"nodes_grpc": {"UP"}, "nodes_http": {"UP"}}
    assert sorted(states["nodes_grpc"]) == cluster.nodes == ["node-1", "node-2", "node-3"]


@pytest.mark.shared_data
def test_an_overview_job_is_run_by_the_queue_worker_container(cluster, run_bvh):
    """Nodes only queue jobs in a cluster (docs/jobs.md): this one finishing means the worker's
    container took it from Redis, and its record is in PostgreSQL."""
    with httpx.Client(
        base_url=f"https://{cluster.http}",
        timeout=30.0,
        verify=ssl.create_default_context(cafile=str(cluster.ca_file)),
        headers={"Authorization": f"Bearer {cluster.admin_key}"},
    ) as client:
        served = checks.Served(grpc=cluster.grpc, zmq="", client=client, log_tail=lambda: cluster.logs("job-worker"))
        checks.assert_overview_done(served, checks.post_overview_job(served, run_bvh))


def test_a_killed_node_container_loses_no_session(cluster):
    report = failover.run(
        "node-container", nodes=3, sessions=12, rate_hz=30.0, seconds=8.0, kill_after_s=3.0, compose_cluster=cluster
    )
    assert report["sessions_on_killed"] > 0, report
    if report["sessions_lost"] or report["frames_not_answered"]:
        lost = {k: report[k] for k in ("sessions_lost", "errors", "frames_not_answered", "unanswered_per_session")}
        pytest.fail(f"{lost}\n{_what_the_cluster_logged(cluster)}", pytrace=False)
    assert report["max_pose_difference"] == 0.0, report["max_pose_difference_per_session"]
    assert report["interrupted_sessions"] > 0, report  # the kill broke streams, which the SDK resumed elsewhere
    assert report["killed_container_rejoined_s"] is not None  # started again, HAProxy sees it UP
    # and takes new sessions again: HAProxy that goes on connecting to its old address sends each
    # one elsewhere after its connect timeout (deploy/haproxy.py, REUSE_PER_CLIENT)
    assert _sessions_until_one_is_on(cluster, report["killed_node"]) is not None, _what_the_cluster_logged(cluster)


def _sessions_until_one_is_on(cluster, node: str, most: int = 24) -> int | None:
    """How many sessions created through the balancer it took for one to be held by `node`; None
    when none of `most` was (each lands on a node by its random route key: with three nodes up
    none of 24 misses one of them once in 17,000)."""
    client = cd.connect(f"grpcs://{cluster.grpc}", key=cluster.admin_key, ca_file=cluster.ca_file, timeout_s=60.0)
    request = session_request(build_demo_scene(), Lens(vertical_fov_deg=50.0, aspect=16 / 9), cd.pb.FRAMING_ONLY)
    try:
        for created in range(1, most + 1):
            session = client.create_session(request)
            if session.id in cluster.sessions_on(node):
                return created
        return None
    finally:
        client.close()


def _what_the_cluster_logged(cluster, lines: int = 12) -> str:
    """The last lines of the balancer's log (HAProxy logs errors and state changes only) and of
    each node's that are not routine, for a failure's message: where a session's frames went is in
    them, not in the client's report. Short: CI shows a failure's tail."""
    said = []
    for service in ("haproxy", *cluster.nodes):
        kept = []
        for line in cluster.logs(service, chars=20000).splitlines():
            if line and '"event": "ready"' not in line and not line.startswith("[") and line not in kept[-1:]:
                kept.append(line[:300])  # HAProxy writes each line twice, once with a "[LEVEL] (pid) :" prefix
        said.append(f"--- {service} ---\n" + "\n".join(kept[-lines:]))
    return "\n".join(said)
