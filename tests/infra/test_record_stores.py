"""The base of the stores of records (infra/postgres.py's PostgresStore, infra/sqlite.py's
SqliteStore): the tables made when a store opens, each write one transaction under the store's
lock, the caller's own error when PostgreSQL cannot be reached. jobs/records.py, access/keys.py and
precompute/tracks/registry.py build their stores on them (their own tests run on both backends)."""

from __future__ import annotations

import socket
import threading

import pytest

from camdirector.infra.postgres import PostgresStore, advisory_lock
from camdirector.infra.sqlite import SqliteStore

SCHEMA = ["CREATE TABLE IF NOT EXISTS counts (name TEXT PRIMARY KEY, n INTEGER NOT NULL)"]


class Down(RuntimeError):
    pass


class Counts:
    """A toy store: counters, each increment a read and a write in one transaction."""

    def increment(self, name: str) -> None:
        with self._tx() as db:
            row = db.execute("SELECT n FROM counts WHERE name = ?", (name,)).fetchone()
            if row is None:
                db.execute("INSERT INTO counts (name, n) VALUES (?, ?)", (name, 1))
            else:
                db.execute("UPDATE counts SET n = ? WHERE name = ?", (row[0] + 1, name))

    def count(self, name: str) -> int:
        with self._read() as db:
            row = db.execute("SELECT n FROM counts WHERE name = ?", (name,)).fetchone()
        return row[0] if row is not None else 0


class PostgresCounts(PostgresStore, Counts):
    def __init__(self, url: str) -> None:
        super().__init__(url, "toy store", Down, SCHEMA, write_lock=advisory_lock(0x746F79))


class SqliteCounts(SqliteStore, Counts):
    def __init__(self, path) -> None:
        super().__init__(path, ";".join(SCHEMA))


@pytest.fixture
def two_stores(tmp_path, records_url):
    """Two stores of one database, as two nodes (or two processes of one) open it."""
    stores = [PostgresCounts(records_url) if records_url else SqliteCounts(tmp_path / "counts.sqlite3") for _ in range(2)]
    yield stores
    for store in stores:
        store.close()


def test_writes_under_the_lock_do_not_lose_an_increment(two_stores):
    """Both stores make the table (once), and 4 x 25 increments through them all count: each
    read-and-write holds the write lock."""
    stores = two_stores

    def work(store):
        for _ in range(25):
            store.increment("frames")

    threads = [threading.Thread(target=work, args=(stores[i % 2],)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert stores[0].count("frames") == stores[1].count("frames") == 100


def test_an_unreachable_database_is_the_stores_own_error_with_the_password_hidden():
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    with pytest.raises(Down, match=r"toy store postgresql://cam:\*\*\*@127\.0\.0\.1:\d+/x is unreachable: ") as caught:
        PostgresCounts(f"postgresql://cam:secret@127.0.0.1:{port}/x")
    assert "secret" not in str(caught.value)


def test_the_advisory_lock_is_sql_of_an_integer_key():
    assert advisory_lock(0x63616D64) == "SELECT pg_advisory_xact_lock(1667329380)"
