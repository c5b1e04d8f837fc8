"""The Python SDK against real servers with authentication on (issue 26): keys on every call over
gRPC and ZeroMQ (CURVE), gRPC over TLS with a studio's own CA, refused keys raised at once and
never tried again, and a key that shows in no log, repr or error message."""

from __future__ import annotations

import asyncio
import logging
import subprocess
import sys
from pathlib import Path

import grpc
import pytest
import zmq

import camdirector_client as cd
from camdirector.deploy.server_process import ServerProcess
from camdirector_client import wire
from tests.service.wire_client import two_target_request, walk


@pytest.fixture(scope="module")
def auth_server(tmp_path_factory):
    """Authentication on, plaintext gRPC (loopback), ZeroMQ with CURVE; its data directory known,
    for `camdirector keys`."""
    data_dir = tmp_path_factory.mktemp("auth-server")
    with ServerProcess("--workers", "1", "--data-dir", str(data_dir), transports=("grpc", "zmq"), auth=True) as srv:
        srv.data_dir = data_dir
        yield srv


@pytest.fixture(scope="module")
def tls_server(tls_files):
    """Authentication on, gRPC over TLS with a certificate signed by the test CA."""
    with ServerProcess(
        "--workers", "1", "--tls-cert", str(tls_files.cert), "--tls-key", str(tls_files.key), transports=("grpc",), auth=True
    ) as srv:
        yield srv


@pytest.fixture(autouse=True)
def no_key_in_environment(monkeypatch):
    monkeypatch.delenv(wire.KEY_ENV, raising=False)


