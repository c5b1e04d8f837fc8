"""A real `camdirector serve` with authentication on: the first admin key, the keys command, TLS,
CURVE, protected mode on non-loopback addresses, tenants' limits, the audit trail, and a stream
whose key is revoked."""

from __future__ import annotations

import json
import os
import signal
import ssl
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import grpc
import httpx
import pytest
import zmq

from camdirector.deploy.server_process import ServerProcess
from camdirector.deploy.tls import make_tls_files
from camdirector.v1 import director_pb2 as pb
from tests.service import wire_client as wc


def keys_command(data_dir: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "camdirector", "keys", *args, "--data-dir", str(data_dir)], capture_output=True, text=True
    )


def _auth(key: str) -> dict:
    return {"Authorization": f"Bearer {key}"}


def test_the_first_start_makes_an_admin_key_and_logs_its_path_only(tmp_path):
    with ServerProcess("--workers", "0", "--data-dir", str(tmp_path), auth=True) as server:
        key_file = tmp_path / "admin.key"
        assert server.ready["admin_key_file"] == str(key_file)
        assert stat.S_IMODE(os.stat(key_file).st_mode) == 0o600
        assert str(key_file) in server.log_tail() and server.admin_key not in server.log_tail()
        assert httpx.get(f"http://{server.http}/v1/whoami", headers=_auth(server.admin_key)).json()["role"] == "admin"
    with ServerProcess("--workers", "0", "--data-dir", str(tmp_path), auth=True) as again:
        assert "admin_key_file" not in again.ready  # one existed: none made


def test_keys_are_made_listed_and_revoked_from_the_command_line(tmp_path):
    with ServerProcess("--workers", "0", "--data-dir", str(tmp_path), auth=True) as server:
        made = keys_command(tmp_path, "create", "--role", "director", "--tenant", "studio-a", "--name", "desk 2")
        assert made.returncode == 0 and len(made.stdout.splitlines()) == 1, made
        key = made.stdout.strip()
        me = httpx.get(f"http://{server.http}/v1/whoami", headers=_auth(key)).json()
        assert (me["role"], me["tenant"]) == ("director", "studio-a")
        listed = keys_command(tmp_path, "list", "--tenant", "studio-a").stdout
        assert me["key_id"] in listed and key not in listed and "desk 2" in listed
        assert keys_command(tmp_path, "revoke", me["key_id"]).returncode == 0
        assert httpx.get(f"http://{server.http}/v1/sessions", headers=_auth(key)).status_code == 401
        missing = keys_command(tmp_path, "revoke", "0badc0ffee00")
        assert missing.returncode == 1 and "no key" in missing.stderr
        bad = keys_command(tmp_path, "create", "--role", "admin", "--tenant", "Not A Tenant")
        assert bad.returncode == 2 and "tenant" in bad.stderr


def test_a_key_is_revoked_from_a_file_stdin_or_the_environment_never_from_the_arguments(tmp_path):
    """`keys revoke` takes the id, or a whole key from --key-file PATH, --key-file - (stdin) or
    --key-from-env (CAMDIRECTOR_KEY): the key never needs to be in the process's arguments. A file
    without a key is refused with a message that does not show what it holds."""
    keys = [keys_command(tmp_path, "create", "--role", "viewer").stdout.strip() for _ in range(3)]
    (tmp_path / "viewer.key").write_text(keys[0] + "\n")
    base = [sys.executable, "-m", "camdirector", "keys", "revoke", "--data-dir", str(tmp_path)]
    env = {**os.environ, "CAMDIRECTOR_KEY": keys[2]}
    for extra, stdin in (
        (["--key-file", str(tmp_path / "viewer.key")], None),
        (["--key-file", "-"], keys[1]),
        (["--key-from-env"], None),
    ):
        done = subprocess.run([*base, *extra], input=stdin, capture_output=True, text=True, env=env)
        assert done.returncode == 0, done.stderr
    listed = [json.loads(line) for line in keys_command(tmp_path, "list").stdout.splitlines()]
    revoked = {key["id"] for key in listed if key["revoked_s"]}
    assert revoked == {key.split("_")[1] for key in keys}
    (tmp_path / "wrong.key").write_text("cdk_secret-looking but not a key\n")
    wrong = subprocess.run([*base, "--key-file", str(tmp_path / "wrong.key")], capture_output=True, text=True)
    assert wrong.returncode == 2 and "does not hold a key" in wrong.stderr and "secret-looking" not in wrong.stderr


