"""The node's liveness port, which the balancer's health checks ask (issue 40: a hung node out of
the balancer, and its streams on another node, within 1.5 s).

Why a port of its own, answered by a thread of its own. The checks used to go over TLS to the gRPC
and HTTP ports, answered by the front's event loop, which also answers every frame. A hung node
(SIGSTOP, a frozen machine) is told from a busy one only by a check's timeout: the kernel still
accepts the connection, nothing answers. That timeout had to stay above a busy loop's slowest answer
plus a TLS handshake on two loaded cores (400 ms; 300 ms once took a healthy container node out
in a full test run), which kept a hung node in the balancer for up to 1.4 s. This thread does
nothing else: it answers within a millisecond or two whatever the loop is doing (it waits for the
GIL at most the interpreter's switch interval, 5 ms), so the balancer's timeout can be short
(deploy/haproxy.py) without taking a busy node out.

What the answer still says about the loop: `GET /live` is answered 503 "loop stalled" once the
front's loop has not woken for `stall_s` (LoopWatch.last_wake_s), so a loop blocked that long leaves
the balancer as a hung node does, and a loop that is merely slow stays in.

The protocol: HTTP/1.x, over TLS with the node's certificate when the node has one (the balancer
checks it against the cluster's CA: an impostor on a node's address fails its checks, as before),
`GET /live` answered 200 "live", any other request 404, the connection closed after one answer. No
key: it reads at most MAX_REQUEST_BYTES (a longer request is closed unanswered), answers fixed words
and tells nobody more than that the node runs. A connection that has not sent a whole request
REQUEST_TIMEOUT_S after it opened is closed, and at most MAX_CONNECTIONS are held (the oldest closed
for a new one). Bind it where the balancer reaches it and clients do not (docs/scaling.md): whoever
floods it can make the checks fail and take the node out.
"""

from __future__ import annotations

import logging
import selectors
import socket
import ssl
import threading
import time
from collections.abc import Callable

log = logging.getLogger("camdirector.live")

MAX_REQUEST_BYTES = 1024  # a check's request is one line and a few headers
REQUEST_TIMEOUT_S = 1.0  # a connection without a whole request this long after it opened is closed, s
MAX_CONNECTIONS = 64  # connections held at once; the oldest is closed for a new one
STALL_S = 2.0  # a front loop that has not woken this long is answered as stalled (503), s
POLL_S = 0.1  # the thread's longest sleep: deadlines are enforced this often, s


def _reply(status: str, body: str) -> bytes:
    return (
        f"HTTP/1.0 {status}\r\nContent-Type: text/plain\r\nContent-Length: {len(body)}\r\nConnection: close\r\n\r\n{body}"
    ).encode()


LIVE = _reply("200 OK", "live\n")
STALLED = _reply("503 Service Unavailable", "loop stalled\n")
NOT_FOUND = _reply("404 Not Found", "GET /live only\n")


class LiveCheck:
    """Serves `GET /live` on `address` (HOST:PORT, port 0 picks one) from a daemon thread (module
    docstring), over TLS with `tls` (a server context) when given. `last_wake_s` gives when the
    front's loop last woke, on `clock`'s time line, s."""

    def __init__(
        self,
        address: str,
        last_wake_s: Callable[[], float],
        *,
        tls: ssl.SSLContext | None = None,
        stall_s: float = STALL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._tls = tls
        host, _, port = address.rpartition(":")
        self._listener = socket.create_server((host.strip("[]"), int(port)), backlog=128)
        self._listener.setblocking(False)
        bound = self._listener.getsockname()
        self.address = f"{host}:{bound[1]}"  # where it listens, the port picked
        self._last_wake_s = last_wake_s
        self._stall_s = stall_s
        self._clock = clock
        self._selector = selectors.DefaultSelector()
        self._stop_r, self._stop_w = socket.socketpair()
        # connection -> (deadline s, bytes read so far); insertion order is age order
        self._open: dict[socket.socket, tuple[float, bytes]] = {}
        self._thread = threading.Thread(target=self._serve, name="live-check", daemon=True)

    def start(self) -> None:
        self._selector.register(self._listener, selectors.EVENT_READ)
        self._selector.register(self._stop_r, selectors.EVENT_READ)
        self._thread.start()

    def stop(self) -> None:
        """Closes the port first (a check now fails at once: the node leaves the balancer while it
        stops), then the thread and its connections. Once: later calls do nothing."""
        if self._stop_w.fileno() < 0:
            return
        self._stop_w.send(b"x")
        self._thread.join(timeout=2.0)
        for sock in (self._listener, self._stop_r, self._stop_w, *self._open):
            sock.close()
        self._selector.close()

    def answer(self, request: bytes) -> bytes:
        """The reply to one whole request (its bytes up to the blank line)."""
        if not request.startswith(b"GET /live "):
            return NOT_FOUND
        return LIVE if self._clock() - self._last_wake_s() <= self._stall_s else STALLED

    def _serve(self) -> None:
        while True:
            for key, _ in self._selector.select(timeout=POLL_S):
                if key.fileobj is self._stop_r:
                    self._listener.close()
                    return
                try:
                    if key.fileobj is self._listener:
                        self._accept()
                    elif key.fileobj in self._open:  # not closed by an earlier event of this batch
                        self._read(key.fileobj)
                except Exception:  # one connection's fault: the thread must outlive it, or the node's checks stop
                    log.exception("liveness port: a connection failed")
            now = self._clock()
            for sock in [s for s, (deadline, _) in self._open.items() if deadline < now]:
                self._close(sock)

    def _accept(self) -> None:
        try:
            sock, _ = self._listener.accept()
        except BlockingIOError:  # another wake-up took it
            return
        if len(self._open) >= MAX_CONNECTIONS:
            self._close(next(iter(self._open)))
        sock.setblocking(False)
        if self._tls is not None:  # the handshake is made by the first reads (_read)
            try:
                sock = self._tls.wrap_socket(sock, server_side=True, do_handshake_on_connect=False)
            except OSError:  # closed by its peer before it was taken (a check that timed out while the node hung)
                sock.close()
                return
        self._open[sock] = (self._clock() + REQUEST_TIMEOUT_S, b"")
        self._selector.register(sock, selectors.EVENT_READ)

    def _read(self, sock: socket.socket) -> None:
        deadline, got = self._open[sock]
        try:
            if isinstance(sock, ssl.SSLSocket) and got == b"":
                sock.do_handshake()  # done already: returns at once
            chunk = sock.recv(MAX_REQUEST_BYTES + 1 - len(got))
        except (BlockingIOError, InterruptedError, ssl.SSLWantReadError):
            return
        except ssl.SSLWantWriteError:  # a handshake message that did not fit: the deadline ends it
            return
        except OSError:
            chunk = b""
        if not chunk:
            self._close(sock)
            return
        got += chunk
        end = got.find(b"\r\n\r\n")
        if end < 0:
            if len(got) <= MAX_REQUEST_BYTES:
                self._open[sock] = (deadline, got)
            else:  # too long for a check: closed unanswered
                self._close(sock)
            return
        try:  # a reply this small fits an empty socket buffer: one send, never a partial one to finish
            sock.send(self.answer(got[:end]))
        except OSError:
            pass
        self._close(sock)

    def _close(self, sock: socket.socket) -> None:
        self._selector.unregister(sock)
        del self._open[sock]
        sock.close()
