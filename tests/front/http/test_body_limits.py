"""Bounded before authenticated (front/http/body_limits.py, issue 39 finding 3) against a real
server with keys: a body over its route's limit answers 413 before it is read, a route that needs
a key answers 401 before its body is read, and a 422 never echoes what was sent. The requests go
over raw sockets that send only the start of the body: an answer that arrives proves the server
did not wait for the rest."""

from __future__ import annotations

import socket
import time

import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.front.http.body_limits import LOGIN_BODY_BYTES

pytestmark = pytest.mark.timeout(120)

UPLOAD_LIMIT = 64 * 1024


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    data_dir = tmp_path_factory.mktemp("body-limits")
    srv = ServerProcess(
        "--workers",
        "0",
        "--data-dir",
        str(data_dir),
        "--max-upload-bytes",
        str(UPLOAD_LIMIT),
        transports=("http",),
        auth=True,
    )
    yield srv
    srv.stop()


def _answer_to_partial(server, head: str, first_part: bytes, timeout_s: float = 5.0) -> tuple[int, bytes, float]:
    """Sends `head` (request line and headers) and `first_part` of the body, never the rest;
    returns (status, the answer's bytes, seconds until it came). socket.timeout when the server
    waits for the rest of the body instead of answering."""
    host, port = server.http.rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=timeout_s) as sock:
        t0 = time.perf_counter()
        sock.sendall(head.encode() + b"\r\n" + first_part)
        answer = b""
        while b"\r\n\r\n" not in answer or len(answer) < answer.index(b"\r\n\r\n") + 4 + _length(answer):
            chunk = sock.recv(65536)
            if not chunk:
                break
            answer += chunk
        elapsed = time.perf_counter() - t0
    return int(answer.split(b" ", 2)[1]), answer, elapsed


def _length(answer: bytes) -> int:
    for line in answer.split(b"\r\n\r\n", 1)[0].split(b"\r\n"):
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            return int(value)
    return 0


def test_a_12_mib_login_answers_413_at_once_without_reading_or_echoing_it(server):
    body_start = b'{"key": "' + b"A" * 60_000
    head = f"POST /v1/login HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: {12 * 1024 * 1024}\r\n"
    status, answer, elapsed = _answer_to_partial(server, head, body_start)
    assert status == 413 and b"AAAA" not in answer and len(answer) < 1024
    assert f"limit of {LOGIN_BODY_BYTES} bytes".encode() in answer
    assert elapsed < 2.0


def test_a_chunked_login_is_counted_as_it_arrives(server):
    head = "POST /v1/login HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n"
    chunk = b'{"key": "' + b"B" * 2000
    chunks = b"".join(b"%x\r\n%s\r\n" % (len(chunk), chunk) for _ in range(3))  # 6 KiB, no last chunk
    status, answer, _ = _answer_to_partial(server, head, chunks)
    assert status == 413 and b"BBBB" not in answer


def test_an_upload_without_a_valid_key_answers_401_before_its_body_is_read(server):
    boundary = "cdboundary"
    first_part = (
        f'--{boundary}\r\nContent-Disposition: form-data; name="level"; filename="big.obj"\r\n\r\n'.encode() + b"v 0 0 0\n" * 512
    )
    for authorization in ("", "Authorization: Bearer cdk_not-a-key\r\n"):
        head = (
            f"POST /v1/levels HTTP/1.1\r\nHost: x\r\n{authorization}"
            f"Content-Type: multipart/form-data; boundary={boundary}\r\nContent-Length: {UPLOAD_LIMIT}\r\n"
        )
        status, answer, _ = _answer_to_partial(server, head, first_part)
        assert status == 401, answer
        assert b"www-authenticate: Bearer" in answer.lower().replace(b"bearer", b"Bearer")


def test_with_a_valid_key_an_upload_is_read_and_one_over_its_limit_answers_413(server):
    with httpx.Client(base_url=f"http://{server.http}", timeout=30) as client:
        auth = {"Authorization": f"Bearer {server.admin_key}"}
        r = client.post("/v1/levels", data={"name": "cube"}, files={"level": ("cube.obj", b"v 0 0 0\n")}, headers=auth)
        assert r.status_code == 400 and "not a usable mesh" in r.json()["detail"]  # read and checked as before
        r = client.post("/v1/levels", data={"name": "huge"}, files={"level": ("x.obj", b"#" * (3 * UPLOAD_LIMIT))}, headers=auth)
        assert r.status_code == 413


def test_a_422_names_the_field_but_never_echoes_what_was_sent(server):
    secret = "cdk_secret-sent-in-the-wrong-shape"
    with httpx.Client(base_url=f"http://{server.http}", timeout=30) as client:
        r = client.post("/v1/login", json={"key": {"value": secret}})
        assert r.status_code == 422 and secret not in r.text
        assert r.json()["detail"] == [{"loc": ["body", "key"], "msg": "Input should be a valid string", "type": "string_type"}]
        r = client.post("/v1/keys", json={"role": secret}, headers={"Authorization": f"Bearer {server.admin_key}"})
        assert r.status_code == 422 and secret not in r.text
        assert all(set(error) == {"loc", "msg", "type"} for error in r.json()["detail"])
