"""The dashboard's login from outside, against real servers with keys (docs/security.md, "A
dashboard login's life"): a login ends when the secret is rotated (`camdirector keys rotate-secret`) or at
logout, on every node within the revocation poll (two nodes over PostgreSQL, one over SQLite); a
malformed cookie, CSRF token or Origin answers 401 or 403, never 500; and a local user who reads
what the server left readable in its data folder cannot forge a login."""

from __future__ import annotations

import re
import stat
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.front.http.auth import COOKIE, CSRF_HEADER, CookieSigner

NODES_POLL_S = 1.5  # a change reaches every node within the 0.25-s poll; the rest is a loaded machine's room


def keys_command(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "camdirector", "keys", *args], capture_output=True, text=True, timeout=60)


def keyed_node(data_dir: Path, *args: str) -> ServerProcess:
    return ServerProcess("--workers", "0", "--data-dir", str(data_dir), *args, transports=("http",), auth=True)


@pytest.fixture
def cluster(records_url, tmp_path):
    """One node on SQLite, or two sharing a PostgreSQL; `records`: the keys command's arguments
    that reach their records."""
    shared = ["--job-store", records_url] if records_url else []
    nodes = [keyed_node(tmp_path / "a", *shared)]  # the first makes the admin key
    try:
        if records_url:
            nodes.append(keyed_node(tmp_path / "b", *shared))
        yield SimpleNamespace(nodes=nodes, records=shared or ["--data-dir", str(tmp_path / "a")], admin_key=nodes[0].admin_key)
    finally:
        stopped = [node.stop() for node in nodes]
    assert stopped == [0] * len(nodes), "a node did not exit cleanly"


@pytest.fixture(scope="module")
def node(tmp_path_factory):
    """One node on SQLite, its data folder (made by the server) as `.data_dir`."""
    data_dir = tmp_path_factory.mktemp("login-node") / "data"
    with keyed_node(data_dir) as server:
        server.data_dir = data_dir
        yield server


def log_in(node: ServerProcess, key: str) -> tuple[str, str]:
    """(the login cookie, its CSRF token), as the dashboard gets them."""
    reply = httpx.post(f"http://{node.http}/v1/login", json={"key": key})
    assert reply.status_code == 200, reply.text
    return reply.cookies[COOKIE], reply.json()["csrf_token"]


def with_cookie(cookie: str | bytes) -> dict:
    return {"Cookie": (COOKIE.encode() + b"=" + cookie) if isinstance(cookie, bytes) else f"{COOKIE}={cookie}"}


def whoami(node: ServerProcess, cookie: str | bytes) -> httpx.Response:
    return httpx.get(f"http://{node.http}/v1/whoami", headers=with_cookie(cookie))


def refused_everywhere_soon(nodes: list[ServerProcess], cookie: str) -> None:
    deadline = time.monotonic() + NODES_POLL_S
    while (codes := [whoami(node, cookie).status_code for node in nodes]) != [401] * len(nodes):
        assert time.monotonic() < deadline, f"still answered {codes} {NODES_POLL_S} s on"
        time.sleep(0.02)


def test_rotating_the_secret_ends_every_login_on_every_node_and_a_new_login_works(cluster):
    cookie, _ = log_in(cluster.nodes[0], cluster.admin_key)
    assert [whoami(node, cookie).status_code for node in cluster.nodes] == [200] * len(cluster.nodes)
    rotated = keys_command("rotate-secret", *cluster.records)
    assert rotated.returncode == 0 and "every login" in rotated.stdout, rotated
    refused_everywhere_soon(cluster.nodes, cookie)
    assert "log in again" in whoami(cluster.nodes[0], cookie).json()["detail"]
    fresh, _ = log_in(cluster.nodes[-1], cluster.admin_key)
    assert [whoami(node, fresh).status_code for node in cluster.nodes] == [200] * len(cluster.nodes)


