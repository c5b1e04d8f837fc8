"""One PostgreSQL connection for the records that several nodes share (job records,
jobs/records.py; the level index, precompute/tracks/registry.py): opened lazily and again
after PostgreSQL dropped it, one statement at a time behind a lock, `?` placeholders as SQLite's
(so both record stores write their SQL once), and an unreachable database raised as the caller's
own error with a one-line reason and the password hidden. psycopg is imported only when used:
a single node on SQLite never loads it."""
from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

CONNECT_TIMEOUT_S = 5  # seconds to wait for PostgreSQL to answer a connection before calling it down


class QmarkConnection:
    """A psycopg connection that speaks `?` placeholders (no statement of ours has a literal `?`)."""

    def __init__(self, conn) -> None:
        self._conn = conn

    def execute(self, sql: str, args=()):
        return self._conn.execute(sql.replace("?", "%s"), tuple(args))


class PostgresDatabase:
    """The database at `url`; `what` names it in messages ("job store"), `unavailable` is the
    exception type raised when it cannot be reached."""

    def __init__(self, url: str, what: str, unavailable: type[Exception]) -> None:
        self.url = url
        self._what = what
        self._unavailable = unavailable
        self._lock = threading.Lock()
        self._conn = None

    def _connection(self):
        import psycopg

        if self._conn is None or self._conn.closed or self._conn.broken:
            self._conn = psycopg.connect(self.url, autocommit=True, connect_timeout=CONNECT_TIMEOUT_S)
        return self._conn

    @contextlib.contextmanager
    def _reachable(self) -> Iterator[None]:
        import psycopg

        try:
            yield
        except psycopg.OperationalError as exc:
            lines = [line for line in str(exc).splitlines() if line.strip()]
            reason = lines[-1].strip() if lines else type(exc).__name__
            raise self._unavailable(f"{self._what} {redacted(self.url)} is unreachable: {reason}") from None

    @contextlib.contextmanager
    def transaction(self, lock_sql: str, lock_args=()) -> Iterator[QmarkConnection]:
        """A transaction that first runs `lock_sql` (the caller's write lock: an advisory lock or
        a table lock, as BEGIN IMMEDIATE serializes SQLite's writers)."""
        with self._lock, self._reachable():
            conn = self._connection()
            with conn.transaction():
                conn.execute(lock_sql, tuple(lock_args))
                yield QmarkConnection(conn)

    @contextlib.contextmanager
    def read(self) -> Iterator[QmarkConnection]:
        with self._lock, self._reachable():
            yield QmarkConnection(self._connection())

    def close(self) -> None:
        with self._lock:
            if self._conn is not None:
                self._conn.close()


def is_unique_violation(exc: Exception) -> bool:
    """Whether `exc` is PostgreSQL refusing a row whose key is taken."""
    import psycopg

    return isinstance(exc, psycopg.errors.UniqueViolation)


def redacted(url: str) -> str:
    """The URL without its password, for messages."""
    scheme, sep, rest = url.partition("://")
    userinfo, at, host = rest.rpartition("@")
    if not at or ":" not in userinfo:
        return url
    return f"{scheme}{sep}{userinfo.split(':', 1)[0]}:***@{host}"
