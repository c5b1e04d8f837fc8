"""A session's frames keep their order through the compiled edge (native/src/edge.rs, zmq_edge.rs):
while one of its frames is with the front's Python (here: from a caller the edge does not know yet),
its later frames from a caller let in go there too, not straight to the worker, and go straight
again once Python has answered. The edge alone, driven by hand: a real ROUTER socket, a socket pair
standing in for the worker's frame socket, the events answered by this test as the front would."""

from __future__ import annotations

import select
import socket
import time

import zmq

from camdirector import _native
from camdirector.front.zmq_service import loaded_libzmq
from camdirector.infra.channels import encode_reply, read_request
from camdirector.v1 import director_pb2 as pb

SESSION = "s" * 32


def _frame(number: int) -> bytes:
    return pb.FrameUpdate(session_id=SESSION, frame=number).SerializeToString()


def _events(edge: _native.Edge, wake: socket.socket, n: int) -> list[tuple]:
    """The next `n` events the edge asks the front, waited for on its wake socket."""
    found: list[tuple] = []
    deadline = time.monotonic() + 10
    while len(found) < n:
        assert select.select([wake], [], [], max(0.0, deadline - time.monotonic()))[0], f"{len(found)} of {n} events"
        wake.recv(4096)
        found += edge.take_events()
    return found


def test_a_sessions_frames_wait_behind_its_frame_with_python():
    context = zmq.Context.instance()
    router = context.socket(zmq.ROUTER)
    router.setsockopt(zmq.LINGER, 0)
    router.bind("tcp://127.0.0.1:*")
    address = router.getsockopt_string(zmq.LAST_ENDPOINT)
    wake, edge_end = socket.socketpair()
    edge = _native.Edge(None, "", edge_end.detach(), [], 1 << 20, False, 60.0, 120.0)
    worker_front, worker = socket.socketpair()
    clients = []
    try:
        path = loaded_libzmq()
        assert path is not None
        edge.serve_zmq(router.underlying, path, zmq.zmq_version_info())
        edge.set_worker(0, worker_front.detach())
        edge.route(SESSION, 0, "default", 60.0, 0.0, None)
        known, stranger = (context.socket(zmq.DEALER) for _ in range(2))
        for client in (known, stranger):
            client.setsockopt(zmq.LINGER, 0)
            client.setsockopt(zmq.RCVTIMEO, 10000)
            client.connect(address)
            clients.append(client)
        reader = worker.makefile("rb")

        def answered_by_worker(number: int) -> None:
            known.send_multipart([b"Frame", _frame(number), b"Bearer known"])
            request_id, op, session_id, payload = read_request(reader)
            assert (op, session_id, payload) == ("frame", SESSION, _frame(number))
            worker.sendall(encode_reply(request_id, 0, f"worker {number}".encode(), None))
            assert known.recv_multipart() == [b"0", f"worker {number}".encode()]

        # the known caller's first frame goes to Python, which lets it in
        known.send_multipart([b"Frame", _frame(1), b"Bearer known"])
        ((kind, token, parts),) = _events(edge, wake, 1)
        assert kind == "zmq" and parts[1:] == [b"Frame", _frame(1), b"Bearer known"]
        edge.answer_zmq(token, [parts[0], b"0", b"python 1"], (None, "default"))
        assert known.recv_multipart() == [b"0", b"python 1"]
        answered_by_worker(2)

        # a stranger's frame of the session is with Python: the known caller's next waits behind it
        stranger.send_multipart([b"Frame", _frame(3), b"Bearer stranger"])
        ((_, held_token, held_parts),) = _events(edge, wake, 1)
        known.send_multipart([b"Frame", _frame(4), b"Bearer known"])
        ((_, token, parts),) = _events(edge, wake, 1)
        assert parts[1:] == [b"Frame", _frame(4), b"Bearer known"]
        assert not select.select([worker], [], [], 0.2)[0]  # nothing reached the worker
        edge.answer_zmq(held_token, [held_parts[0], b"0", b"python 3"], None)
        edge.answer_zmq(token, [parts[0], b"0", b"python 4"], None)
        assert stranger.recv_multipart() == [b"0", b"python 3"]
        assert known.recv_multipart() == [b"0", b"python 4"]

        # answered: straight to the worker again
        answered_by_worker(5)
    finally:
        edge.stop()
        for client in clients:
            client.close()
        router.close()
        wake.close()
        worker.close()
