"""The service image (docker/Dockerfile) built with Debian's podman and run as a user runs it: TLS
files mounted, keys on, the data directory a named volume. From the host, as clients: gRPC health,
a session of each rig over gRPC (TLS and the admin key the first start wrote to the volume) and
ZeroMQ (CURVE, the server key from the volume), a level added over REST, a monitor picture and an
overview job rendered with EGL inside. Then the container is killed (`podman kill`: SIGKILL, as a
crash) and started again on the same volume: a session streamed before goes on from its checkpoint,
and an overview job queued before the kill finishes.

The image is built once for the module (deploy/image.py: the local debootstrap base made once per
machine, then podman's layer cache). Where podman, runc or debootstrap is missing, or the tests do
not run as root (rootful podman, debootstrap), the module skips with the reason; under CI (.ci/run
sets CAMDIRECTOR_REQUIRE_PODMAN=1) that is a failure. A failed build is a failure everywhere."""

from __future__ import annotations

import os
import re
import ssl
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import grpc
import httpx
import numpy as np
import pytest
import zmq.auth
from grpc_health.v1 import health_pb2, health_pb2_grpc

from camdirector.deploy import image as podman_image
from camdirector.deploy.compose import require_podman_compose
from camdirector.deploy.services import ServiceError, free_port
from camdirector.deploy.tls import make_tls_files
from camdirector.v1 import director_pb2 as pb
from camdirector.version import VERSION
from tests import served_checks as checks
from tests.conftest import why_no_image
from tests.precompute.tracks.tiny_levels import corridor
from tests.service.test_failover import _undisturbed as undisturbed
from tests.service.wire_client import two_target_request, walk

ROOT = Path(__file__).resolve().parents[2]
USER_ID = 10001  # the image's `camdirector` user (docker/Dockerfile)
TLS_IN = "/etc/camdirector/tls"

pytestmark = pytest.mark.timeout(1800)  # a fresh machine downloads every dependency into the image


def test_the_dockerfile_labels_the_project_version_by_default():
    """`docker build` without --build-arg VERSION (docker/compose*.yaml) labels this version too."""
    text = (ROOT / "docker" / "Dockerfile").read_text()
    assert re.findall(r"^ARG VERSION=(\S+)$", text, re.MULTILINE) == [VERSION]
    assert 'org.opencontainers.image.version="${VERSION}"' in text


def podman_or_skip(compose: bool = False) -> None:
    """A skip with the reason where this machine cannot build and run the image (and, with
    `compose`, run docker/compose.cluster.yaml); under CI a failure."""
    why = why_no_image()
    if why is None and compose:
        try:
            require_podman_compose()
        except ServiceError as exc:
            why = str(exc)
    if why is not None:
        if os.environ.get("CAMDIRECTOR_REQUIRE_PODMAN") == "1":
            pytest.fail(f"{why} (CAMDIRECTOR_REQUIRE_PODMAN=1)")
        pytest.skip(why)


@pytest.fixture(scope="module")
def image() -> str:
    podman_or_skip()
    started = time.monotonic()
    tag = podman_image.build_image(ROOT)  # a failed build raises: a failure, never a skip
    print(f"image {tag}: built in {time.monotonic() - started:.0f} s, {podman_image.image_size(tag) / 1e6:.0f} MB")
    return tag


@dataclass
class Running(checks.Served):
    """The container, reached from the host as a client (served_checks.Served)."""

    container: podman_image.Container | None = None
    ports: dict[str, int] = field(default_factory=dict)


def reach(container: podman_image.Container, ca: Path, ports: dict[str, int]) -> Running:
    """Waits until the container's HTTPS answers /healthz; the clients for it, with the admin key
    and the CURVE server key read from its volume."""
    http = f"127.0.0.1:{ports['http']}"
    context = ssl.create_default_context(cafile=str(ca))
    deadline = time.monotonic() + 180
    while True:
        try:
            if httpx.get(f"https://{http}/healthz", verify=context, timeout=2).status_code == 200:
                break
        except httpx.HTTPError:
            pass
        assert container.running(), f"the container exited:\n{container.logs()}"
        assert time.monotonic() < deadline, f"the container did not answer in 180 s:\n{container.logs()}"
        time.sleep(0.5)
    volume = container.volume_path()
    key = (volume / "admin.key").read_text().strip()
    client = httpx.Client(base_url=f"https://{http}", verify=context, timeout=30.0, headers={"Authorization": f"Bearer {key}"})
    return Running(
        grpc=f"127.0.0.1:{ports['grpc']}",
        zmq=f"tcp://127.0.0.1:{ports['zmq']}",
        client=client,
        log_tail=container.logs,
        key=key,
        ca_file=ca,
        zmq_server_key=zmq.auth.load_certificate(volume / "zmq" / "server.key")[0].decode(),
        container=container,
        ports=ports,
    )


