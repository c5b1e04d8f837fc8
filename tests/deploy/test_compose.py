"""docker/compose.cluster.yaml: no container engine runs on the test machines, so its syntax and
content are checked instead: the services, one data volume shared by every node and worker, one
node id each, TLS files for every node and the balancer, and an haproxy.cfg that is what
deploy/haproxy.py writes for those nodes and that HAProxy accepts."""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from camdirector.deploy.haproxy import COMPOSE_TLS_DIR, compose_config
from camdirector.deploy.tls import files_in

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
        # keys on (no CAMDIRECTOR_AUTH to turn them off), TLS with the files the balancer trusts
        assert not {"CAMDIRECTOR_AUTH", "CAMDIRECTOR_INSECURE"} & set(env)
        tls = files_in(COMPOSE_TLS_DIR)
        assert (env["CAMDIRECTOR_TLS_CERT"], env["CAMDIRECTOR_TLS_KEY"]) == (str(tls.cert), str(tls.key))
    # node-1 makes the admin key and the CURVE key pair in the shared volume before the others start
    assert all(s["depends_on"] == {"node-1": {"condition": "service_healthy"}}
               for name, s in nodes(compose).items() if name != "node-1")
    mounting_tls = [s for name, s in compose["services"].items() if name in nodes(compose) or name == "haproxy"]
    assert all(f"./tls:{COMPOSE_TLS_DIR}:ro" in s["volumes"] for s in mounting_tls)
    sharing = [s for name, s in compose["services"].items() if name in nodes(compose) or name == "job-worker"]
    assert all("camdirector-data:/var/lib/camdirector" in s["volumes"] for s in sharing)
    assert set(compose["volumes"]) == {"camdirector-data", "postgres-data"}


def test_the_haproxy_config_is_what_haproxy_py_writes_and_haproxy_accepts(compose, tmp_path, tls_files):
    content = compose["configs"]["haproxy_cfg"]["content"]
    assert content == compose_config(len(nodes(compose)))
    if shutil.which("haproxy") is None and not Path("/usr/sbin/haproxy").exists():
        pytest.skip("haproxy is not installed (Debian package haproxy)")
    # HAProxy reads the TLS files it names while checking: those of `python -m camdirector.deploy.tls`
    (tmp_path / "haproxy.cfg").write_text(content.replace(str(COMPOSE_TLS_DIR), str(tls_files.ca_cert.parent)))
    checked = subprocess.run([shutil.which("haproxy") or "/usr/sbin/haproxy", "-c", "-f", str(tmp_path / "haproxy.cfg")],
                             capture_output=True, text=True)
    assert checked.returncode == 0, checked.stderr  # node names unresolved here leave those servers down, not an error
