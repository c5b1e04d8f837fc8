"""HAProxy's health check speaks gRPC health checking over TLS (deploy/haproxy.py): a node is up
only while grpc.health.v1.Health/Check answers SERVING, and only with a certificate of the CA; a
node that hangs (SIGSTOP) is marked down and the streams it held are cut; and a balancer with no
healthy node answers gRPC calls with UNAVAILABLE at once."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from concurrent import futures
from pathlib import Path

import grpc
import pytest
from grpc_health.v1 import health, health_pb2, health_pb2_grpc

from camdirector.deploy.haproxy import GRPC_BACKEND, Backend, BalancerSettings, HAProxy, render_config
from camdirector.deploy.services import free_port
from camdirector.v1 import director_pb2_grpc as pbg
from tests.conftest import service_or_skip
from tests.deploy.conftest import new_keys, route
from tests.service import wire_client as wc


@pytest.fixture
def balancer(tmp_path, tls_files):
    """Starts HAProxy in front of the given backends; stops it after the test."""
    started = []

    def start(*backends: Backend) -> HAProxy:
        proxy = service_or_skip(lambda: HAProxy(tmp_path, tls_files).start(list(backends)))
        started.append(proxy)
        return proxy

    yield start
    for proxy in started:
        proxy.stop()


def _health_server(certificate: Path, key: Path) -> tuple[grpc.Server, health.HealthServicer, int]:
    """A gRPC server of the health service alone, over TLS with this certificate; its port."""
    server = grpc.server(futures.ThreadPoolExecutor(2))
    servicer = health.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(servicer, server)
    port = server.add_secure_port("127.0.0.1:0", grpc.ssl_server_credentials([(key.read_bytes(), certificate.read_bytes())]))
    server.start()
    return server, servicer, port


def test_a_node_is_up_only_while_its_grpc_health_service_answers_serving(balancer, tls_files):
    server, servicer, port = _health_server(tls_files.cert, tls_files.key)
    try:
        servicer.set("", health_pb2.HealthCheckResponse.SERVING)
        proxy = balancer(Backend("node-1", 1, f"127.0.0.1:{port}", f"127.0.0.1:{free_port()}"))
        proxy.wait_until({"node-1": "UP"}, timeout_s=10, backends=(GRPC_BACKEND,))
        servicer.set("", health_pb2.HealthCheckResponse.NOT_SERVING)
        # each failed check waits out its timeout for a SERVING that does not come
        assert proxy.wait_until({"node-1": "DOWN"}, timeout_s=10, backends=(GRPC_BACKEND,)) < 5
        servicer.set("", health_pb2.HealthCheckResponse.SERVING)
        assert proxy.wait_until({"node-1": "UP"}, timeout_s=10, backends=(GRPC_BACKEND,)) < 5
    finally:
        server.stop(0)


# A gRPC health server (SERVING) over TLS in a process of its own, which a test can SIGSTOP; it
# prints its port.
_HEALTH_SERVER = """
import sys, threading
from concurrent import futures
import grpc
from grpc_health.v1 import health, health_pb2_grpc
server = grpc.server(futures.ThreadPoolExecutor(4))
health_pb2_grpc.add_HealthServicer_to_server(health.HealthServicer(), server)
credentials = grpc.ssl_server_credentials([(open(sys.argv[2], "rb").read(), open(sys.argv[1], "rb").read())])
print(server.add_secure_port("127.0.0.1:0", credentials), flush=True)
server.start()
threading.Event().wait()
"""


def test_a_hung_node_is_marked_down_and_the_streams_it_held_are_cut(balancer, tls_files):
    """A node SIGSTOPped keeps its connections open and silent. Its checks time out, HAProxy marks
    it DOWN, and `on-marked-down shutdown-sessions` ends the streams it held with an error, which
    the SDKs answer by opening them again through the balancer, to a live node. Without it such a
    stream waits for as long as the node hangs: here until its 20 s deadline."""
    node = subprocess.Popen(
        [sys.executable, "-c", _HEALTH_SERVER, str(tls_files.cert), str(tls_files.key)], stdout=subprocess.PIPE, text=True
    )
    try:
        port = int(node.stdout.readline())
        proxy = balancer(Backend("node-1", 1, f"127.0.0.1:{port}", f"127.0.0.1:{free_port()}"))
        proxy.wait_until({"node-1": "UP"}, timeout_s=10, backends=(GRPC_BACKEND,))
        with grpc.secure_channel(proxy.grpc, grpc.ssl_channel_credentials(tls_files.ca_cert.read_bytes())) as channel:
            watch = health_pb2_grpc.HealthStub(channel).Watch(health_pb2.HealthCheckRequest(), timeout=20)
            assert next(watch).status == health_pb2.HealthCheckResponse.SERVING  # the stream is open
            os.kill(node.pid, signal.SIGSTOP)
            proxy.wait_until({"node-1": "DOWN"}, timeout_s=15, backends=(GRPC_BACKEND,))
            with pytest.raises(grpc.RpcError) as ended:
                next(watch)
            assert ended.value.code() != grpc.StatusCode.DEADLINE_EXCEEDED, ended.value
    finally:
        os.kill(node.pid, signal.SIGCONT)
        node.kill()
        node.wait()


def test_the_checks_take_a_silent_node_out_within_about_a_second(tls_files):
    """The worst case of a hung node's checks (the first one starting just before it hangs) fits
    in 1.5 s, each check's timeout is shorter than the steady interval, and a restart's old
    process cannot hold streams for long (hard-stop-after)."""
    s = BalancerSettings()
    worst_s = s.check_interval_s + s.fall * s.check_timeout_s + (s.fall - 1) * s.check_fast_interval_s
    assert worst_s <= 1.5 and s.check_timeout_s < s.check_interval_s
    text = render_config(
        s, [Backend("node-1", 1, "127.0.0.1:1", "127.0.0.1:2")], tls=tls_files, stats_socket="s", grpc_port=3, http_port=4
    )
    assert text.count("on-marked-down shutdown-sessions") == 2  # both backends
    assert "inter 500ms fastinter 100ms downinter 500ms fall 2 rise 2" in text
    assert "timeout check 400ms" in text and "hard-stop-after 5s" in text


def test_a_node_whose_certificate_is_not_of_the_ca_gets_nothing(balancer, tmp_path):
    """A node that answers SERVING but shows a certificate of another CA (an impostor on its
    address) fails its checks: HAProxy sends it no call."""
    from camdirector.deploy.tls import make_tls_files

    other = make_tls_files(tmp_path / "other-ca")
    server, servicer, port = _health_server(other.cert, other.key)
    try:
        servicer.set("", health_pb2.HealthCheckResponse.SERVING)
        proxy = balancer(Backend("node-1", 1, f"127.0.0.1:{port}", f"127.0.0.1:{free_port()}"))
        proxy.wait_until({"node-1": "DOWN"}, timeout_s=10, backends=(GRPC_BACKEND,))
        (row,) = [r for r in proxy.command("show stat").splitlines() if r.startswith(f"{GRPC_BACKEND},node-1,")]
        assert "L6RSP" in row  # the TLS handshake failed: the check never reached the health service
    finally:
        server.stop(0)


def test_with_no_healthy_node_calls_fail_at_once_with_unavailable(balancer, tls_files):
    dead = [Backend(f"node-{k}", k, f"127.0.0.1:{free_port()}", f"127.0.0.1:{free_port()}") for k in (1, 2)]
    proxy = balancer(*dead)
    proxy.wait_until({b.name: "DOWN" for b in dead}, timeout_s=10)
    channel = grpc.secure_channel(proxy.grpc, grpc.ssl_channel_credentials(tls_files.ca_cert.read_bytes()))
    stub = pbg.DirectorStub(channel)
    for metadata in (route(new_keys(1)[0]), ()):  # hashed, and round robin
        start = time.monotonic()
        with pytest.raises(grpc.RpcError) as failed:
            stub.CreateSession(wc.two_target_request(), metadata=metadata, timeout=10)
        assert failed.value.code() == grpc.StatusCode.UNAVAILABLE, failed.value
        assert "503" in failed.value.details()  # HAProxy's answer, which gRPC maps to UNAVAILABLE
        assert time.monotonic() - start < 1.0
    channel.close()


def test_balancer_settings_are_validated():
    with pytest.raises(ValueError, match="weight"):
        BalancerSettings(weight=0)
    with pytest.raises(ValueError, match="fall and rise"):
        BalancerSettings(fall=0)
    with pytest.raises(ValueError, match="hard_stop_after_s"):
        BalancerSettings(hard_stop_after_s=0)