@pytest.mark.parametrize(
    "args, refused",
    [
        (("--grpc", "0.0.0.0:0", "--zmq", "", "--http", ""), "grpc on 0.0.0.0:0"),
        (("--grpc", "", "--zmq", "", "--http", "0.0.0.0:0"), "http on 0.0.0.0:0"),
        (("--grpc", "", "--zmq", "tcp://0.0.0.0:*", "--http", "", "--no-auth"), "zmq on 0.0.0.0:*"),
    ],
)
def test_a_non_loopback_address_without_encryption_refuses_to_start(tmp_path, args, refused):
    run = subprocess.run(
        [sys.executable, "-m", "camdirector", "serve", "--workers", "0", "--data-dir", str(tmp_path), *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2 and refused in run.stderr and "--tls-cert" in run.stderr, run.stderr


def test_insecure_lets_a_non_loopback_address_start(tmp_path):
    with ServerProcess("--workers", "0", "--grpc", "0.0.0.0:0", "--insecure", transports=(), auth=True) as server:
        assert server.grpc.startswith("0.0.0.0:")


def test_over_tls_a_plaintext_client_is_refused_and_one_with_the_ca_served(tmp_path, tls_files):
    with ServerProcess("--workers", "0", "--tls-cert", str(tls_files.cert), "--tls-key", str(tls_files.key), auth=True) as server:
        assert server.url("grpc").startswith("grpcs://")
        trusted = wc.GrpcRaw(server.grpc, key=server.admin_key, ca_file=tls_files.ca_cert)
        assert trusted.call("CreateSession", wc.two_target_request()).session_id
        trusted.close()
        plain = wc.GrpcRaw(server.grpc, key=server.admin_key)
        with pytest.raises(wc.RpcFailed) as refused:
            plain.call("CreateSession", wc.two_target_request())
        assert refused.value.code == grpc.StatusCode.UNAVAILABLE
        plain.close()
        stranger = make_tls_files(tmp_path / "another-ca")
        untrusting = wc.GrpcRaw(server.grpc, key=server.admin_key, ca_file=stranger.ca_cert)  # another CA
        with pytest.raises(wc.RpcFailed):
            untrusting.call("CreateSession", wc.two_target_request())
        context = ssl.create_default_context(cafile=str(tls_files.ca_cert))
        with httpx.Client(verify=context) as https:
            assert https.get(f"https://{server.http}/v1/sessions", headers=_auth(server.admin_key)).status_code == 200
        with pytest.raises(httpx.HTTPError):
            httpx.get(f"http://{server.http}/v1/sessions", headers=_auth(server.admin_key), timeout=5)
        with pytest.raises(httpx.HTTPError):  # the system's roots do not know this CA
            httpx.get(f"https://{server.http}/healthz", timeout=5)


def test_zeromq_is_curve_encrypted_and_a_client_without_the_servers_key_gets_nothing():
    with ServerProcess("--workers", "0", transports=("zmq",), auth=True) as server:
        assert len(server.zmq_server_key) == 40  # Z85 of 32 bytes
        curve = wc.ZmqRaw(server.zmq, key=server.admin_key, server_key=server.zmq_server_key)
        assert curve.call("CreateSession", wc.two_target_request()).session_id
        for junk in (b"", b"Bearer", b"Bearer cdk_x", b"\xff\xfe", b"Basic " + server.admin_key.encode()):
            code, message = curve.send_raw([b"CreateSession", wc.two_target_request().SerializeToString(), junk])
            assert code == b"16", (junk, message)
        curve.close()
        plain = wc.ZmqRaw(server.zmq, key=server.admin_key)
        plain.sock.setsockopt(zmq.RCVTIMEO, 1500)
        with pytest.raises(zmq.Again):  # the handshake never completes: no request reaches the server
            plain.call("CreateSession", wc.two_target_request())
        plain.close()


def test_tenants_limits_answer_resource_exhausted_with_a_message(tmp_path):
    with ServerProcess(
        "--workers",
        "0",
        "--data-dir",
        str(tmp_path),
        "--tenant-max-sessions",
        "2",
        "--tenant-max-fps",
        "20",
        transports=("grpc",),
        auth=True,
    ) as server:
        alpha = wc.GrpcRaw(server.grpc, key=server.admin_key)
        beta = wc.GrpcRaw(
            server.grpc, key=keys_command(tmp_path, "create", "--role", "engine", "--tenant", "beta").stdout.strip()
        )
        first = alpha.call("CreateSession", wc.two_target_request()).session_id
        alpha.call("CreateSession", wc.two_target_request())
        with pytest.raises(wc.RpcFailed) as full:
            alpha.call("CreateSession", wc.two_target_request())
        assert full.value.code == grpc.StatusCode.RESOURCE_EXHAUSTED and "tenant 'default'" in full.value.message
        assert beta.call("CreateSession", wc.two_target_request()).session_id  # another tenant's share
        start_s, answered = time.monotonic(), 0
        with pytest.raises(wc.RpcFailed) as fast:
            for update in wc.walk(first, 90):  # as fast as it goes: far above 20 a second
                alpha.call("Frame", update)
                answered += 1
        assert fast.value.code == grpc.StatusCode.RESOURCE_EXHAUSTED and "20 frames a second" in fast.value.message
        # a full bucket (one second's frames), refilled while the burst ran, as fast as this machine sent it
        assert 20 <= answered <= 20 + 20 * (time.monotonic() - start_s)
        _after_data_loss_the_updates_since_are_taken_at_once(beta)  # its second session: alpha has its two
        time.sleep(0.2)
        alpha.call("Frame", next(wc.walk(first, 1, start_frame=100)))  # the session goes on at its pace
        alpha.close()
        beta.close()


def test_style_changes_and_key_changes_are_in_the_tenants_audit_trail(tmp_path):
    with ServerProcess("--workers", "0", "--data-dir", str(tmp_path), transports=("grpc", "http"), auth=True) as server:
        http = f"http://{server.http}"
        raw = wc.GrpcRaw(server.grpc, key=server.admin_key)
        session_id = raw.call("CreateSession", wc.two_target_request()).session_id
        raw.call("UpdateStyle", pb.UpdateStyleRequest(session_id=session_id, style=pb.Style(preferred_phi_deg=40)))
        raw.close()
        assert (
            httpx.put(
                f"{http}/v1/sessions/{session_id}/style", json={"preferredPhiDeg": 30}, headers=_auth(server.admin_key)
            ).status_code
            == 200
        )
        made = httpx.post(f"{http}/v1/keys", json={"role": "viewer", "name": "producer"}, headers=_auth(server.admin_key)).json()
        assert httpx.delete(f"{http}/v1/keys/{made['id']}", headers=_auth(server.admin_key)).status_code == 200
        trail = httpx.get(f"{http}/v1/audit", headers=_auth(server.admin_key)).json()["entries"]
        admin_id = server.admin_key.split("_")[1]
        assert [(e["action"], e["session_id"], e["key_id"]) for e in trail] == [
            ("style", session_id, admin_id),
            ("style", session_id, admin_id),
            ("key.create", None, admin_id),
            ("key.revoke", None, admin_id),
        ]
        assert trail[0]["detail"]["via"] == "grpc" and trail[1]["detail"]["style"] == {"preferredPhiDeg": 30}
        viewer = httpx.post(f"{http}/v1/keys", json={"role": "viewer"}, headers=_auth(server.admin_key)).json()["key"]
        assert httpx.get(f"{http}/v1/audit", headers=_auth(viewer)).status_code == 403


def test_a_stream_whose_key_is_revoked_ends_unauthenticated_within_the_poll(tmp_path):
    with ServerProcess("--workers", "1", "--data-dir", str(tmp_path), transports=("grpc", "http"), auth=True) as server:
        engine = httpx.post(f"http://{server.http}/v1/keys", json={"role": "engine"}, headers=_auth(server.admin_key)).json()
        raw = wc.GrpcRaw(server.grpc, key=engine["key"])
        session_id = raw.call("CreateSession", wc.two_target_request()).session_id
        revoked_at, answered = [], []

        def paced():
            for n, update in enumerate(wc.walk(session_id, 100_000)):
                if n == 30:  # revoked_at: when the revocation is asked for (it holds before the answer comes)
                    revoked_at.append(time.monotonic())
                    threading.Thread(
                        target=lambda: httpx.delete(
                            f"http://{server.http}/v1/keys/{engine['id']}", headers=_auth(server.admin_key)
                        )
                    ).start()
                answered.append(time.monotonic())
                time.sleep(1 / 60)
                yield update

        with pytest.raises(wc.RpcFailed) as ended:
            raw.stream(paced())
        assert ended.value.code == grpc.StatusCode.UNAUTHENTICATED and "revoked" in ended.value.message
        assert answered[-1] - revoked_at[0] < 1.0  # the poll is every 0.25 s
        raw.close()


def test_one_tenants_live_views_leave_room_for_another_tenants(tmp_path):
    """Each tenant holds at most its share of the node's live views (`--tenant-max-live-views`,
    16 by default, of the node's 64): the next is 429 saying whose share it is, and another
    tenant's viewer still gets its stream."""
    with ServerProcess("--workers", "1", "--data-dir", str(tmp_path), transports=("grpc", "http"), auth=True) as server:
        beta_key = keys_command(tmp_path, "create", "--role", "admin", "--tenant", "beta").stdout.strip()
        sessions = {}
        for tenant, key in (("alpha", server.admin_key), ("beta", beta_key)):
            raw = wc.GrpcRaw(server.grpc, key=key)
            sessions[tenant] = raw.call("CreateSession", wc.two_target_request()).session_id
            raw.stream(list(wc.walk(sessions[tenant], 5)))
            raw.close()

        parts = []  # each open stream's iterator, held: a dropped one closes its response

        def view(tenant: str, key: str, client: httpx.Client) -> httpx.Response:
            url = f"http://{server.http}/v1/sessions/{sessions[tenant]}/view.mjpeg"
            reply = client.send(client.build_request("GET", url, params={"fps": 1}, headers=_auth(key)), stream=True)
            if reply.status_code == 200:
                parts.append(reply.iter_bytes())
                next(parts[-1])  # its first part: the stream is counted
            return reply

        with httpx.Client(timeout=60, limits=httpx.Limits(max_connections=32)) as client:
            held = [view("alpha", server.admin_key, client) for _ in range(16)]
            try:
                assert [reply.status_code for reply in held] == [200] * 16
                refused = view("alpha", server.admin_key, client)
                assert refused.status_code == 429, refused.status_code
                assert "tenant 'default' has its maximum of 16 live views" in refused.read().decode()
                theirs = view("beta", beta_key, client)
                assert theirs.status_code == 200
                theirs.close()
            finally:
                for reply in held:
                    reply.close()


def test_another_tenants_session_live_or_lost_answers_as_a_made_up_id(tmp_path):
    """An id that is not the caller's tenant's takes one path whatever it names: a made-up id,
    another tenant's live session, and another tenant's session lost with its worker (checkpoints
    off) answer the same status and the same words on every RPC and route that names a session;
    the session's own tenant is still told its session was lost."""
    with ServerProcess(
        "--workers", "1", "--checkpoint-store", "off", "--data-dir", str(tmp_path), transports=("grpc", "http"), auth=True
    ) as server:
        alpha = wc.GrpcRaw(server.grpc, key=server.admin_key)
        beta_key = keys_command(tmp_path, "create", "--role", "admin", "--tenant", "beta").stdout.strip()
        beta = wc.GrpcRaw(server.grpc, key=beta_key)
        lost = alpha.call("CreateSession", wc.two_target_request()).session_id
        os.kill(server.worker_pids()[0], signal.SIGKILL)
        deadline = time.monotonic() + 60
        while True:
            try:
                alpha.call("Frame", next(wc.walk(lost, 1)))
            except wc.RpcFailed as exc:
                if "worker process holding it" in exc.message:
                    break
            assert time.monotonic() < deadline, "the killed worker's session still answers"
            time.sleep(0.2)
        live = alpha.call("CreateSession", wc.two_target_request()).session_id
        requests = {
            "Frame": lambda sid: next(wc.walk(sid, 1)),
            "UpdateStyle": lambda sid: pb.UpdateStyleRequest(session_id=sid, style=pb.Style()),
            "TakeShot": lambda sid: pb.TakeShotRequest(session_id=sid, release=True),
            "CloseSession": lambda sid: pb.CloseSessionRequest(session_id=sid),
        }

        def answer(rpc: str, session_id: str) -> tuple[str, str]:
            try:
                beta.call(rpc, requests[rpc](session_id))
            except wc.RpcFailed as exc:
                return exc.code.name, exc.message.replace(session_id, "<ID>")
            return "OK", ""

        made_up = "0123456789abcdef0123456789abcdef"
        for rpc in requests:
            unknown = ("NOT_FOUND", "unknown session id '<ID>' (closed, reclaimed, or never created)")
            assert answer(rpc, live) == answer(rpc, lost) == answer(rpc, made_up) == unknown, rpc
        for route in ("", "/amap.png", "/view", "/topview.png"):
            answers = set()
            for session_id in (live, lost, made_up):
                reply = httpx.get(f"http://{server.http}/v1/sessions/{session_id}{route}", headers=_auth(beta_key), timeout=30)
                answers.add((reply.status_code, reply.text.replace(session_id, "<ID>")))
            assert len(answers) == 1 and answers.pop()[0] == 404, route
        with pytest.raises(wc.RpcFailed) as own:
            alpha.call("Frame", next(wc.walk(lost, 1, start_frame=2)))
        assert own.value.code == grpc.StatusCode.UNAVAILABLE and "died" in own.value.message
        alpha.close()
        beta.close()


def _after_data_loss_the_updates_since_are_taken_at_once(client: wc.GrpcRaw) -> None:
    """A session whose client was answered frames it has not taken (restored from a checkpoint that
    fell behind) answers DATA_LOSS, and its client sends the updates since again at once: far more
    than the tenant's 20 frames a second, and every one is answered (front/router.py's resend burst)."""
    resent = client.call("CreateSession", wc.two_target_request()).session_id
    ahead = next(wc.walk(resent, 1, start_frame=40))
    ahead.answered_frame = 30  # answered up to frame 30: this session has taken none
    with pytest.raises(wc.RpcFailed) as lost:
        client.call("Frame", ahead)
    assert lost.value.code == grpc.StatusCode.DATA_LOSS and "resend from 1" in lost.value.message
    for update in wc.walk(resent, 30):
        update.answered_frame = update.frame - 1
        assert client.call("Frame", update).frame == update.frame
