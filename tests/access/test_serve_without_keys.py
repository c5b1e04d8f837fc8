"""A real `camdirector serve` without keys (`--no-auth`) and with `--insecure`: both say so on
stderr and in /healthz; without keys it stays on this machine unless told otherwise, makes and
revokes no key, and takes changes only from its own address and pages (docs/security.md)."""

from __future__ import annotations

import subprocess
import sys

import httpx

from camdirector.deploy.server_process import ServerProcess
from tests.service import wire_client as wc


def test_no_auth_and_insecure_warn_on_stderr_and_show_in_healthz():
    with ServerProcess("--workers", "0", transports=("http",)) as open_server:
        assert "WARNING" in open_server.log_tail() and "--no-auth: every caller" in open_server.log_tail()
        health = httpx.get(f"http://{open_server.http}/healthz").json()
        assert (health["auth"], health["insecure"]) == (False, False)
    with ServerProcess("--workers", "0", "--insecure", transports=("http",), auth=True) as insecure:
        assert "WARNING" in insecure.log_tail() and "--insecure: " in insecure.log_tail()
        assert "--no-auth" not in insecure.log_tail()
        health = httpx.get(f"http://{insecure.http}/healthz").json()
        assert (health["auth"], health["insecure"]) == (True, True)


def test_no_auth_beyond_loopback_needs_insecure_even_over_tls(tmp_path, tls_files):
    tls = ("--tls-cert", str(tls_files.cert), "--tls-key", str(tls_files.key))
    run = subprocess.run(
        [sys.executable, "-m", "camdirector", "serve", "--workers", "0", "--data-dir", str(tmp_path), *tls, "--no-auth"]
        + ["--grpc", "", "--zmq", "", "--http", "0.0.0.0:0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2, run.stderr
    assert "without keys" in run.stderr and "http on 0.0.0.0:0" in run.stderr and "--insecure" in run.stderr, run.stderr
    with ServerProcess("--workers", "0", *tls, "--http", "0.0.0.0:0", "--insecure", transports=("http",)) as server:
        assert server.http.startswith("0.0.0.0:")


def test_keys_are_neither_made_nor_revoked_without_keys_and_a_restart_with_keys_makes_the_admin_key(tmp_path):
    with ServerProcess("--workers", "0", "--data-dir", str(tmp_path), transports=("http",)) as open_server:
        http = f"http://{open_server.http}"
        made = httpx.post(f"{http}/v1/keys", json={"role": "admin", "name": "left behind"})
        assert made.status_code == 403 and "key" not in made.json(), made.text
        assert "--no-auth" in made.json()["detail"]
        assert httpx.delete(f"{http}/v1/keys/0badc0ffee00").status_code == 403
    assert not (tmp_path / "admin.key").exists()
    with ServerProcess("--workers", "0", "--data-dir", str(tmp_path), transports=("http",), auth=True) as keyed:
        assert keyed.ready["admin_key_file"] == str(tmp_path / "admin.key")  # as on any first start with keys
        keys = httpx.get(f"http://{keyed.http}/v1/keys", headers={"Authorization": f"Bearer {keyed.admin_key}"}).json()
        assert [(k["id"], k["role"]) for k in keys["keys"]] == [(keyed.admin_key.split("_")[1], "admin")]


def test_without_keys_changes_come_only_from_this_servers_own_address_and_pages():
    with ServerProcess("--workers", "0", transports=("grpc", "http")) as server:
        raw = wc.GrpcRaw(server.grpc)
        session_id = raw.call("CreateSession", wc.two_target_request()).session_id
        raw.close()
        http, port = f"http://{server.http}", server.http.rpartition(":")[2]
        style = f"{http}/v1/sessions/{session_id}/style"
        for headers in ({}, {"Origin": http}, {"Host": f"localhost:{port}", "Origin": f"http://localhost:{port}"}):
            assert httpx.put(style, json={"preferredPhiDeg": 30}, headers=headers).status_code == 200, headers
        for headers, blamed in (
            ({"Origin": "https://pages.example"}, "Origin"),  # another site's page
            ({"Origin": "null"}, "Origin"),  # a sandboxed frame or a file
            ({"Origin": f"http://localhost:{port}"}, "Origin"),  # another origin, though this machine
            ({"Host": f"rebound.example:{port}"}, "Host"),  # DNS rebinding: the page's name, this address
            ({"Origin": "http://["}, "Origin"),  # unreadable: refused, not a 500
            ({"Host": "["}, "Host"),
        ):
            refused = httpx.put(style, json={"preferredPhiDeg": 40}, headers=headers)
            assert refused.status_code == 403 and blamed in refused.json()["detail"], (headers, refused.text)
        assert httpx.get(f"{http}/v1/sessions/{session_id}").json()["style"]["preferredPhiDeg"] == 30
        # A page's form, posted across sites: multipart, as a browser sends it without asking first.
        form = httpx.post(
            f"{http}/v1/overview-jobs", files={"file": ("run.bvh", b"HIERARCHY\n")}, headers={"Origin": "https://pages.example"}
        )
        assert form.status_code == 403, form.text
        assert httpx.get(f"{http}/v1/overview-jobs").json()["jobs"] == []
        # A rebound name reads nothing either.
        assert httpx.get(f"{http}/v1/sessions", headers={"Host": f"rebound.example:{port}"}).status_code == 403
