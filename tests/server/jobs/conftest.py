"""Fixtures of the job tests: a fresh PostgreSQL database per test, and the record store on both
backends (SQLite and PostgreSQL: every store test runs on each)."""
from __future__ import annotations

import uuid
from pathlib import Path

import pytest

from camdirector.server.jobs import PostgresJobStore, SqliteJobStore


@pytest.fixture
def postgres_url(postgres_server) -> str:
    """A new empty database on the shared PostgreSQL cluster, dropped after the test."""
    import psycopg

    name = f"jobs_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres_server.url, autocommit=True) as admin:
        admin.execute(f"CREATE DATABASE {name}")
    yield postgres_server.url.rsplit("/", 1)[0] + "/" + name
    with psycopg.connect(postgres_server.url, autocommit=True) as admin:
        admin.execute(f"DROP DATABASE {name} WITH (FORCE)")


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
