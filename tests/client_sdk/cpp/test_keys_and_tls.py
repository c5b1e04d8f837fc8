"""The C/C++ SDK against a server with authentication on and gRPC over TLS (issue 26): with the
key (CAMDIRECTOR_KEY, the SDK's default) and the test CA it streams; without a key, over
plaintext, or without the CA, cd_session_open fails and says why; a key revoked mid-stream ends
the session (SESSION_FAILED, UNAUTHENTICATED) instead of reconnecting over and over."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from camdirector.deploy.server_process import ServerProcess
from tests.client_sdk.cpp.conftest import StreamRun, run_json

KEY_ENV = "CAMDIRECTOR_KEY"


@pytest.fixture(scope="module")
def tls_server(tls_files, tmp_path_factory):
    data_dir = tmp_path_factory.mktemp("cpp-auth-server")
    with ServerProcess(
        "--workers",
        "1",
        "--data-dir",
        str(data_dir),
        "--tls-cert",
        str(tls_files.cert),
        "--tls-key",
        str(tls_files.key),
        transports=("grpc",),
        auth=True,
    ) as srv:
        srv.data_dir = data_dir
        yield srv


def test_with_the_key_and_the_ca_it_streams_over_tls(sdk_bin, tls_server, tls_files):
    url = tls_server.url("grpc")
    assert url.startswith("grpcs://")
    report = run_json(
        sdk_bin / "engine_loop",
        url,
        "120",
        "--ca-file",
        str(tls_files.ca_cert),
        env={KEY_ENV: tls_server.admin_key},
        timeout_s=120,
    )
    assert report["frames_answered"] + report["frames_dropped"] == 120 and report["last_pose_frame"] == 120, report
    assert report["flush"] == "OK" and report["close"] == "OK" and report["server_frames"] == report["frames_answered"]
    assert report["max_screen_error"] < 1e-6, report


def engine_loop_without(sdk_bin, *args: str, key: str | None) -> subprocess.CompletedProcess:
    """engine_loop ARGS, expected to fail, with `key` as CAMDIRECTOR_KEY (None: unset)."""
    env = {k: v for k, v in os.environ.items() if k != KEY_ENV}
    if key is not None:
        env[KEY_ENV] = key
    return subprocess.run([str(sdk_bin / "engine_loop"), *args], capture_output=True, text=True, timeout=120, env=env)


@pytest.mark.parametrize(
    ("case", "expected"),
    [
        ("no key", ["UNAUTHENTICATED"]),
        ("plaintext", ["UNAVAILABLE", "if it serves TLS, connect with grpcs://"]),
        ("no ca", ["UNAVAILABLE", "set ca_file"]),
    ],
)
def test_open_fails_and_says_why(sdk_bin, tls_server, tls_files, case, expected):
    url, ca = tls_server.url("grpc"), ["--ca-file", str(tls_files.ca_cert)]
    args = {"no key": [url, "10", *ca], "plaintext": [url.replace("grpcs://", "grpc://"), "10"], "no ca": [url, "10"]}[case]
    done = engine_loop_without(sdk_bin, *args, key=None if case == "no key" else tls_server.admin_key)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert "engine_loop: open: " in done.stderr, done.stderr  # after gRPC's own log lines, if any
    for text in expected:
        assert text in done.stderr, done.stderr
    assert tls_server.admin_key.split("_", 2)[2] not in done.stdout + done.stderr  # cdk_ID_SECRET


def test_a_key_revoked_mid_stream_ends_the_session_without_retrying(sdk_bin, tls_server, tls_files):
    def keys(*args: str) -> str:
        return subprocess.run(
            [sys.executable, "-m", "camdirector", "keys", *args, "--data-dir", str(tls_server.data_dir)],
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        ).stdout.strip()

    engine = keys("create", "--role", "engine", "--name", "cpp sdk revocation")
    run = StreamRun(
        sdk_bin / "sdk_check",
        tls_server.url("grpc"),
        "failed",
        30.0,
        "--after",
        "0",
        "--ca-file",
        str(tls_files.ca_cert),
        env={KEY_ENV: engine},
    )
    run.wait_ready()
    keys("revoke", engine)
    report = run.report()
    assert report["seen"], report
    failed = [e for e in report["events"] if e["kind"] == "SESSION_FAILED"]
    assert failed and failed[0]["status"] == "UNAUTHENTICATED" and "revoked" in failed[0]["message"], report["events"]
    assert [e["kind"] for e in report["events"]] == ["STREAMING", "SESSION_FAILED"], report["events"]
    assert report["stats"]["streams_opened"] == 1 and report["stats"]["state"] == 5, report["stats"]  # FAILED
