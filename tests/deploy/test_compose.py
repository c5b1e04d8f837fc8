"""docker/compose.cluster.yaml: no container engine runs on the test machines, so its syntax and
content are checked instead: the services, one data volume shared by every node and worker, one
node id each, and an haproxy.cfg that is what deploy/haproxy.py writes for those nodes and that
HAProxy accepts."""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from camdirector.deploy.haproxy import compose_config

COMPOSE = Path(__file__).resolve().parents[2] / "docker" / "compose.cluster.yaml"


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
    sharing = [s for name, s in compose["services"].items() if name in nodes(compose) or name == "job-worker"]
    assert all("camdirector-data:/var/lib/camdirector" in s["volumes"] for s in sharing)
    assert set(compose["volumes"]) == {"camdirector-data", "postgres-data"}


def test_the_haproxy_config_is_what_haproxy_py_writes_and_haproxy_accepts(compose, tmp_path):
    content = compose["configs"]["haproxy_cfg"]["content"]
    assert content == compose_config(len(nodes(compose)))
    if shutil.which("haproxy") is None and not Path("/usr/sbin/haproxy").exists():
        pytest.skip("haproxy is not installed (Debian package haproxy)")
    (tmp_path / "haproxy.cfg").write_text(content)
    checked = subprocess.run([shutil.which("haproxy") or "/usr/sbin/haproxy", "-c", "-f", str(tmp_path / "haproxy.cfg")],
                             capture_output=True, text=True)
    assert checked.returncode == 0, checked.stderr  # node names unresolved here leave those servers down, not an error