@pytest.fixture(scope="module")
def served(image, tmp_path_factory):
    """The image run as docs/container.md says: TLS files mounted (the key given to the image's
    user), keys on, a named volume; on the host's network, bound to free loopback ports."""
    tls_dir = tmp_path_factory.mktemp("image-tls")
    tls = make_tls_files(tls_dir)
    tls_dir.chmod(0o755)
    os.chown(tls.key, USER_ID, USER_ID)
    ports = {"grpc": free_port(), "zmq": free_port(), "http": free_port()}
    name = f"camdirector-test-{uuid.uuid4().hex[:10]}"
    container = podman_image.Container(
        image,
        name,
        volume=name,
        mounts=[f"{tls_dir}:{TLS_IN}:ro"],
        env={
            "CAMDIRECTOR_GRPC_ADDR": f"127.0.0.1:{ports['grpc']}",
            "CAMDIRECTOR_ZMQ_ADDR": f"tcp://127.0.0.1:{ports['zmq']}",
            "CAMDIRECTOR_HTTP_ADDR": f"127.0.0.1:{ports['http']}",
            "CAMDIRECTOR_TLS_CERT": f"{TLS_IN}/server.pem",
            "CAMDIRECTOR_TLS_KEY": f"{TLS_IN}/server.key",
            "CAMDIRECTOR_WORKERS": "1",
            "CAMDIRECTOR_MAX_CONCURRENT_JOBS": "1",
        },
    )
    try:
        container.start()
        running = reach(container, tls.ca_cert, ports)
        yield running
        running.client.close()
    finally:
        container.remove()


@pytest.fixture(scope="module")
def corridor_level(served) -> str:
    """The corridor level, added over REST (what the tracks rig's sessions stand in)."""
    checks.add_level_over_rest(served, "corridor", corridor())
    return "corridor"


def test_the_image_is_labelled_runs_unprivileged_and_keeps_its_data_in_a_volume(image):
    assert podman_image.image_label(image) == VERSION
    found = podman_image.inspect(image)
    assert found["Config"]["User"] == "camdirector"
    assert "/var/lib/camdirector" in found["Config"]["Volumes"]
    assert (found.get("Healthcheck") or {}).get("Test"), "no health check (podman keeps it with --format docker)"
    print(f"image size: {podman_image.image_size(image) / 1e6:.0f} MB")  # reported, not asserted


def test_grpc_health_and_the_image_health_check(served):
    credentials = grpc.composite_channel_credentials(
        grpc.ssl_channel_credentials(served.ca_file.read_bytes()), grpc.access_token_call_credentials(served.key)
    )
    with grpc.secure_channel(served.grpc, credentials) as channel:
        reply = health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(), timeout=10)
    assert reply.status == health_pb2.HealthCheckResponse.SERVING
    assert served.container.health() == "healthy"
    assert served.container.exec("id", "-u").strip() == str(USER_ID)


def test_the_compiled_module_is_in_the_venv_and_no_toolchain_in_the_image(served):
    """The build stage compiled camdirector._native into the wheel; the final stage copied only the
    venv, so neither Rust nor a C compiler came with it."""
    where = served.container.exec("python", "-c", "import camdirector._native as n; print(n.__file__, n.__version__)").split()
    assert where == ["/opt/camdirector/venv/lib/python3.11/site-packages/camdirector/_native.abi3.so", VERSION]
    tools = "cargo rustc rustup gcc cc"
    found = served.container.exec("sh", "-c", f"for t in {tools}; do command -v $t; done; ls -d /opt/*")
    assert found.split() == ["/opt/camdirector"], found


def test_a_level_added_over_rest_is_listed(served, corridor_level):
    assert [level["name"] for level in served.client.get("/v1/levels").json()["levels"]] == [corridor_level]
    checks.tracks_session_on(served, corridor_level)


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
@pytest.mark.parametrize("rig", ["toric", "match", "tracks"])
def test_a_session_of_each_rig_over_each_transport(served, corridor_level, rig, transport):
    checks.session_of_rig(served, rig, transport, level=corridor_level)


def test_a_monitor_picture_rendered_inside(served):
    checks.monitor_picture(served)


@pytest.mark.shared_data
def test_an_overview_job_completes(served, run_bvh):
    checks.assert_overview_done(served, checks.post_overview_job(served, run_bvh))


def pose_values(pose: pb.CameraPose) -> list[float]:
    p, q = pose.position, pose.rotation
    return [p.x, p.y, p.z, q.x, q.y, q.z, q.w, pose.vertical_fov_deg]


@pytest.mark.shared_data
def test_a_killed_container_started_again_restores_its_session_and_finishes_a_queued_job(served, run_bvh, tmp_path):
    import camdirector_client as cd

    create = two_target_request(style=pb.Style(visibility=pb.RAYCAST), seed=9)
    updates = [pb.FrameUpdate(frame=u.frame, time_s=u.time_s, states=u.states) for u in walk("x", 150)]
    url = f"grpcs://{served.grpc}"
    client = cd.connect(url, key=served.key, ca_file=str(served.ca_file))
    try:
        session = client.create_session(create)
        answers = [session.send(u) for u in updates[:100]]
        # one job running (max_concurrent_jobs 1) and one queued behind it when the container dies
        jobs = [checks.post_overview_job(served, run_bvh) for _ in range(2)]
        served.container.kill()
        assert not served.container.running()
        served.container.start()
        again = reach(served.container, served.ca_file, served.ports)
        served.client.close()
        served.client = again.client
        answers += [session.send(u) for u in updates[100:]]  # the same session, restored from its checkpoint
        assert [a.frame for a in answers] == [u.frame for u in updates]
        assert session.close() == 150
    finally:
        client.close()
    # the same inputs in a session nothing disturbed (this process's SessionTable, checkpoints off)
    expected = undisturbed(tmp_path, create, updates)
    assert all(a.pose.vertical_fov_deg > 0 for a in answers)
    got, want = np.array([pose_values(a.pose) for a in answers]), np.array([pose_values(p) for p in expected])
    assert np.allclose(got, want, atol=1e-6), f"largest differences: {np.abs(got - want).max(axis=0)}"
    for job in jobs:
        checks.assert_overview_done(served, job)
