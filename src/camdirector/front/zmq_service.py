"""ZeroMQ transport: a ROUTER socket speaking the two-frame envelope of docs/protocol.md.

Request: [RPC name, serialized request]; reply: [status code as ASCII decimal, serialized reply or
UTF-8 error message]. DEALER clients send exactly that; REQ clients add an empty delimiter frame,
which is echoed back. Anything else on the socket gets an error reply (when it has an identity to
answer) and never disturbs the loop.
"""
from __future__ import annotations

import asyncio
import logging
import time

import zmq
import zmq.asyncio

from camdirector.errors import DirectorError, exhausted, internal, invalid, unimplemented
from camdirector.front.router import SessionRouter, named_session, session_id_of
from camdirector.v1 import director_pb2 as pb

log = logging.getLogger("camdirector.zmq")
TRANSPORT = "zmq"


class ZmqTransport:
    def __init__(self, router: SessionRouter, address: str):
        self.router = router
        self.metrics = router.metrics
        self.ctx = zmq.asyncio.Context.instance()
        self.socket = self.ctx.socket(zmq.ROUTER)
        self.socket.setsockopt(zmq.LINGER, 0)
        # ZeroMQ drops (and disconnects) anything far over the limit before we see it; between the
        # limit and this cap we answer RESOURCE_EXHAUSTED ourselves.
        self.socket.setsockopt(zmq.MAXMSGSIZE, 2 * router.settings.max_message_bytes)
        self.socket.bind(address)
        self.address = self.socket.getsockopt_string(zmq.LAST_ENDPOINT)
        self._loop_task: asyncio.Task | None = None
        self._tasks: set[asyncio.Task] = set()
        self._handlers = {
            b"CreateSession": lambda p: self.router.create(p, TRANSPORT),
            b"Frame": lambda p: self.router.frame(p, session_id_of(pb.FrameUpdate, p), TRANSPORT),
            b"UpdateStyle": self.router.update_style,
            b"TakeShot": self.router.take_shot,
            b"CloseSession": self.router.close,
        }

    def start(self) -> None:
        self._loop_task = asyncio.create_task(self._serve())

    async def stop(self) -> None:
        if self._loop_task is not None:
            self._loop_task.cancel()
        self.socket.close()

    async def _serve(self) -> None:
        while True:
            parts = await self.socket.recv_multipart(copy=True)
            task = asyncio.create_task(self._handle(parts))  # parsing before the first await keeps order
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)

    async def _handle(self, parts: list[bytes]) -> None:
        identity, body = parts[0], parts[1:]
        envelope = [identity]
        if len(body) == 3 and body[0] == b"":  # REQ client
            envelope, body = [identity, b""], body[1:]
        t0 = time.perf_counter()
        rpc = body[0] if body else b""
        try:
            if len(body) != 2:
                raise invalid(f"expected 2 frames (RPC name, payload), got {len(body)}")
            name, payload = body
            handler = self._handlers.get(name)
            if handler is None:
                raise unimplemented(f"unknown RPC {name[:64]!r}; expected one of CreateSession, Frame, UpdateStyle, "
                                    "TakeShot, CloseSession")
            if len(payload) > self.router.settings.max_message_bytes:
                raise exhausted(f"message of {len(payload)} bytes exceeds the limit of {self.router.settings.max_message_bytes}")
            reply = [b"0", await handler(payload)]
        except DirectorError as exc:
            self.metrics.labelled(self.metrics.errors, TRANSPORT, exc.code.name).inc()
            reply = [str(exc.code.value[0]).encode(), exc.message.encode()]
        except Exception as exc:  # never let one request end the loop; INTERNAL, as over gRPC
            name = rpc[:64].decode(errors="replace")
            error = internal(exc, name, named_session(name, body[1]) if len(body) == 2 else None, log)
            self.metrics.labelled(self.metrics.errors, TRANSPORT, error.code.name).inc()
            reply = [str(error.code.value[0]).encode(), error.message.encode()]
        label = rpc.decode() if rpc in self._handlers else "invalid"  # bounded label set
        self.metrics.labelled(self.metrics.request, TRANSPORT, label).observe(time.perf_counter() - t0)
        try:
            await self.socket.send_multipart(envelope + reply)
        except zmq.ZMQError as exc:  # the peer went away
            log.debug("zmq reply dropped: %s", exc)
