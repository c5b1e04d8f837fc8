"""One PostgreSQL connection for the records that several nodes share (job records,
jobs/records.py; keys, session owners and the audit, access/keys.py; the level index,
precompute/tracks/registry.py): opened lazily and again after PostgreSQL dropped it, one
statement at a time behind a lock, `?` placeholders as SQLite's (so both record stores write
their SQL once), and an unreachable database raised as the caller's own error with a one-line
reason and the URL's secrets hidden (infra/redaction.py). `PostgresStore` is what those three
stores' PostgreSQL side shares: the tables created once when it opens, each write one transaction
under its write lock.

Every call is bounded, a down or hung database included (issue 40): the connect by
CONNECT_TIMEOUT_S, each statement by PostgreSQL's own statement_timeout, a silent peer by TCP
keepalives and tcp_user_timeout, and the whole call by `deadline_s`. A server stopped by SIGSTOP
still has its kernel accept and acknowledge, so only that last bound ends a call waiting for its
answer: a watchdog thread shuts down the connection's socket, psycopg returns at once with an
error, and the next call connects again. A call that found the database hung makes the calls of
the next HUNG_RETRY_S fail at once: those queued behind it do not each wait their deadline in turn.
A URL's one host name is looked up off the calls' path (infra/host_address.py says why: a lookup
cannot be bounded), and connections go to the address found (libpq's `hostaddr`; `host` still
names the server to TLS): a connect waits for the first lookup up to `deadline_s`, and a failed
one looks the name up again. psycopg is imported only when used: a single node on SQLite never
loads it."""

from __future__ import annotations

import contextlib
import itertools
import os
import socket
import threading
import time
from collections.abc import Iterator, Sequence
from typing import Any

from camdirector.infra.host_address import HostAddress, Lookup, lookup_stream_addresses
from camdirector.infra.redaction import redacted

RECORDS_DEADLINE_S = 2.0  # the longest one call waits for its turn at the connection, and again for its answers, s
CONNECT_TIMEOUT_S = 2  # libpq's connect_timeout, TCP and startup together: whole seconds, and libpq takes no less than 2
STATEMENT_TIMEOUT_MS = 1500  # PostgreSQL cancels a statement running longer, ms: under the deadline, so the connection stays
IDLE_IN_TRANSACTION_MS = 5000  # PostgreSQL ends a session idle this long inside a transaction (and frees its locks), ms
KEEPALIVE_IDLE_S = 5  # an idle connection's first TCP keepalive probe after this long, s
KEEPALIVE_INTERVAL_S = 2  # between unanswered probes, s
KEEPALIVE_COUNT = 3  # unanswered probes before the kernel drops the connection
TCP_USER_TIMEOUT_MS = 5000  # data sent and not acknowledged this long drops the connection (a host gone), ms
HUNG_RETRY_S = 1.0  # after a call found the database hung, calls fail at once this long before one tries again, s


class QmarkConnection:
    """A psycopg connection that speaks `?` placeholders (no statement of ours has a literal `?`)."""

    def __init__(self, conn: Any) -> None:
        self._conn = conn

    def execute(self, sql: str, args: Sequence[Any] = ()) -> Any:
        return self._conn.execute(sql.replace("?", "%s"), tuple(args))


def _conninfo(url: str, hostaddr: str | None = None) -> str:
    """`url` with the bounds of the module docstring added (options the URL gives are kept), and
    `hostaddr`, the address to connect to, when given."""
    from psycopg.conninfo import conninfo_to_dict, make_conninfo

    options = f"-c statement_timeout={STATEMENT_TIMEOUT_MS} -c idle_in_transaction_session_timeout={IDLE_IN_TRANSACTION_MS}"
    return make_conninfo(
        url,
        **({"hostaddr": hostaddr} if hostaddr is not None else {}),
        options=f"{conninfo_to_dict(url).get('options') or ''} {options}".strip(),
        connect_timeout=CONNECT_TIMEOUT_S,
        keepalives=1,
        keepalives_idle=KEEPALIVE_IDLE_S,
        keepalives_interval=KEEPALIVE_INTERVAL_S,
        keepalives_count=KEEPALIVE_COUNT,
        tcp_user_timeout=TCP_USER_TIMEOUT_MS,
    )