def keys(server, *args: str) -> str:
    """`camdirector keys ARGS` on the server's data directory; its output."""
    done = subprocess.run(
        [sys.executable, "-m", "camdirector", "keys", *args, "--data-dir", str(server.data_dir)],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    return done.stdout.strip()


def security_of(server, transport: str) -> dict:
    """What `connect` needs besides the URL and the key for `transport` of `server`."""
    return {"zmq_server_key": server.zmq_server_key} if transport == "zmq" else {}


def drive_sync(url: str, **options) -> tuple[int, int]:
    """A session: frames, a stream, a style change, closed; (frames answered, server's count)."""
    with cd.connect(url, **options) as client:
        with client.create_session(two_target_request(seed=2)) as session:
            session.frame(1, 1 / 60)
            replies = list(session.stream(walk("", 10, start_frame=2)))
            session.update_style({"gaze_room_m": 0.5})
        return 1 + len(replies), session.close()


async def drive_async(url: str, **options) -> tuple[int, int]:
    async with cd.connect_async(url, **options) as client:
        async with client.create_session(two_target_request(seed=2)) as session:
            await session.frame(1, 1 / 60)
            replies = [reply async for reply in session.stream(walk("", 10, start_frame=2))]
            await session.update_style({"gaze_room_m": 0.5})
        return 1 + len(replies), await session.close()


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
def test_a_key_opens_streams_and_closes_sessions_sync_and_async(auth_server, transport, monkeypatch):
    url = auth_server.url(transport)
    assert drive_sync(url, key=auth_server.admin_key, **security_of(auth_server, transport)) == (11, 11)
    monkeypatch.setenv(wire.KEY_ENV, auth_server.admin_key)  # no key given: the environment's
    assert asyncio.run(drive_async(url, **security_of(auth_server, transport))) == (11, 11)


def test_the_zmq_server_key_may_be_given_as_its_file(auth_server):
    key_file = auth_server.data_dir / "zmq" / "server.key"
    assert drive_sync(auth_server.url("zmq"), key=auth_server.admin_key, zmq_server_key=key_file) == (11, 11)
    assert drive_sync(auth_server.url("zmq"), key=auth_server.admin_key, zmq_server_key=str(key_file)) == (11, 11)


def test_zmq_without_the_servers_curve_key_gets_no_answer_and_is_told_why(auth_server):
    url = auth_server.url("zmq")
    with cd.connect(url, timeout_s=0.5, key=auth_server.admin_key) as client:
        with pytest.raises(cd.DirectorError) as plain:
            client.create_session(two_target_request())
    other_server_key = zmq.curve_keypair()[0].decode()
    with cd.connect(url, timeout_s=0.5, key=auth_server.admin_key, zmq_server_key=other_server_key) as client:
        with pytest.raises(cd.DirectorError) as wrong:
            client.create_session(two_target_request())
    assert plain.value.code == wrong.value.code == grpc.StatusCode.DEADLINE_EXCEEDED
    assert "zmq_server_key" in plain.value.message and "CURVE" in plain.value.message, plain.value
    assert "is zmq_server_key the server's public key?" in wrong.value.message, wrong.value


def test_grpcs_with_the_ca_sync_and_async(tls_server, tls_files):
    url = tls_server.url("grpc")
    assert url.startswith("grpcs://")
    options = {"key": tls_server.admin_key, "ca_file": tls_files.ca_cert}
    assert drive_sync(url, **options) == (11, 11)
    assert asyncio.run(drive_async(url, **options)) == (11, 11)


def test_tls_refusals_are_unavailable_with_what_to_check(tls_server, tls_files):
    plaintext_url = tls_server.url("grpc").replace("grpcs://", "grpc://")
    with cd.connect(plaintext_url, key=tls_server.admin_key) as client:
        with pytest.raises(cd.DirectorError) as plaintext:
            client.create_session(two_target_request())
    assert plaintext.value.code == grpc.StatusCode.UNAVAILABLE
    assert "if it serves TLS, connect with grpcs://" in plaintext.value.message, plaintext.value

    async def without_the_ca():  # the system's roots do not hold the test CA
        async with cd.connect_async(tls_server.url("grpc"), key=tls_server.admin_key) as client:
            await client.create_session(two_target_request())

    with pytest.raises(cd.DirectorError) as untrusted:
        asyncio.run(without_the_ca())
    assert untrusted.value.code == grpc.StatusCode.UNAVAILABLE
    assert "give ca_file" in untrusted.value.message, untrusted.value


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
def test_no_key_an_unknown_key_or_a_role_without_the_verb_are_refused(auth_server, transport):
    url, security = auth_server.url(transport), security_of(auth_server, transport)
    viewer = keys(auth_server, "create", "--role", "viewer", "--name", "sdk test viewer")
    for key, code in [
        (None, grpc.StatusCode.UNAUTHENTICATED),
        ("cdk_0123456789ab_" + "x" * 43, grpc.StatusCode.UNAUTHENTICATED),
        (viewer, grpc.StatusCode.PERMISSION_DENIED),
    ]:
        with cd.connect(url, key=key, **security) as client:
            with pytest.raises(cd.DirectorError) as refused:
                client.create_session(two_target_request())
        assert refused.value.code == code, (key is None, refused.value)


def refusals_sync(url: str, key: str, revoke, **security) -> list[tuple[grpc.StatusCode, str, int]]:
    """Takes a shot with an engine's key, then changes the style after `revoke()`: each refusal's
    (code, message, the session's retries then)."""
    with cd.connect(url, key=key, **security) as client:
        session = client.create_session(two_target_request())
        session.frame(1, 1 / 60)
        with pytest.raises(cd.DirectorError) as denied:
            session.take_shot(["a"])
        retries_denied = session.retries
        revoke()
        with pytest.raises(cd.DirectorError) as revoked:
            session.update_style({"gaze_room_m": 0.5})
    return [
        (denied.value.code, denied.value.message, retries_denied),
        (revoked.value.code, revoked.value.message, session.retries),
    ]


async def refusals_async(url: str, key: str, revoke, **security) -> list[tuple[grpc.StatusCode, str, int]]:
    async with cd.connect_async(url, key=key, **security) as client:
        session = await client.create_session(two_target_request())
        await session.frame(1, 1 / 60)
        with pytest.raises(cd.DirectorError) as denied:
            await session.take_shot(["a"])
        retries_denied = session.retries
        revoke()
        with pytest.raises(cd.DirectorError) as revoked:
            await session.update_style({"gaze_room_m": 0.5})
    return [
        (denied.value.code, denied.value.message, retries_denied),
        (revoked.value.code, revoked.value.message, session.retries),
    ]


@pytest.mark.parametrize("mode", ["sync", "async"])
@pytest.mark.parametrize("transport", ["grpc", "zmq"])
def test_refused_keys_are_raised_at_once_never_retried(auth_server, transport, mode):
    """An engine's key may stream but not take shots: PERMISSION_DENIED. Revoked mid-session, its
    next call is UNAUTHENTICATED. Neither is tried again (a retry would be refused the same)."""
    engine = keys(auth_server, "create", "--role", "engine", "--name", f"sdk test engine {mode} {transport}")
    args = (auth_server.url(transport), engine, lambda: keys(auth_server, "revoke", engine))
    security = security_of(auth_server, transport)
    refusals = refusals_sync(*args, **security) if mode == "sync" else asyncio.run(refusals_async(*args, **security))
    (denied, _, retries_denied), (revoked, message, retries_revoked) = refusals
    assert denied == grpc.StatusCode.PERMISSION_DENIED and revoked == grpc.StatusCode.UNAUTHENTICATED, refusals
    assert "revoked" in message and retries_denied == retries_revoked == 0, refusals


def test_the_key_shows_in_no_log_repr_or_message(auth_server, tls_server, tls_files, caplog, capfd):
    caplog.set_level(logging.DEBUG)
    secret = keys(auth_server, "create", "--role", "engine", "--name", "sdk secrecy")
    seen: list[str] = []
    for url, options in [(auth_server.url("grpc"), {}), (auth_server.url("zmq"), security_of(auth_server, "zmq"))]:
        with cd.connect(url, key=secret, **options) as client:
            session = client.create_session(two_target_request())
            session.frame(1, 1 / 60)
            with pytest.raises(cd.DirectorError) as denied:
                session.take_shot(["a"])
            seen += [
                repr(client),
                str(client),
                repr(session),
                repr(denied.value),
                str(denied.value),
                repr(client._transport._security),
            ]
            session.close()
    # Refusals that name the connection: TLS with a CA not given, ZeroMQ without CURVE.
    with cd.connect(tls_server.url("grpc"), key=secret) as client, pytest.raises(cd.DirectorError) as untrusted:
        client.create_session(two_target_request())
    with cd.connect(auth_server.url("zmq"), timeout_s=0.3, key=secret) as client, pytest.raises(cd.DirectorError) as unanswered:
        client.create_session(two_target_request())
    with pytest.raises(ValueError) as bad:
        cd.connect(auth_server.url("grpc"), key=secret + "\n")
    seen += [repr(untrusted.value), repr(unanswered.value), str(bad.value)]
    keys(auth_server, "revoke", secret)
    with cd.connect(auth_server.url("grpc"), key=secret) as client, pytest.raises(cd.DirectorError) as revoked:
        client.create_session(two_target_request())
    assert revoked.value.code == grpc.StatusCode.UNAUTHENTICATED
    seen.append(repr(revoked.value))
    captured = capfd.readouterr()  # grpc's own C logging writes to the process's stderr
    secret_part = secret.split("_", 2)[2]  # cdk_ID_SECRET: the id is no secret
    for text in [*seen, caplog.text, captured.out, captured.err]:
        assert secret_part not in text, text
    assert "Security(key=set, tls=False, curve=True)" in seen


@pytest.mark.parametrize(
    ("url", "options", "match"),
    [
        ("grpc://127.0.0.1:1", {"ca_file": "ca.pem"}, "ca_file is for grpcs://"),
        ("tcp://127.0.0.1:1", {"ca_file": "ca.pem"}, "ZeroMQ is encrypted with CURVE"),
        ("grpcs://127.0.0.1:1", {"zmq_server_key": "x" * 40}, "zmq_server_key is for tcp://"),
        ("tcp://127.0.0.1:1", {"zmq_server_key": "~" * 40}, "not Z85"),
        ("tcp://127.0.0.1:1", {"zmq_server_key": "/nowhere/server.key"}, "is neither"),
        ("grpc://127.0.0.1:1", {"key": "has space"}, "without spaces"),
        ("grpc://127.0.0.1:1", {"key": ""}, "non-empty"),
    ],
)
def test_options_that_do_not_fit_the_url_are_refused_at_connect(url, options, match):
    with pytest.raises(ValueError, match=match) as refused:
        cd.connect(url, **options)
    assert "has space" not in str(refused.value)


def test_a_missing_ca_file_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.pem"):
        cd.connect("grpcs://127.0.0.1:1", ca_file=Path(tmp_path / "nothere.pem"))
