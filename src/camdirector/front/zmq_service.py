"""ZeroMQ transport: a ROUTER socket speaking the two-frame envelope of docs/protocol.md.

Request: [RPC name, serialized request, key]; reply: [status code as ASCII decimal, serialized
reply or UTF-8 error message]. The key frame is `Bearer KEY`, checked as gRPC's metadata is
(front/session_calls.py); a server without authentication (`--no-auth`) also takes the two-frame
request without it. DEALER clients send exactly that; REQ clients add an empty delimiter frame,
which is echoed back. Anything else on the socket gets an error reply (when it has an identity to
answer) and never disturbs the loop.

With authentication on the socket is a CURVE server (RFC 26): traffic is encrypted and clients
must know the server's public key, `DIR/zmq/server.key` (made at the first start; the secret half
beside it, mode 0600). Clients are not told apart by CURVE keys: the bearer key says who calls.

The socket is read straight off the event loop (its ZMQ_FD, which is edge-triggered: each wake-up
reads every message waiting, and a send that leaves messages waiting schedules another read)
rather than through `zmq.asyncio`, whose futures and flag enums cost the front about 40 us a frame.
Sends never wait: a ROUTER socket queues the reply or, past its high-water mark, drops it.

With `zmq_front compiled` (the default) the socket is made and bound here but read and written by
the compiled edge (front/edge.py, native/src/zmq_edge.rs) through pyzmq's own libzmq: it answers a
routed session's Frame requests itself and hands every other request to `answer`, whose reply it
sends. Where pyzmq's libzmq is not a shared library of the process, the socket stays here.
"""

from __future__ import annotations

import asyncio
import logging
import os
import tempfile
import time
from pathlib import Path
from typing import cast

import zmq
import zmq.auth

from camdirector import _native
from camdirector.access.guard import Guard, Identity
from camdirector.errors import DirectorError, exhausted, invalid, unimplemented
from camdirector.front.router import SessionRouter, named_session
from camdirector.front.session_calls import RPCS, SessionCalls

log = logging.getLogger("camdirector.zmq")
TRANSPORT = "zmq"


ENVELOPE_SLACK_BYTES = 64 * 1024  # over max_message_bytes a frame may be and still get an answer, bytes
CURVE_DIR = "zmq"  # in the data directory: server.key (public) and server.key_secret
READ_BATCH = 64  # messages read in one turn of the event loop before the others get theirs
# plain ints: pyzmq's enums cost a call each
_EVENTS, _POLLIN, _RCVMORE, _NOBLOCK = int(zmq.EVENTS), int(zmq.POLLIN), int(zmq.RCVMORE), int(zmq.NOBLOCK)


def curve_server_keys(data_dir: str | Path) -> tuple[bytes, bytes]:
    """The server's CURVE (public, secret) keys, Z85, made on first use. Nodes sharing one data
    directory and starting together agree: the pair is made aside and its secret file (which
    holds both halves) linked into place only if none is there yet, so the first one wins."""
    folder = Path(data_dir) / CURVE_DIR
    secret_file = folder / "server.key_secret"
    if not secret_file.exists():
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=folder) as aside:
            public, secret = zmq.auth.create_certificates(aside, "server")
            os.chmod(secret, 0o600)
            try:
                os.link(secret, secret_file)  # atomic, and refuses to replace another node's
                os.replace(public, folder / "server.key")
            except FileExistsError:
                pass
    public_key, secret_key = zmq.auth.load_certificate(secret_file)
    assert secret_key is not None  # the secret file holds both halves
    return public_key, secret_key


def loaded_libzmq() -> str | None:
    """The path of the libzmq pyzmq loaded into this process (a shared library), from
    /proc/self/maps; None where there is none (pyzmq built with libzmq inside) or no /proc."""
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return None
    for line in maps.splitlines():
        path = line.split(maxsplit=5)[-1] if line.count(" ") >= 5 else ""
        if os.path.basename(path).startswith("libzmq"):
            return path
    return None


