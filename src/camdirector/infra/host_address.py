"""A service's host name looked up off its callers' path: new connections go to the addresses last
found, and a lookup runs on a thread of its own when a connection fails (the service may have
moved: a restarted container's new address).

Why: a name lookup cannot be bounded or cancelled (glibc's getaddrinfo waits its resolver's 5 s
per try, per name server), and in a container network lookups do stall. In the compose cluster
(docker/compose.cluster.yaml under podman) a node's lookups of `redis` took 5, 10 and 20 s while
other nodes' took 1 ms (podman's aardvark-dns drops queries around a container joining or leaving
the network: containers/aardvark-dns#389). A checkpoint writer that connected by name then sat in
one lookup for those seconds: every session created meanwhile had no checkpoint, and the node's
loss lost them (tests/deploy/test_compose_cluster.py, docs/scaling.md). With this, a lookup that
stalls delays nothing but itself.

`redis_pool` makes redis-py's connections use one (RedisStore, the job queue); PostgreSQL's use
libpq's `hostaddr` (infra/postgres.py).
"""

from __future__ import annotations

import functools
import logging
import socket
import threading
import time
from collections.abc import Callable
from typing import Any
from urllib.parse import urlsplit

log = logging.getLogger("camdirector.lookups")

Lookup = Callable[[str, int], list[str]]

SLOW_LOOKUP_S = 1.0  # a lookup that took longer is logged (the callers never waited for it), s


def lookup_stream_addresses(host: str, port: int) -> list[str]:
    """`host`'s addresses for a TCP connection to `port`, in the resolver's order (duplicates
    dropped). Raises OSError (socket.gaierror) when the name is not found."""
    found = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    return list(dict.fromkeys(str(info[4][0]) for info in found))


class HostAddress:
    """`host`'s addresses, looked up by `lookup` on a daemon thread, one lookup at a time.
    `current` is the address a new connection is to use; None until a lookup has answered. What an
    operator needs to know is logged: a lookup that fails (once, until one answers again), one
    slower than SLOW_LOOKUP_S, and an address that changed."""

    def __init__(
        self, host: str, port: int, lookup: Lookup = lookup_stream_addresses, clock: Callable[[], float] = time.monotonic
    ):
        self.host = host
        self.port = port
        self._lookup = lookup
        self._clock = clock
        self._lock = threading.Condition()  # notified when a lookup answers
        self._addresses: list[str] = []
        self._next = 0  # which of _addresses new connections use: the next one after a failure
        self._looking: threading.Thread | None = None
        self._answers = 0  # lookups answered so far
        self.last_error: OSError | None = None  # the last lookup's failure, None once one answers

    @property
    def current(self) -> str | None:
        with self._lock:
            return self._addresses[self._next] if self._addresses else None

    def refresh(self) -> None:
        """Starts a lookup unless one is running; its addresses replace those known (a failed one
        keeps them)."""
        with self._lock:
            if self._looking is not None:
                return
            self._looking = threading.Thread(target=self._look_up, name=f"lookup-{self.host}", daemon=True)
            self._looking.start()

    def failed(self) -> None:
        """A connection to `current` failed: the next address known is tried first from now on,
        and the name is looked up again."""
        with self._lock:
            if self._addresses:
                self._next = (self._next + 1) % len(self._addresses)
        self.refresh()

    def wait(self, timeout_s: float) -> str | None:
        """`current`, waiting up to `timeout_s` for a lookup to answer when no address is known yet
        (a lookup is started if none runs)."""
        with self._lock:
            if self._addresses:
                return self._addresses[self._next]
            answers = self._answers
        self.refresh()
        with self._lock:
            self._lock.wait_for(lambda: self._answers > answers, timeout_s)
            return self._addresses[self._next] if self._addresses else None

    def known(self, timeout_s: float) -> str:
        """`wait`'s address; OSError naming the host, and why, when no lookup has found one."""
        address = self.wait(timeout_s)
        if address is None:
            raise OSError(f"no address of {self.host} is known ({self.last_error or 'its lookup has not answered yet'})")
        return address

    def look_up_now(self) -> None:
        """Looks the name up on the caller's thread (a process starting, which may wait); raises
        OSError when the lookup fails."""
        self._answered(*self._ask())
        if self.last_error is not None:
            raise self.last_error

    def _look_up(self) -> None:
        addresses, error = self._ask()
        with self._lock:
            self._looking = None
        self._answered(addresses, error)

    def _ask(self) -> tuple[list[str], OSError | None]:
        started_s = self._clock()
        try:
            addresses = self._lookup(self.host, self.port)
            error = None if addresses else OSError(f"no address found for {self.host}")
        except OSError as exc:
            addresses, error = [], exc
        took_s = self._clock() - started_s
        if took_s > SLOW_LOOKUP_S:
            log.warning("looking up %s took %.1f s (no connection waited for it)", self.host, took_s)
        return addresses, error

    def _answered(self, addresses: list[str], error: OSError | None) -> None:
        with self._lock:
            failing_before, known_before = self.last_error is not None, list(self._addresses)
            self.last_error = error
            if addresses and set(addresses) != set(self._addresses):
                self._addresses, self._next = addresses, 0
            self._answers += 1
            self._lock.notify_all()
            current = self._addresses[self._next] if self._addresses else None
        if error is not None and not failing_before:
            kept = f"new connections still go to {current}" if current else "no connection can be made until one answers"
            log.warning("looking up %s failed (%s): %s", self.host, error, kept)
        elif error is None and failing_before:
            log.warning("looking up %s works again: %s", self.host, ", ".join(addresses))
        if known_before and addresses and set(addresses) != set(known_before):
            log.warning("%s moved: %s -> %s", self.host, ", ".join(known_before), ", ".join(addresses))


def redis_pool(url: str, lookup: Lookup = lookup_stream_addresses, **kwargs: Any) -> tuple[Any, HostAddress | None]:
    """A redis-py ConnectionPool for `url` (`kwargs` as ConnectionPool.from_url's) and its
    HostAddress, whose first lookup is started here: a `redis://` URL's connections go to the
    address it found. None, and connections made as redis-py makes them, for `rediss://` (TLS
    checks the name) and `unix://`."""
    import redis  # only a process given a Redis URL needs the client

    parts = urlsplit(url)
    if parts.scheme != "redis" or not parts.hostname:
        return redis.ConnectionPool.from_url(url, **kwargs), None
    address = HostAddress(parts.hostname, parts.port or 6379, lookup)
    address.refresh()
    return redis.ConnectionPool.from_url(url, connection_class=_pinned_connection_class(), address=address, **kwargs), address


@functools.cache
def _pinned_connection_class() -> type:
    """redis-py's TCP connection, connecting to the address its HostAddress last found rather than
    looking the host name up itself, and having the name looked up again when a connect fails;
    made when first used, so that only a process given a Redis URL imports the client."""
    import redis

    class PinnedConnection(redis.connection.Connection):
        def __init__(self, address: HostAddress, **kwargs: Any) -> None:
            self.address = address
            super().__init__(**kwargs)  # type: ignore[no-untyped-call]  # redis-py's own signature is untyped

        @property
        def host(self) -> str:  # what redis-py's connect looks up: an address literal, found already
            return self.address.current or self.address.host

        @host.setter
        def host(self, name: str) -> None:
            pass  # the name is the HostAddress's

        def _connect(self) -> Any:  # redis-py's TCP connect, reconnects included (since redis-py 3)
            try:
                return super()._connect()  # type: ignore[no-untyped-call]
            except OSError:
                self.address.failed()  # moved, maybe: a restarted container's new address
                raise

    return PinnedConnection