def test_a_cookie_replayed_after_logout_is_refused_on_every_node(cluster):
    cookie, _ = log_in(cluster.nodes[0], cluster.admin_key)
    elsewhere, _ = log_in(cluster.nodes[-1], cluster.admin_key)  # the same key, another browser
    out = httpx.post(f"http://{cluster.nodes[0].http}/v1/logout", headers=with_cookie(cookie))
    assert out.status_code == 204 and f'{COOKIE}=""' in out.headers["set-cookie"]
    refused = whoami(cluster.nodes[0], cookie)  # the copied cookie, where it logged out: at once
    assert refused.status_code == 401 and "logged out" in refused.json()["detail"], refused.text
    refused_everywhere_soon(cluster.nodes, cookie)
    assert [whoami(node, elsewhere).status_code for node in cluster.nodes] == [200] * len(cluster.nodes)
    assert httpx.post(f"http://{cluster.nodes[0].http}/v1/logout", headers=with_cookie(cookie)).status_code == 204


@pytest.mark.parametrize(
    "cookie",
    [
        "é".encode(),
        b"x.1.\xc3\xa9",
        b"0123456789ab.0123456789abcdef0123456789abcdef.9999999999.\xc3\xa9" + b"A" * 42,
        b"0123456789ab.0123456789abcdef0123456789abcdef.9999999999." + b"!" * 43,
        b"0123456789ab.9999999999.@@@",
        b"....",
        b"x" * 3000,
    ],
)
def test_a_malformed_cookie_answers_401(node, cookie):
    reply = whoami(node, cookie)
    assert reply.status_code == 401 and "log in again" in reply.json()["detail"], reply.text


@pytest.mark.parametrize(
    "headers",
    [
        {CSRF_HEADER: "é".encode()},
        {CSRF_HEADER: b"\xff" * 43},
        {CSRF_HEADER: b"not base64 at all!"},
        {"Origin": b"http://[", "token": True},
        {"Origin": "http://é.example".encode(), "token": True},
    ],
)
def test_a_malformed_csrf_token_or_origin_answers_403(node, headers):
    cookie, token = log_in(node, node.admin_key)
    sent = {**with_cookie(cookie), **{name: value for name, value in headers.items() if name != "token"}}
    if headers.get("token"):
        sent[CSRF_HEADER] = token  # the right token, from a wrong Origin
    reply = httpx.post(f"http://{node.http}/v1/keys", json={"role": "viewer"}, headers=sent)
    assert reply.status_code == 403 and CSRF_HEADER in reply.json()["detail"], reply.text


def readable_by_others(data_dir: Path) -> list[Path]:
    """The files under `data_dir` that its group or anyone else may read: a read bit on the file
    and the search bit on every folder down to it, for the same class of user."""
    found = []
    for path in sorted(p for p in data_dir.rglob("*") if p.is_file()):
        folders = [data_dir, *(data_dir / f for f in path.relative_to(data_dir).parents if f != Path("."))]
        for read, search in ((stat.S_IRGRP, stat.S_IXGRP), (stat.S_IROTH, stat.S_IXOTH)):
            if path.stat().st_mode & read and all(folder.stat().st_mode & search for folder in folders):
                found.append(path)
                break
    return found


def test_a_local_user_cannot_forge_a_login_from_what_the_data_folder_lets_others_read(node):
    log_in(node, node.admin_key)  # a login made: the secret in use, the records written
    readable = readable_by_others(node.data_dir)
    # The records keep secrets as 64 hex digits, in pages where other text may touch them: every
    # 64 digits of a run of hex digits in a readable file are tried as the cookie secret, for the
    # admin key's id (granted to the attacker: an id is no secret).
    runs = [run.decode() for path in readable for run in re.findall(rb"[0-9a-f]{64,}", path.read_bytes())]
    candidates = {bytes.fromhex(run[i : i + 64]) for run in runs for i in range(len(run) - 63)}
    admin_id = node.admin_key.split("_")[1]
    forged = [s.hex()[:8] for s in candidates if whoami(node, CookieSigner(lambda s=s: s).cookie(admin_id)).status_code == 200]
    assert not forged, f"a login forged from what others may read: {[str(p.relative_to(node.data_dir)) for p in readable]}"
