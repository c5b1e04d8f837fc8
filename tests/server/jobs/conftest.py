"""Fixtures of the job tests: the record store on both backends (SQLite and PostgreSQL, a fresh
database per test: tests/conftest.py's postgres_url; every store test runs on each)."""
from __future__ import annotations

from pathlib import Path

import pytest

from camdirector.server.jobs import PostgresJobStore, SqliteJobStore


@pytest.fixture(params=["sqlite", "postgres"])
def backend(request) -> str:
    """The record store's backend: "" (SQLite) or a fresh PostgreSQL database's URL."""
    return "" if request.param == "sqlite" else request.getfixturevalue("postgres_url")


@pytest.fixture
def make_store(tmp_path, backend):
    """Opens stores on `backend` over one folder (as nodes do), closed after the test."""
    opened = []

    def make(root: Path = tmp_path / "jobs"):
        store = PostgresJobStore(backend, root) if backend else SqliteJobStore(root)
        opened.append(store)
        return store

    yield make
    for store in opened:
        store.close()


@pytest.fixture
def store(make_store):
    return make_store()
