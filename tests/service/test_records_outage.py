"""The records database (PostgreSQL, the nodes' --job-store) hung or down under a serving node with
keys on (issue 40). Hung is stopped by SIGSTOP: its kernel still accepts connections and
acknowledges what is sent, so a call waits for an answer that never comes unless it has a deadline.

Either way a session streaming with a key the node knows keeps being answered while other calls
wait on the database; every call that needs the database answers UNAVAILABLE over gRPC and
ZeroMQ and 503 with Retry-After over HTTP, never INTERNAL or 500, and never hangs; once the
database answers again a CreateSession succeeds."""

from __future__ import annotations

import contextlib
import queue
import threading
import time

import grpc
import httpx
import pytest

from camdirector.access.guard import RECORDS_DOWN
from camdirector.deploy.server_process import ServerProcess
from camdirector.deploy.services import PostgresServer
from camdirector.v1 import director_pb2 as pb
from tests.conftest import service_or_skip
from tests.infra.test_postgres_deadlines import stopped
from tests.service.wire_client import GrpcRaw, RpcFailed, ZmqRaw, two_target_request, walk

CREATING_S = 4.0  # CreateSession calls are made for this long while the session streams, s (two deadlines)
FRAMES_WHILE_CREATING = 10  # frames answered meanwhile, at the least (a node whose loop waits answers none)


def failed(call) -> RpcFailed | object:
    try:
        return call()
    except RpcFailed as exc:
        return exc


@pytest.mark.parametrize("outage", ["hung", "down"])
def test_the_records_database_hung_or_down_delays_only_the_calls_that_need_it(tmp_path, outage):
    postgres = service_or_skip(lambda: PostgresServer(tmp_path / "postgres").start())
    paused = contextlib.ExitStack()
    try:
        with ServerProcess("--workers", "1", "--data-dir", str(tmp_path / "data"), "--job-store", postgres.url, auth=True) as srv:
            http = f"http://{srv.http}"
            admin = {"authorization": f"Bearer {srv.admin_key}"}
            uncached = httpx.post(f"{http}/v1/keys", json={"role": "engine"}, headers=admin, timeout=30).json()["key"]
            login = httpx.post(f"{http}/v1/login", json={"key": srv.admin_key}, timeout=30)
            streaming = GrpcRaw(srv.grpc, key=srv.admin_key)  # the admin key, cached by its first call
            session_id = streaming.call("CreateSession", two_target_request(seed=3)).session_id
            sent: queue.Queue = queue.Queue()
            stream = streaming.stub.StreamFrames(iter(sent.get, None), timeout=120, metadata=streaming.metadata)
            frames = walk(session_id, 1_000_000)

            def next_frame() -> int:
                sent.put(next(frames))
                return next(stream).frame

            assert next_frame() == 1
            if outage == "hung":
                paused.enter_context(stopped(postgres))
            else:
                postgres.stop()

            creator = GrpcRaw(srv.grpc, key=srv.admin_key)
            created: list = []

            def create_for_a_while() -> None:
                start = time.monotonic()
                while time.monotonic() - start < CREATING_S:
                    created.append(failed(lambda: creator.call("CreateSession", two_target_request())))

            creating = threading.Thread(target=create_for_a_while)
            creating.start()
            answered = 0
            while creating.is_alive():
                next_frame()
                answered += 1
                time.sleep(0.01)
            creating.join()
            assert answered >= FRAMES_WHILE_CREATING, answered
            unavailable = [isinstance(c, RpcFailed) and c.code == grpc.StatusCode.UNAVAILABLE for c in created]
            assert created and all(unavailable), created

            zmq_client = ZmqRaw(srv.zmq, key=srv.admin_key, server_key=srv.zmq_server_key)
            calls = {
                "CreateSession, a key not cached": (GrpcRaw(srv.grpc, key=uncached), "CreateSession", two_target_request()),
                "CreateSession over ZeroMQ": (zmq_client, "CreateSession", two_target_request()),
                "UpdateStyle": (streaming, "UpdateStyle", pb.UpdateStyleRequest(session_id=session_id)),
                "UpdateStyle over ZeroMQ": (zmq_client, "UpdateStyle", pb.UpdateStyleRequest(session_id=session_id)),
                "TakeShot": (streaming, "TakeShot", pb.TakeShotRequest(session_id=session_id, release=True)),
                "TakeShot over ZeroMQ": (zmq_client, "TakeShot", pb.TakeShotRequest(session_id=session_id, release=True)),
            }
            for what, (client, rpc, request) in calls.items():
                answer = failed(lambda client=client, rpc=rpc, request=request: client.call(rpc, request))
                assert isinstance(answer, RpcFailed) and answer.code == grpc.StatusCode.UNAVAILABLE, (what, answer)
                assert answer.message == RECORDS_DOWN, what
            zmq_client.close()
            answers = {
                "login": lambda: httpx.post(f"{http}/v1/login", json={"key": uncached}, timeout=30),
                "whoami": lambda: httpx.get(f"{http}/v1/whoami", headers={"authorization": f"Bearer {uncached}"}, timeout=30),
                "keys": lambda: httpx.get(f"{http}/v1/keys", headers=admin, timeout=30),
                "logout": lambda: httpx.post(f"{http}/v1/logout", cookies=login.cookies, timeout=30),
                "style": lambda: httpx.put(f"{http}/v1/sessions/{session_id}/style", json={}, headers=admin, timeout=30),
            }
            for what, ask in answers.items():
                answer = ask()
                assert answer.status_code == 503 and answer.headers.get("retry-after"), (what, answer.status_code, answer.text)
                assert answer.json() == {"detail": RECORDS_DOWN}, what
            assert next_frame() == answered + 2  # the stream went on through all of it
            sent.put(None)
            if outage == "hung":
                paused.close()  # SIGCONT
                for _ in range(20):  # a client retries UNAVAILABLE
                    resumed = failed(lambda: creator.call("CreateSession", two_target_request()))
                    if isinstance(resumed, pb.CreateSessionResponse):
                        break
                    time.sleep(0.25)
                assert isinstance(resumed, pb.CreateSessionResponse), resumed
    finally:
        paused.close()
        postgres.stop()