class _Watchdog:
    """One thread per process that shuts down the socket of a call past its deadline (the module
    docstring). The socket is shut down through a duplicate of its descriptor: the connection keeps
    its own, psycopg sees end of file and fails the call, and its owner closes it."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._due: dict[int, tuple[float, int]] = {}  # watch -> (deadline on the monotonic clock, s; socket's fd)
        self._fired: set[int] = set()
        self._ids = itertools.count()
        self._thread: threading.Thread | None = None

    def watch(self, fd: int, deadline_s: float) -> int:
        with self._cond:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="postgres-watchdog", daemon=True)
                self._thread.start()
            watch = next(self._ids)
            self._due[watch] = (time.monotonic() + deadline_s, fd)
            self._cond.notify()
            return watch

    def done(self, watch: int) -> bool:
        """Ends the watch; whether it fired (the socket was shut down)."""
        with self._cond:
            self._due.pop(watch, None)
            if watch in self._fired:
                self._fired.discard(watch)
                return True
            return False

    def _run(self) -> None:
        with self._cond:
            while True:
                now = time.monotonic()
                for watch, (due_s, fd) in list(self._due.items()):
                    if due_s <= now:  # the fd is the connection's until done(), which waits for this lock
                        del self._due[watch]
                        self._fired.add(watch)
                        with contextlib.suppress(OSError), socket.socket(fileno=os.dup(fd)) as sock:
                            sock.shutdown(socket.SHUT_RDWR)
                next_s = min((due_s for due_s, _ in self._due.values()), default=None)
                self._cond.wait(None if next_s is None else next_s - now)


_WATCHDOG = _Watchdog()


def _host_address(url: str, lookup: Lookup) -> HostAddress | None:
    """The URL's host name to look up off the calls' path (the module docstring); None where libpq
    is to connect as it would (a socket folder, several hosts, a `hostaddr` given, no host)."""
    from psycopg.conninfo import conninfo_to_dict

    parts = conninfo_to_dict(url)
    host, port = str(parts.get("host") or ""), str(parts.get("port") or "5432")
    if not host or host.startswith("/") or "," in host or "," in port or parts.get("hostaddr"):
        return None
    return HostAddress(host, int(port), lookup)


class PostgresDatabase:
    """The database at `url`; `what` names it in messages ("job store"), `unavailable` is the
    exception type raised when it cannot be reached or does not answer within `deadline_s`."""

    def __init__(
        self,
        url: str,
        what: str,
        unavailable: type[Exception],
        deadline_s: float = RECORDS_DEADLINE_S,
        lookup: Lookup = lookup_stream_addresses,
    ) -> None:
        """lookup: how the URL's host name is looked up (tests stall it)."""
        self.url = url
        self.address = _host_address(url, lookup)
        self.deadline_s = deadline_s
        self._what = what
        self._unavailable = unavailable
        self._lock = threading.Lock()
        self._conn: Any = None  # a psycopg.Connection once connected
        self._hung_until_s = 0.0  # on the monotonic clock: calls fail at once before this (HUNG_RETRY_S)

    def _down(self, reason: str) -> Exception:
        return self._unavailable(f"{self._what} {redacted(self.url)} is unreachable: {reason}")

    def _connection(self) -> Any:
        import psycopg

        if self._conn is None or self._conn.closed or self._conn.broken:
            hostaddr = None
            if self.address is not None:
                try:
                    hostaddr = self.address.known(self.deadline_s)
                except OSError as exc:
                    raise self._down(str(exc)) from None
            try:
                self._conn = psycopg.connect(_conninfo(self.url, hostaddr), autocommit=True)
            except psycopg.OperationalError:
                if self.address is not None:
                    self.address.failed()
                raise
        return self._conn

    @contextlib.contextmanager
    def _call(self) -> Iterator[Any]:
        """The connection for one call, within the bounds of the module docstring; psycopg's
        OperationalError (unreachable, timed out, cut by the watchdog) raised as `unavailable`."""
        import psycopg

        if not self._lock.acquire(timeout=self.deadline_s):
            raise self._down(f"an earlier call has had no answer for {self.deadline_s:g} s")
        try:
            if time.monotonic() < self._hung_until_s:
                raise self._down(f"it gave no answer within {self.deadline_s:g} s; tried again within {HUNG_RETRY_S:g} s")
            cut = False  # the watchdog shut the connection's socket down
            try:
                conn = self._connection()
                watch = _WATCHDOG.watch(conn.fileno(), self.deadline_s)
                try:
                    yield conn
                finally:
                    cut = _WATCHDOG.done(watch)
                    if cut:  # not to be used again, even when the call got its answer first
                        conn.close()
            except psycopg.OperationalError as exc:
                if cut or isinstance(exc, psycopg.errors.ConnectionTimeout):
                    self._hung_until_s = time.monotonic() + HUNG_RETRY_S
                lines = [line for line in str(exc).splitlines() if line.strip()]
                reason = lines[-1].strip() if lines else type(exc).__name__
                raise self._down(f"no answer within {self.deadline_s:g} s" if cut else reason) from None
        finally:
            self._lock.release()

    @contextlib.contextmanager
    def transaction(self, lock_sql: str, lock_args: Sequence[Any] = ()) -> Iterator[QmarkConnection]:
        """A transaction that first runs `lock_sql` (the caller's write lock: an advisory lock or
        a table lock, as BEGIN IMMEDIATE serializes SQLite's writers)."""
        with self._call() as conn, conn.transaction():
            conn.execute(lock_sql, tuple(lock_args))
            yield QmarkConnection(conn)

    @contextlib.contextmanager
    def read(self) -> Iterator[QmarkConnection]:
        with self._call() as conn:
            yield QmarkConnection(conn)

    def close(self) -> None:
        with self._lock:
            if self._conn is not None:
                self._conn.close()


