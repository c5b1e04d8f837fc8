"""The ZeroMQ socket read straight off the event loop (front/zmq_service.py), or by the compiled
edge (front/edge.py, native/src/zmq_edge.rs), which hands these requests to the same Python: messages
that waited before the socket was first read, and far more than one turn's batch sent at once, from
several clients, each get their own answer; a REQ client's delimiter comes back. Where pyzmq's
libzmq cannot be shared, the edge leaves the socket to the loop. A real ROUTER socket and real
DEALER and REQ clients, a real router (sessions inline) whose Frame handler echoes."""

from __future__ import annotations

import asyncio
import socket

import pytest
import zmq
import zmq.asyncio

from camdirector import _native
from camdirector.front import zmq_service
from camdirector.front.edge import EdgeFront
from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionRouter
from camdirector.front.zmq_service import READ_BATCH, ZmqTransport
from camdirector.server_settings import ServerSettings

CLIENTS = 3
PER_CLIENT = 3 * READ_BATCH + 5  # several turns' batches each, sent before any is answered


@pytest.mark.parametrize("reader", ["loop", "edge", "edge without a shared libzmq", "edge given a libzmq not loaded"])
def test_every_message_waiting_or_sent_at_once_is_answered(reader, tmp_path, monkeypatch):
    if reader == "edge without a shared libzmq":
        monkeypatch.setattr(zmq_service, "loaded_libzmq", lambda: None)
    if reader == "edge given a libzmq not loaded":  # the edge refuses it (OSError): the loop reads
        monkeypatch.setattr(zmq_service, "loaded_libzmq", lambda: str(tmp_path / "libzmq.so.5"))

    async def exchange() -> tuple[list[list[list[bytes]]], list[bytes]]:
        router = SessionRouter(ServerSettings(workers=0, data_dir=str(tmp_path)), Metrics())
        transport = ZmqTransport(router, "tcp://127.0.0.1:*", router.guard)
        edge = EdgeFront(router, router.guard) if reader != "loop" else None

        async def echo(payload, identity):
            await asyncio.sleep(0)  # answered on a later turn, as a worker's reply is
            return b"echo " + payload

        transport._handlers[b"Frame"] = (transport._handlers[b"Frame"][0], echo)
        context = zmq.asyncio.Context.instance()
        clients = [context.socket(zmq.DEALER) for _ in range(CLIENTS)]
        req = context.socket(zmq.REQ)
        for sock in [*clients, req]:
            sock.setsockopt(zmq.LINGER, 0)
            sock.connect(transport.address)
        try:
            for k, client in enumerate(clients):  # all sent before the transport reads anything
                for i in range(PER_CLIENT):
                    await client.send_multipart([b"Frame", f"{k}/{i}".encode()])
            await asyncio.sleep(0.2)  # arrived and waiting in the ROUTER socket
            if edge is None:
                transport.start()
            else:
                await edge.start(None, transport)
                assert (edge.zmq is transport) == (reader == "edge")  # else the loop reads it
            replies = [[await asyncio.wait_for(c.recv_multipart(), 10.0) for _ in range(PER_CLIENT)] for c in clients]
            await req.send_multipart([b"Frame", b"by REQ"])
            req_reply = await asyncio.wait_for(req.recv_multipart(), 10.0)
        finally:
            for sock in [*clients, req]:
                sock.close()
            if edge is not None:
                await edge.stop()
            await transport.stop()
        return replies, req_reply

    replies, req_reply = asyncio.run(exchange())
    for k, answered in enumerate(replies):
        assert sorted(answered) == sorted([b"0", f"echo {k}/{i}".encode()] for i in range(PER_CLIENT))
    assert req_reply == [b"0", b"echo by REQ"]  # the REQ socket took the reply: its delimiter came back


def test_the_edge_takes_no_socket_through_a_libzmq_of_another_version():
    """The edge calls the libzmq pyzmq loaded only when it is the version pyzmq reports."""
    path = zmq_service.loaded_libzmq()
    assert path is not None  # pyzmq's wheels ship libzmq as a shared library
    wake, edge_end = socket.socketpair()
    edge = _native.Edge(None, "", edge_end.detach(), [], 1 << 20, False, 60.0, 120.0)
    try:
        with pytest.raises(OSError, match=r"pyzmq's is 3\.0\.0"):
            edge.serve_zmq(0, path, (3, 0, 0))
    finally:
        edge.stop()
        wake.close()
