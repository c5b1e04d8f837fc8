"""The ZeroMQ socket read straight off the event loop (front/zmq_service.py): messages that
waited before the loop looked, and far more than one turn's batch sent at once, from several
clients, each get their own answer; a REQ client's delimiter comes back. A real ROUTER socket and
real DEALER and REQ clients, a real router (sessions inline) whose Frame handler echoes."""

from __future__ import annotations

import asyncio

import zmq
import zmq.asyncio

from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionRouter
from camdirector.front.zmq_service import READ_BATCH, ZmqTransport
from camdirector.server_settings import ServerSettings

CLIENTS = 3
PER_CLIENT = 3 * READ_BATCH + 5  # several turns' batches each, sent before any is answered


def test_every_message_waiting_or_sent_at_once_is_answered(tmp_path):
    async def exchange() -> tuple[list[list[list[bytes]]], list[bytes]]:
        router = SessionRouter(ServerSettings(workers=0, data_dir=str(tmp_path)), Metrics())
        transport = ZmqTransport(router, "tcp://127.0.0.1:*", router.guard)

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
            transport.start()
            replies = [[await asyncio.wait_for(c.recv_multipart(), 10.0) for _ in range(PER_CLIENT)] for c in clients]
            await req.send_multipart([b"Frame", b"by REQ"])
            req_reply = await asyncio.wait_for(req.recv_multipart(), 10.0)
        finally:
            for sock in [*clients, req]:
                sock.close()
            await transport.stop()
        return replies, req_reply

    replies, req_reply = asyncio.run(exchange())
    for k, answered in enumerate(replies):
        assert sorted(answered) == sorted([b"0", f"echo {k}/{i}".encode()] for i in range(PER_CLIENT))
    assert req_reply == [b"0", b"echo by REQ"]  # the REQ socket took the reply: its delimiter came back
