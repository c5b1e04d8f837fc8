"""docker/compose.cluster.yaml's content, checked without running it (test_compose_cluster.py runs
it): the services, one data volume shared by every node and worker, one node id each, TLS files
for every node and the balancer, the public images by default, and the haproxy.cfg it mounts
(docker/haproxy.cluster.cfg), which is what deploy/haproxy.py writes for those nodes and what
HAProxy accepts."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from camdirector.deploy.compose import ComposeCluster
from camdirector.deploy.haproxy import COMPOSE_TLS_DIR, compose_config
from camdirector.deploy.tls import files_in

DOCKER = Path(__file__).resolve().parents[2] / "docker"
COMPOSE = DOCKER / "compose.cluster.yaml"
TLS_MOUNT = f"${{CAMDIRECTOR_TLS_DIR:-./tls}}:{COMPOSE_TLS_DIR}:ro"


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load(COMPOSE.read_text())


def nodes(compose: dict) -> dict[str, dict]:
    return {name: s for name, s in compose["services"].items() if re.fullmatch(r"node-\d+", name)}


def test_the_services_and_what_each_node_is_told(compose):
    assert {"redis", "postgres", "haproxy", "job-worker"} <= set(compose["services"])
    assert len(nodes(compose)) >= 2
    for name, service in nodes(compose).items():
        env = service["environment"]
        assert env["CAMDIRECTOR_NODE_ID"] == name
        assert env["CAMDIRECTOR_CHECKPOINT_STORE"].startswith("redis://redis:")
        assert env["CAMDIRECTOR_JOB_STORE"].startswith("postgresql://camdirector@postgres:")
        assert env["CAMDIRECTOR_JOB_QUEUE"].startswith("redis://redis:")
        assert service["build"]["dockerfile"] == "docker/Dockerfile"
        # keys on (no CAMDIRECTOR_AUTH to turn them off), TLS with the files the balancer trusts
        assert not {"CAMDIRECTOR_AUTH", "CAMDIRECTOR_INSECURE"} & set(env)
        tls = files_in(COMPOSE_TLS_DIR)
        assert (env["CAMDIRECTOR_TLS_CERT"], env["CAMDIRECTOR_TLS_KEY"]) == (str(tls.cert), str(tls.key))
    # node-1 makes the admin key and the CURVE key pair in the shared volume before the others start
    assert all(
        s["depends_on"] == {"node-1": {"condition": "service_healthy"}} for name, s in nodes(compose).items() if name != "node-1"
    )
    mounting_tls = [s for name, s in compose["services"].items() if name in nodes(compose) or name == "haproxy"]
    assert all(TLS_MOUNT in s["volumes"] for s in mounting_tls)
    sharing = [s for name, s in compose["services"].items() if name in nodes(compose) or name == "job-worker"]
    assert all("camdirector-data:/var/lib/camdirector" in s["volumes"] for s in sharing)
    assert set(compose["volumes"]) == {"camdirector-data", "postgres-data"}


def test_deploy_compose_finds_the_same_node_services(compose, tmp_path):
    """deploy/compose.py reads the node services without a YAML parser (the installed package has none)."""
    assert ComposeCluster(COMPOSE.parents[1], tmp_path, "p", {}).nodes == sorted(nodes(compose)) == ["node-1", "node-2", "node-3"]


def test_users_get_the_public_images_and_the_documented_ports_by_default(compose):
    """The variables deploy/compose.py sets (local stand-ins, free ports) default to what a user
    with a registry runs."""
    images = {name: s["image"] for name, s in compose["services"].items()}
    assert images["redis"] == "${CAMDIRECTOR_REDIS_IMAGE:-redis:7-bookworm}"
    assert images["postgres"] == "${CAMDIRECTOR_POSTGRES_IMAGE:-postgres:15-bookworm}"
    assert images["haproxy"] == "${CAMDIRECTOR_HAPROXY_IMAGE:-haproxy:2.6}"
    assert {images[name] for name in nodes(compose)} | {images["job-worker"]} == {"${CAMDIRECTOR_IMAGE:-camdirector:latest}"}
    assert compose["services"]["haproxy"]["ports"] == [
        "${CAMDIRECTOR_GRPC_PORT:-50051}:50051",
        "${CAMDIRECTOR_HTTP_PORT:-8080}:8080",
    ]
    # each stand-in is a target of docker/stand-ins/Dockerfile
    targets = re.findall(r"^FROM \S+ AS (\w+)$", (DOCKER / "stand-ins" / "Dockerfile").read_text(), re.MULTILINE)
    assert sorted(targets) == ["haproxy", "postgres", "redis"]


def test_the_haproxy_config_is_what_haproxy_py_writes_and_haproxy_accepts(compose, tmp_path, tls_files):
    assert "configs" not in compose  # podman-compose 1.0.3 has no inline configs: the file is mounted
    assert "./haproxy.cluster.cfg:/usr/local/etc/haproxy/haproxy.cfg:ro" in compose["services"]["haproxy"]["volumes"]
    content = (DOCKER / "haproxy.cluster.cfg").read_text()
    assert content == compose_config(len(nodes(compose)))
    if shutil.which("haproxy") is None and not Path("/usr/sbin/haproxy").exists():
        pytest.skip("haproxy is not installed (Debian package haproxy)")
    # HAProxy reads the TLS files it names while checking: those of `python -m camdirector.deploy.tls`
    (tmp_path / "haproxy.cfg").write_text(content.replace(str(COMPOSE_TLS_DIR), str(tls_files.ca_cert.parent)))
    checked = subprocess.run(
        [shutil.which("haproxy") or "/usr/sbin/haproxy", "-c", "-f", str(tmp_path / "haproxy.cfg")],
        capture_output=True,
        text=True,
    )
    assert checked.returncode == 0, checked.stderr  # node names unresolved here leave those servers down, not an error
