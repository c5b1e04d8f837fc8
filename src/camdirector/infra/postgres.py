"""One PostgreSQL connection for the records that several nodes share (job records,
jobs/records.py; keys, session owners and the audit, access/keys.py; the level index,
precompute/tracks/registry.py): opened lazily and again after PostgreSQL dropped it, one
statement at a time behind a lock, `?` placeholders as SQLite's (so both record stores write
their SQL once), and an unreachable database raised as the caller's own error with a one-line
reason and the URL's secrets hidden (infra/redaction.py). `PostgresStore` is what those three
stores' PostgreSQL side shares: the tables created once when it opens, each write one transaction
under its write lock.
psycopg is imported only when used: a single node on SQLite never loads it."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator, Sequence
from typing import Any

from camdirector.infra.redaction import redacted

CONNECT_TIMEOUT_S = 5  # seconds to wait for PostgreSQL to answer a connection before calling it down


class QmarkConnection:
    """A psycopg connection that speaks `?` placeholders (no statement of ours has a literal `?`)."""

    def __init__(self, conn: Any) -> None:
        self._conn = conn

    def execute(self, sql: str, args: Sequence[Any] = ()) -> Any:
        return self._conn.execute(sql.replace("?", "%s"), tuple(args))


class PostgresDatabase:
    """The database at `url`; `what` names it in messages ("job store"), `unavailable` is the
    exception type raised when it cannot be reached."""

    def __init__(self, url: str, what: str, unavailable: type[Exception]) -> None:
        self.url = url
        self._what = what
        self._unavailable = unavailable
        self._lock = threading.Lock()
        self._conn: Any = None  # a psycopg.Connection once connected

    def _connection(self) -> Any:
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
    def transaction(self, lock_sql: str, lock_args: Sequence[Any] = ()) -> Iterator[QmarkConnection]:
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
