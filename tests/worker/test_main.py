"""The worker's loop tells a request waiting in its read buffer from none, on either of its sockets
(worker/main.py)."""

import select
import socket

from camdirector.infra.channels import encode_request
from camdirector.worker.main import _Requests, _Sockets


def test_a_request_read_into_the_buffer_with_the_one_before_it_counts_as_waiting():
    front, worker = socket.socketpair()
    with front, worker:
        requests = _Requests(worker)
        incoming = _Sockets(requests, None)
        front.sendall(b"".join(encode_request(1, "frame", "s-1", b"a" * 1000) + encode_request(2, "style", "s-é", b"b" * 20)))
        assert requests.read() == (1, "frame", "s-1", b"a" * 1000)
        assert not select.select([worker], [], [], 0)[0]  # the socket is drained: both came in one read
        assert incoming.waiting()  # the second waits in the buffer all the same
        assert requests.read() == (2, "style", "s-é", b"b" * 20)  # a session id of more bytes than characters
        assert not incoming.waiting()
        front.sendall(b"".join(encode_request(3, "ping", "", b"")))
        assert incoming.waiting()  # on the socket
        assert requests.read() == (3, "ping", "", b"")
        assert not incoming.waiting()


def test_the_loop_takes_a_request_from_whichever_socket_has_one_and_a_buffered_one_first():
    front, worker = socket.socketpair()
    edge, frames = socket.socketpair()
    with front, worker, edge, frames:
        control, framed = _Requests(worker), _Requests(frames)
        incoming = _Sockets(control, framed)
        assert not incoming.waiting()
        edge.sendall(b"".join(encode_request(7, "frame", "s-1", b"f" * 100) + encode_request(8, "frame", "s-1", b"g")))
        assert incoming.waiting()
        assert incoming.next() is framed
        assert framed.read() == (7, "frame", "s-1", b"f" * 100)
        front.sendall(b"".join(encode_request(9, "style", "s-1", b"s")))
        assert incoming.next() is framed  # its second request is already read: before the front's
        assert framed.read() == (8, "frame", "s-1", b"g")
        assert incoming.next() is control
        assert control.read() == (9, "style", "s-1", b"s")
        assert not incoming.waiting()
        edge.close()
        assert incoming.next() is framed  # its end of file, which the loop reads and drops
