"""The liveness port (front/live_check.py): what it answers, that it answers while the thread that
runs the event loop is busy, and that nobody can hold it."""

from __future__ import annotations

import socket
import ssl
import struct
import threading
import time

import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.front import live_check
from camdirector.front.live_check import LiveCheck


def _ask(address: str, request: bytes = b"GET /live HTTP/1.0\r\n\r\n", tls: ssl.SSLContext | None = None) -> bytes:
    host, _, port = address.rpartition(":")
    with socket.create_connection((host, int(port)), timeout=5) as raw:
        sock = tls.wrap_socket(raw, server_hostname="localhost") if tls else raw
        sock.sendall(request)
        answer = b""
        while chunk := sock.recv(4096):
            answer += chunk
        return answer


@pytest.fixture
def check():
    """A liveness port whose loop last woke at `wake[0]` on the clock `now[0]`."""
    wake, now = [0.0], [0.0]
    live = LiveCheck("127.0.0.1:0", lambda: wake[0], stall_s=2.0, clock=lambda: now[0])
    live.start()
    yield live, wake, now
    live.stop()


def test_live_while_the_loop_wakes_and_stalled_once_it_has_not_for_stall_s(check):
    live, wake, now = check
    assert _ask(live.address).startswith(b"HTTP/1.0 200 OK") and _ask(live.address).endswith(b"live\n")
    now[0] = 2.0  # exactly stall_s since the last wake: still live
    assert _ask(live.address).startswith(b"HTTP/1.0 200 OK")
    now[0] = 2.5
    assert _ask(live.address).startswith(b"HTTP/1.0 503 Service Unavailable")
    wake[0] = 2.4
    assert _ask(live.address).startswith(b"HTTP/1.0 200 OK")


def test_other_requests_are_refused_in_words(check):
    live, _, _ = check
    assert _ask(live.address, b"GET /healthz HTTP/1.0\r\n\r\n").startswith(b"HTTP/1.0 404 Not Found")
    assert _ask(live.address, b"POST /live HTTP/1.0\r\n\r\n").startswith(b"HTTP/1.0 404 Not Found")
    too_long = b"GET /live HTTP/1.0\r\nX: " + b"a" * live_check.MAX_REQUEST_BYTES + b"\r\n\r\n"
    with pytest.raises(ConnectionResetError):  # closed unanswered, the rest of the request unread
        _ask(live.address, too_long)
    assert _ask(live.address).startswith(b"HTTP/1.0 200 OK")


def test_a_silent_connection_is_closed_and_idle_ones_cannot_hold_the_port():
    live = LiveCheck("127.0.0.1:0", time.monotonic)  # the real clock: the deadline has to pass
    live.start()
    try:
        host, _, port = live.address.rpartition(":")
        idle = [socket.create_connection((host, int(port)), timeout=5) for _ in range(live_check.MAX_CONNECTIONS + 8)]
        assert _ask(live.address).startswith(b"HTTP/1.0 200 OK")  # the oldest idle ones made room
        assert idle[0].recv(1) == b""  # closed by the server: the oldest
        idle[-1].settimeout(live_check.REQUEST_TIMEOUT_S + 5)
        assert idle[-1].recv(1) == b""  # closed by the server once its request's time ran out
        for sock in idle:
            sock.close()
    finally:
        live.stop()


def test_it_answers_while_the_thread_of_the_event_loop_holds_the_interpreter():
    """The balancer's checks must not wait for a busy loop (issue 40): the main thread spins in
    Python, as a loop stuck in a long computation would, and the answer comes before it ends."""
    live = LiveCheck("127.0.0.1:0", time.monotonic)
    live.start()
    answered: list[tuple[bytes, float]] = []
    client = threading.Thread(target=lambda: answered.append((_ask(live.address), time.monotonic())))
    try:
        client.start()
        spin_until = time.monotonic() + 3.0
        while time.monotonic() < spin_until:
            pass
        spin_end = time.monotonic()
        client.join(10)
        ((answer, at),) = answered
        assert answer.startswith(b"HTTP/1.0 200 OK") and at < spin_end
    finally:
        live.stop()


def test_over_tls_it_shows_the_certificate_and_a_plain_request_gets_no_answer(tls_files):
    server_context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server_context.load_cert_chain(tls_files.cert, tls_files.key)
    live = LiveCheck("127.0.0.1:0", time.monotonic, tls=server_context)
    live.start()
    try:
        client_context = ssl.create_default_context(cafile=str(tls_files.ca_cert))
        assert _ask(live.address, tls=client_context).startswith(b"HTTP/1.0 200 OK")
        try:  # not a TLS hello: the handshake fails, closed unanswered (reset if bytes were left unread)
            plain = _ask(live.address)
        except ConnectionResetError:
            plain = b""
        assert plain == b""
        assert _ask(live.address, tls=client_context).startswith(b"HTTP/1.0 200 OK")
    finally:
        live.stop()


def test_checks_left_behind_while_the_node_hung_do_not_stop_it(tls_files):
    """A hung node's kernel takes the balancer's checks into its backlog; each sends its TLS hello
    and gives up with a reset. When the node resumes, the thread takes them reset with data unread,
    which a TLS wrap refuses (ssl.SSLError): the thread lives on and answers the next check (the chaos run's
    paused node once stayed out of the balancer for good)."""
    server_context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server_context.load_cert_chain(tls_files.cert, tls_files.key)
    live = LiveCheck("127.0.0.1:0", time.monotonic, tls=server_context)  # not started: the node hangs
    host, _, port = live.address.rpartition(":")
    client_context = ssl.create_default_context(cafile=str(tls_files.ca_cert))
    for _ in range(3):
        raw = socket.create_connection((host, int(port)), timeout=5)
        hello = client_context.wrap_socket(raw, server_hostname="localhost", do_handshake_on_connect=False)
        hello.setblocking(False)
        with pytest.raises(ssl.SSLWantReadError):
            hello.do_handshake()  # the hello is sent; no answer comes
        hello.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # reset, as HAProxy ends a check
        hello.close()
    live.start()
    try:
        assert _ask(live.address, tls=client_context).startswith(b"HTTP/1.0 200 OK")
    finally:
        live.stop()


def test_stop_closes_the_port_at_once(check):
    live, _, _ = check
    host, _, port = live.address.rpartition(":")
    live.stop()
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((host, int(port)), timeout=5)


def test_a_node_serves_it_where_asked_and_names_it_in_its_ready_line():
    server = ServerProcess("--live", "127.0.0.1:0", "--workers", "0", transports=("grpc",))
    try:
        assert _ask(server.ready["live"]).startswith(b"HTTP/1.0 200 OK")
    finally:
        server.stop()
