"""Fixtures of the job tests: the record store on both backends (SQLite and PostgreSQL, a fresh
database per test: tests/conftest.py's records_url; every store test runs on each)."""

from __future__ import annotations

from pathlib import Path

import pytest

from camdirector.jobs import PostgresJobStore, SqliteJobStore


@pytest.fixture
def make_store(tmp_path, records_url):
    """Opens stores on `records_url` (tests/conftest.py) over one folder (as nodes do), closed after the test."""
    opened = []

    def make(root: Path = tmp_path / "jobs"):
        store = PostgresJobStore(records_url, root) if records_url else SqliteJobStore(root)
        opened.append(store)
        return store

    yield make
    for store in opened:
        store.close()


@pytest.fixture
def store(make_store):
    return make_store()
