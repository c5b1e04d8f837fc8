"""infra/postgres.py's bounds against a hung PostgreSQL (issue 40): the server stopped by SIGSTOP
still has its kernel accept connections and acknowledge what is sent, so a call without a
deadline of its own waits for an answer forever. Every call here must come back with the
caller's error; the bound checked is far above the deadline (no timing is asserted)."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from camdirector.deploy.services import PostgresServer, descendants
from camdirector.infra.postgres import HUNG_RETRY_S, PostgresDatabase, advisory_lock
from tests.conftest import service_or_skip
from tests.infra.test_host_address import ScriptedLookup

RETURNS_WITHIN_S = 20.0  # a call that has not come back by then hangs (the deadline is 2 s)


class Down(RuntimeError):
    pass


@contextmanager
def stopped(postgres: PostgresServer) -> Iterator[None]:
    """PostgreSQL's postmaster and every backend stopped (SIGSTOP) for the block, then resumed."""
    postmaster = int((postgres.data / "postmaster.pid").read_text().split()[0])
    pids = [postmaster, *descendants([postmaster])]
    try:
        for pid in pids:
            os.kill(pid, signal.SIGSTOP)
        yield
    finally:
        for pid in pids:
            os.kill(pid, signal.SIGCONT)


def outcome(call: Callable[[], object]) -> BaseException | object:
    """What `call` returned or raised, run in a thread; pytest.fail when it has not come back within
    RETURNS_WITHIN_S (the thread, a daemon, is left behind)."""
    done: list = []

    def run() -> None:
        try:
            done.append(call())
        except BaseException as exc:
            done.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(RETURNS_WITHIN_S)
    if not done:
        pytest.fail(f"the call has not come back within {RETURNS_WITHIN_S:g} s")
    return done[0]


@pytest.fixture
def postgres(tmp_path) -> Iterator[PostgresServer]:
    server = service_or_skip(lambda: PostgresServer(Path(tmp_path) / "postgres").start())
    try:
        yield server
    finally:
        server.stop()


def read_one(db: PostgresDatabase) -> int:
    with db.read() as conn:
        return conn.execute("SELECT 1").fetchone()[0]


def write_one(db: PostgresDatabase) -> int:
    with db.transaction(advisory_lock(0x74657374)) as conn:
        return conn.execute("SELECT 2").fetchone()[0]


def test_a_call_to_a_stopped_server_comes_back_unavailable_and_the_next_after_it_resumes_works(postgres):
    """Connected before the stop: the read waits on an open connection; a write queued behind it
    comes back too; a database opened during the stop waits on its connect. All come back as Down,
    with the database named, and all work once PostgreSQL runs again."""
    connected = PostgresDatabase(postgres.url, "test records", Down)
    fresh = PostgresDatabase(postgres.url, "test records", Down)
    assert read_one(connected) == 1
    try:
        with stopped(postgres):
            queued: list = []
            behind = threading.Thread(target=lambda: queued.append(outcome(lambda: write_one(connected))), daemon=True)
            behind.start()
            first = outcome(lambda: read_one(connected))
            behind.join(RETURNS_WITHIN_S)
            connecting = outcome(lambda: read_one(fresh))
        for answer in (first, *queued, connecting):
            assert isinstance(answer, Down), answer
            assert "test records postgresql://camdirector@127.0.0.1" in str(answer) and "is unreachable" in str(answer)
        assert len(queued) == 1
        time.sleep(HUNG_RETRY_S)  # calls fail at once this long after a hang, then try again
        for db in (connected, fresh):
            assert outcome(lambda db=db: read_one(db)) == 1
            assert outcome(lambda db=db: write_one(db)) == 2
    finally:
        connected.close()
        fresh.close()


def test_connections_go_to_the_address_found_and_a_stalled_lookup_delays_none(postgres):
    """The URL names the server by a name only the test's lookup knows: connecting again after the
    server dropped the connection waits on no lookup (one is under way, and stalls); before any
    lookup answered, a call comes back Down naming the host."""
    url = postgres.url.replace("127.0.0.1", "records.test")
    lookup = ScriptedLookup()
    db = PostgresDatabase(url, "test records", Down, deadline_s=0.1, lookup=lookup)
    try:
        answer = outcome(lambda: read_one(db))
        assert isinstance(answer, Down) and "no address of records.test is known" in str(answer)
        lookup.give(["127.0.0.1"])
        assert read_one(db) == 1
        other = PostgresDatabase(postgres.url, "test records", Down)
        with other.read() as conn:  # the first one's connection ended, as a restarted server ends it
            conn.execute(
                "SELECT pg_terminate_backend(pid) FROM pg_stat_activity"
                " WHERE pid <> pg_backend_pid() AND datname = current_database()"
            )
        other.close()
        db.address.refresh()
        deadline = time.monotonic() + RETURNS_WITHIN_S
        while lookup.calls < 2:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        first = outcome(lambda: read_one(db))  # may meet the dropped connection: Down, and it is closed
        assert first == 1 or isinstance(first, Down), first
        assert read_one(db) == 1  # connected again while the lookup stalls
    finally:
        lookup.give(["127.0.0.1"])
        db.close()
