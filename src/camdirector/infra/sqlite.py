"""One SQLite connection for a node's own records (job records, jobs/records.py; keys, session
owners and the audit, access/keys.py): WAL journal, one statement at a time behind a lock, each
write one `BEGIN IMMEDIATE` transaction, so a check and the write it guards are atomic across the
node's processes. The SQLite twin of postgres.PostgresDatabase, and `SqliteStore` the twin of
postgres.PostgresStore."""

from __future__ import annotations

import contextlib
import os
import sqlite3
import threading
from collections.abc import Iterator
from pathlib import Path


def create_private(path: str | Path) -> None:
    """Creates the database file at `path` 0600 when missing, before SQLite opens it: SQLite gives
    the -wal and -shm files it creates the main file's mode, whatever the umask, and the WAL holds
    what is written in clear (a key's hash, the cookie secret). An empty file is an empty database
    to SQLite."""
    os.close(os.open(path, os.O_RDWR | os.O_CREAT, 0o600))


class SqliteDatabase:
    def __init__(self, path: str | Path, schema: str) -> None:
        self._lock = threading.Lock()
        create_private(path)
        self._db = sqlite3.connect(path, timeout=30.0, isolation_level=None, check_same_thread=False)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.executescript(schema)

    @contextlib.contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

    @contextlib.contextmanager
    def read(self) -> Iterator[sqlite3.Connection]:
        with self._lock:
            yield self._db

    def close(self) -> None:
        with self._lock:
            self._db.close()


class SqliteStore:
    """The SQLite side of a store of records (jobs/records.py's SqliteJobStore, access/keys.py's
    SqliteAccessStore): the database at `path`, `schema` run when it opens; every write (`_tx()`)
    one BEGIN IMMEDIATE transaction, a read (`_read()`) one statement's turn at the connection.
    Named first among a store's bases, as postgres.PostgresStore."""

    def __init__(self, path: str | Path, schema: str) -> None:
        self._db = SqliteDatabase(path, schema)

    def _tx(self) -> contextlib.AbstractContextManager[sqlite3.Connection]:
        return self._db.transaction()

    def _read(self) -> contextlib.AbstractContextManager[sqlite3.Connection]:
        return self._db.read()

    def close(self) -> None:
        self._db.close()