class PostgresStore:
    """The PostgreSQL side of a store of records (jobs/records.py's PostgresJobStore,
    access/keys.py's PostgresAccessStore, precompute/tracks/registry.py's PostgresLevelIndex):
    the database at `url` (`what` and `unavailable` as PostgresDatabase's), its tables made by
    `schema` when the store opens, under `schema_lock` (by default the write lock) so that nodes
    starting together create them once; every write (`_tx()`) one transaction that first takes
    `write_lock`, as BEGIN IMMEDIATE serializes SQLite's writers; a read (`_read()`) takes none.
    Named first among a store's bases, so that these answer the store's `_tx`, `_read` and `close`."""

    def __init__(
        self,
        url: str,
        what: str,
        unavailable: type[Exception],
        schema: Sequence[str],
        *,
        write_lock: str,
        schema_lock: str | None = None,
    ) -> None:
        self.url = url
        self._db = PostgresDatabase(url, what, unavailable)
        self._write_lock = write_lock
        with self._db.transaction(write_lock if schema_lock is None else schema_lock) as db:
            for statement in schema:
                db.execute(statement)

    def _tx(self) -> contextlib.AbstractContextManager[QmarkConnection]:
        return self._db.transaction(self._write_lock)

    def _read(self) -> contextlib.AbstractContextManager[QmarkConnection]:
        return self._db.read()

    def close(self) -> None:
        self._db.close()


def advisory_lock(key: int) -> str:
    """SQL that takes the transaction-scoped advisory lock `key` (a constant that no other user of
    the database takes)."""
    return f"SELECT pg_advisory_xact_lock({int(key)})"


def is_unique_violation(exc: Exception) -> bool:
    """Whether `exc` is PostgreSQL refusing a row whose key is taken."""
    import psycopg

    return isinstance(exc, psycopg.errors.UniqueViolation)
