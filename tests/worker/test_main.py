"""The worker's loop tells a request waiting in its read buffer from none (worker/main.py)."""

import select
import socket

from camdirector.infra.channels import encode_request
from camdirector.worker.main import _Requests


def test_a_request_read_into_the_buffer_with_the_one_before_it_counts_as_waiting():
    front, worker = socket.socketpair()
    with front, worker:
        incoming = _Requests(worker)
        front.sendall(b"".join(encode_request(1, "frame", "s-1", b"a" * 1000) + encode_request(2, "style", "s-é", b"b" * 20)))
        assert incoming.read() == (1, "frame", "s-1", b"a" * 1000)
        assert not select.select([worker], [], [], 0)[0]  # the socket is drained: both came in one read
        assert incoming.waiting()  # the second waits in the buffer all the same
        assert incoming.read() == (2, "style", "s-é", b"b" * 20)  # a session id of more bytes than characters
        assert not incoming.waiting()
        front.sendall(b"".join(encode_request(3, "ping", "", b"")))
        assert incoming.waiting()  # on the socket
        assert incoming.read() == (3, "ping", "", b"")
        assert not incoming.waiting()