class ZmqTransport:
    """`curve`: the server's (public, secret) keys, None for a plaintext socket (`--no-auth`)."""

    def __init__(self, router: SessionRouter, address: str, guard: Guard, curve: tuple[bytes, bytes] | None = None):
        self.router = router
        self.guard = guard
        self.calls = SessionCalls(router, guard, TRANSPORT)
        self.metrics = router.metrics
        self.ctx: zmq.Context[zmq.Socket[bytes]] = zmq.Context.instance()
        self.socket = self.ctx.socket(zmq.ROUTER)
        self.socket.setsockopt(zmq.LINGER, 0)
        if curve is not None:
            self.socket.curve_server = True
            self.socket.curve_publickey, self.socket.curve_secretkey = curve
        # libzmq drops a frame over this cap as its length arrives, before reading it, and
        # disconnects the peer: an oversized message costs the loop nothing, key or not. A frame
        # between the limit and the cap (CURVE's box included) is answered RESOURCE_EXHAUSTED.
        self.socket.setsockopt(zmq.MAXMSGSIZE, router.settings.max_message_bytes + ENVELOPE_SLACK_BYTES)
        self.socket.bind(address)
        self.address = self.socket.getsockopt_string(zmq.LAST_ENDPOINT)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._read_scheduled = False
        self._tasks: set[asyncio.Task] = set()
        self._handlers = {name.encode(): (RPCS[name], call) for name, call in self.calls.by_rpc.items()}

    def hand_over(self, edge: _native.Edge) -> bool:
        """Lets the compiled edge read and write the socket from now on (zmq_front compiled;
        native/src/zmq_edge.rs), through pyzmq's own libzmq; it asks `answer` for every request it
        does not answer itself. False, logged, when that libzmq cannot be shared (then `start`)."""
        path = loaded_libzmq()
        if path is None:
            log.warning("pyzmq's libzmq is not a shared library of this process: ZeroMQ stays with the Python front")
            return False
        try:
            edge.serve_zmq(self.socket.underlying, path, zmq.zmq_version_info())
        except OSError as exc:
            log.warning("the compiled edge cannot read the ZeroMQ socket (%s): it stays with the Python front", exc)
            return False
        return True

    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._loop.add_reader(self.socket.FD, self._read)
        self._read_soon()  # messages may wait already, and the descriptor only tells of new ones

    async def stop(self) -> None:
        if self._loop is not None:
            self._loop.remove_reader(self.socket.FD)
            self._loop = None
        self.socket.close()

    def _read_soon(self) -> None:
        if not self._read_scheduled and self._loop is not None:
            self._read_scheduled = True
            self._loop.call_soon(self._read)

    def _waiting(self) -> bool:
        """Whether a message waits to be read (ZMQ_EVENTS; asking also clears the descriptor's signal)."""
        return bool(cast("int", self.socket.get(_EVENTS)) & _POLLIN)

    def _read(self) -> None:
        """Reads up to READ_BATCH waiting messages, each handled by its own task (in arrival
        order: a task runs up to its first await before the next starts); more waiting, reads
        again on the next turn."""
        self._read_scheduled = False
        sock = self.socket
        if sock.closed:
            return
        for _ in range(READ_BATCH):
            if not self._waiting():
                return
            parts = [sock.recv(_NOBLOCK)]
            while sock.get(_RCVMORE):
                parts.append(sock.recv(_NOBLOCK))
            task = asyncio.create_task(self._handle(parts))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
        self._read_soon()

    def _error_reply(self, error: DirectorError) -> list[bytes]:
        self.metrics.labelled(self.metrics.errors, TRANSPORT, error.code.name).inc()
        return [str(error.code.value[0]).encode(), error.message.encode()]

    async def _handle(self, parts: list[bytes]) -> None:
        reply, _ = await self.answer(parts)
        try:
            self.socket.send_multipart(reply, _NOBLOCK)
            if self._waiting():  # the send took the descriptor's signal of messages waiting
                self._read_soon()
        except zmq.ZMQError as exc:  # the socket closed (stopping)
            log.debug("zmq reply dropped: %s", exc)

    async def answer(self, parts: list[bytes]) -> tuple[list[bytes], tuple[Identity, bytes] | None]:
        """The reply's frames (its envelope first) to a request's (its identity first); with them,
        for a Frame answered, its caller and payload (front/edge.py routes the session it names
        straight to its worker)."""
        identity, body = parts[0], parts[1:]
        envelope = [identity]
        if len(body) in (3, 4) and body[0] == b"":  # REQ client
            envelope, body = [identity, b""], body[1:]
        t0 = time.perf_counter()
        rpc = body[0] if body else b""
        answered = None
        try:
            if len(body) not in (2, 3):
                raise invalid(f"expected 3 frames (RPC name, payload, key), got {len(body)}")
            name, payload = body[:2]
            authorization = body[2].decode("utf-8", errors="replace") if len(body) == 3 else None
            handler = self._handlers.get(name)
            if handler is None:
                raise unimplemented(
                    f"unknown RPC {name[:64]!r}; expected one of CreateSession, Frame, UpdateStyle, TakeShot, CloseSession"
                )
            if len(payload) > self.router.settings.max_message_bytes:  # the size first: it costs nothing
                raise exhausted(f"message of {len(payload)} bytes exceeds the limit of {self.router.settings.max_message_bytes}")
            need, call = handler
            caller = await self.guard.authorize_async(authorization, need.verb, fresh=need.fresh)  # before the payload is parsed
            reply = [b"0", await call(payload, caller)]
            if name == b"Frame":
                answered = caller, payload
        except Exception as exc:  # never let one request end the loop; answered as over gRPC (Guard.refusal)
            rpc_name = rpc[:64].decode(errors="replace")
            named = lambda: named_session(rpc_name, body[1]) if len(body) in (2, 3) else None  # noqa: E731
            reply = self._error_reply(self.guard.refusal(exc, rpc_name, named, log))
        label = rpc.decode() if rpc in self._handlers else "invalid"  # bounded label set
        self.metrics.labelled(self.metrics.request, TRANSPORT, label).observe(time.perf_counter() - t0)
        return envelope + reply, answered
