"""ZeroMQ checks a message's size before its key (front/zmq_service.py, issue 39 finding 3): a
message over the limit from a client without a key is refused, the one far over it by libzmq
before it is read, and the socket goes on serving the others."""

from __future__ import annotations

import zmq

from camdirector.deploy.server_process import ServerProcess
from camdirector.front.zmq_service import ENVELOPE_SLACK_BYTES
from tests.service import wire_client as wc

LIMIT = 1024 * 1024  # bytes, the server's max_message_bytes


def test_an_oversized_message_without_a_key_is_refused_before_it_is_read_and_others_are_served():
    with ServerProcess("--workers", "0", "--max-message-bytes", str(LIMIT), transports=("zmq",), auth=True) as server:
        stranger = wc.ZmqRaw(server.zmq, server_key=server.zmq_server_key)  # no key frame
        code, message = stranger.send_raw([b"CreateSession", b"\x00" * (LIMIT + 100)])
        assert code == b"8" and b"exceeds the limit" in message  # RESOURCE_EXHAUSTED, not UNAUTHENTICATED
        stranger.sock.setsockopt(zmq.RCVTIMEO, 1500)
        stranger.sock.send_multipart([b"CreateSession", b"\x00" * (LIMIT + 2 * ENVELOPE_SLACK_BYTES), b"Bearer cdk_wrong"])
        try:
            answer = stranger.sock.recv_multipart()
        except zmq.Again:
            answer = None
        assert answer is None  # libzmq dropped it as its length arrived: the server never read it
        stranger.close()
        engine = wc.ZmqRaw(server.zmq, key=server.admin_key, server_key=server.zmq_server_key)
        session = engine.call("CreateSession", wc.two_target_request()).session_id
        assert len(engine.stream(list(wc.walk(session, 5)))) == 5
        engine.close()
        assert server.alive()
