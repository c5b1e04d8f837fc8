"""Secrets and paths never leave (docs/security.md, "What a client is told"): real servers whose
records database URL carries a password in each form libpq takes (trust authentication on
loopback ignores it). A TRACKS CreateSession with an unknown level answers NOT_FOUND naming no
database, host or path, over gRPC and ZeroMQ, with keys on; a node whose database is down at
start, or goes down while it serves, says so in its log with the password hidden and answers its
clients without the URL; a recording is named by its session's id, never by a server path, and a
session's detail names none either. With keys on, the records database down while the node serves
answers every login, key lookup and audit write 503 / UNAVAILABLE, naming only the kind of store,
while keys already known to the node keep streaming frames."""

from __future__ import annotations

import queue
import tempfile
import time

import grpc
import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.deploy.services import PostgresServer, free_port
from camdirector.v1 import director_pb2 as pb
from tests.conftest import service_or_skip
from tests.service.tracks_sessions import tracks_request
from tests.service.wire_client import GrpcRaw, RpcFailed, ZmqRaw, two_target_request, walk

SECRET = "hunter2"


def with_passwords(url: str) -> str:
    """postgresql://USER@HOST:PORT/DB with the password as user info and as the query's password
    and sslpassword."""
    scheme, _, rest = url.partition("://")
    user, _, place = rest.partition("@")
    return f"{scheme}://{user}:{SECRET}@{place}?password={SECRET}&sslpassword={SECRET}"


def assert_names_nothing_of_the_server(text: str, url: str, data_dir) -> None:
    port = url.rsplit(":", 1)[1].split("/")[0]
    for leak in (SECRET, "postgres", "127.0.0.1", f":{port}", str(data_dir), tempfile.gettempdir()):
        assert leak not in text, f"{leak!r} in {text!r}"


def test_an_unknown_level_answers_without_the_database_or_a_path(postgres_url, tmp_path):
    url = with_passwords(postgres_url)
    with ServerProcess("--workers", "1", "--data-dir", str(tmp_path), "--job-store", url, auth=True) as srv:
        clients = [GrpcRaw(srv.grpc, key=srv.admin_key), ZmqRaw(srv.zmq, key=srv.admin_key, server_key=srv.zmq_server_key)]
        for client in clients:
            with pytest.raises(RpcFailed) as err:
                client.call("CreateSession", tracks_request("nowhere", (0.0, 0.0, 0.0)))
            client.close()
            assert err.value.code == grpc.StatusCode.NOT_FOUND
            assert "level_id 'nowhere' is not in this server's level registry" in err.value.message
            assert_names_nothing_of_the_server(err.value.message, url, tmp_path)
        assert SECRET not in srv.log_tail(1 << 20)


def test_a_database_down_at_start_is_logged_without_its_password(tmp_path):
    url = with_passwords(f"postgresql://camdirector@127.0.0.1:{free_port()}/camdirector")
    with pytest.raises(RuntimeError, match="is unreachable") as refused:  # the log's tail comes with it
        ServerProcess("--workers", "0", "--data-dir", str(tmp_path), "--job-store", url)
    assert SECRET not in str(refused.value) and "camdirector:***@127.0.0.1" in str(refused.value)


def test_a_database_down_while_serving_is_logged_without_its_password_and_answered_without_it(tmp_path):
    postgres = service_or_skip(lambda: PostgresServer(tmp_path / "postgres").start())
    url = with_passwords(postgres.url)
    try:
        with ServerProcess("--workers", "1", "--data-dir", str(tmp_path / "data"), "--job-store", url) as srv:
            postgres.stop()
            client = GrpcRaw(srv.grpc)
            with pytest.raises(RpcFailed) as err:
                client.call("CreateSession", tracks_request("arena", (0.0, 0.0, 0.0)))
            client.close()
            assert err.value.code == grpc.StatusCode.UNAVAILABLE, err.value
            assert_names_nothing_of_the_server(err.value.message, url, tmp_path)
            for path in ("/v1/levels", "/v1/level-jobs", "/v1/overview-jobs"):
                answer = httpx.get(f"http://{srv.http}{path}", timeout=30)
                assert answer.status_code == 503, (path, answer.text)
                assert_names_nothing_of_the_server(answer.text, url, tmp_path)
            log = srv.log_tail(1 << 20)
            assert "is unreachable" in log and "camdirector:***@127.0.0.1" in log, log
            assert SECRET not in log
    finally:
        postgres.stop()


def test_the_records_database_down_answers_unavailable_and_known_keys_keep_streaming(tmp_path):
    postgres = service_or_skip(lambda: PostgresServer(tmp_path / "postgres").start())
    url = with_passwords(postgres.url)
    try:
        with ServerProcess("--workers", "1", "--data-dir", str(tmp_path / "data"), "--job-store", url, auth=True) as srv:
            http = f"http://{srv.http}"
            admin = {"authorization": f"Bearer {srv.admin_key}"}
            made = httpx.post(f"{http}/v1/keys", json={"role": "engine"}, headers=admin, timeout=30)
            uncached = made.json()["key"]  # made here, never used: not in the node's cache
            login = httpx.post(f"{http}/v1/login", json={"key": srv.admin_key}, timeout=30)
            grpc_client = GrpcRaw(srv.grpc, key=srv.admin_key)  # the admin key, cached by its first call
            zmq_client = ZmqRaw(srv.zmq, key=srv.admin_key, server_key=srv.zmq_server_key)
            session_id = grpc_client.call("CreateSession", two_target_request(seed=3)).session_id
            sent: queue.Queue = queue.Queue()
            stream = grpc_client.stub.StreamFrames(iter(sent.get, None), timeout=60, metadata=grpc_client.metadata)
            frames = list(walk(session_id, 40))
            for frame in frames[:10]:
                sent.put(frame)
            assert [next(stream).frame for _ in range(10)] == list(range(1, 11))

            postgres.stop()
            time.sleep(1.0)  # the guard's poll meets the outage first (it logs it once)
            for frame in frames[10:20]:  # the open stream goes on
                sent.put(frame)
            assert [next(stream).frame for _ in range(10)] == list(range(11, 21))
            sent.put(None)
            assert [u.frame for u in grpc_client.stream(frames[20:30])] == list(range(21, 31))  # a new stream
            assert [u.frame for u in zmq_client.stream(frames[30:40])] == list(range(31, 41))

            answers = {
                "login": httpx.post(f"{http}/v1/login", json={"key": uncached}, timeout=30),
                "whoami": httpx.get(f"{http}/v1/whoami", headers={"authorization": f"Bearer {uncached}"}, timeout=30),
                "new key": httpx.post(f"{http}/v1/keys", json={"role": "viewer"}, headers=admin, timeout=30),
                "keys": httpx.get(f"{http}/v1/keys", headers=admin, timeout=30),
                "logout": httpx.post(f"{http}/v1/logout", cookies=login.cookies, timeout=30),
            }
            for what, answer in answers.items():
                assert answer.status_code == 503 and answer.headers["retry-after"], (what, answer.status_code, answer.text)
                assert answer.json() == {"detail": "the records database is unreachable; retry later"}, what
            style = pb.UpdateStyleRequest(session_id=session_id)
            calls = [
                (GrpcRaw(srv.grpc, key=uncached), "CreateSession", two_target_request()),
                (ZmqRaw(srv.zmq, key=uncached, server_key=srv.zmq_server_key), "CreateSession", two_target_request()),
                (grpc_client, "UpdateStyle", style),  # read fresh and audited: it waits for the database
                (zmq_client, "UpdateStyle", style),
            ]
            for client, rpc, request in calls:
                with pytest.raises(RpcFailed) as err:
                    client.call(rpc, request)
                client.close()
                assert err.value.code == grpc.StatusCode.UNAVAILABLE, (rpc, err.value)
                assert err.value.message == "the records database is unreachable; retry later"
            log = srv.log_tail(1 << 20)
            assert log.count("records database (keys) postgresql://camdirector:***@127.0.0.1") == 1, log  # once per outage
            assert SECRET not in log
    finally:
        postgres.stop()


def test_a_recording_is_named_by_its_id_and_a_session_names_no_path(server):
    client = GrpcRaw(server.grpc)
    response = client.call("CreateSession", two_target_request(seed=5, record=True))
    session_id = response.session_id
    try:
        assert response.recording_path == f"{session_id}.cdrec"
        assert (server.data_dir / "recordings" / response.recording_path).is_file()
        detail = httpx.get(f"http://{server.http}/v1/sessions/{session_id}", timeout=30)
        assert detail.status_code == 200 and session_id in detail.text
        listed = httpx.get(f"http://{server.http}/v1/sessions", timeout=30)
        for text in (detail.text, listed.text):
            assert str(server.data_dir) not in text and tempfile.gettempdir() not in text
    finally:
        client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        client.close()
