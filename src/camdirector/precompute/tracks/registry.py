"""Level registry that survives restarts: an index of the levels (one row each) plus one artifact
file per level in `<data_dir>/levels/`.

The index is one interface (`LevelIndex`) with two implementations, checked by one test suite
(tests/precompute/tracks/test_registry.py runs every test on both):

    SqliteLevelIndex     `<data_dir>/levels/index.sqlite3` (WAL journal): the embedded single-node default
    PostgresLevelIndex   a `levels` table in PostgreSQL (psycopg 3): the index several nodes share,
                         in the same database as their job records (`--job-store postgresql://...`)

The artifacts stay files in `<data_dir>/levels/` either way (the data directory every node of a
cluster mounts; they are megabytes each); the index names them relative to that folder.

Safe for servers reading while a job or the CLI writes: readers never block on the writer (SQLite
in WAL mode; PostgreSQL's MVCC), artifacts are written to a temporary file and renamed into place
(artifact.save_artifact), each version gets a new file name so a reader holding the old row still
finds its file until it has loaded it (old files are removed after the index points at the new
one; a reader that raced the removal retries from the index). A write is one transaction that
holds the index's write lock (SQLite's `BEGIN IMMEDIATE`; PostgreSQL's `LOCK TABLE levels IN SHARE
ROW EXCLUSIVE MODE`, which readers do not wait on), so the old file a replace removes is the one
the row named. Adding a name that is taken without `replace` is refused by the index's primary
key, in the database, so two nodes adding one name at once give one level and one LevelExists.
Names are 1-64 letters, digits, '.', '_' or '-', starting with a letter or digit.

Tenants (infra/tenants.py): each tenant has its own namespace, so two tenants can each have an
"arena". Tenant `default` keeps plain names, `<name>` in the index and `<name>.<hex>.npz` in the
levels folder, exactly as before tenants: existing data directories and `camdirector level add
NAME FILE` are unchanged. Another tenant's level is `<tenant>/<name>` in the index and its
artifacts lie in `<tenant>/` under the levels folder. The separator '/' can be in neither a level
name nor a tenant, so a qualified name reads back one way and no name of one tenant is another's;
a name is checked before it is qualified, so "acme/arena" asked for by tenant `default` is no
level at all. This keeps one table with its one primary key (a name per tenant is unique by the
same constraint, with no migration of an existing index), where a tenant column would have
meant rebuilding the SQLite table to widen its primary key.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import sqlite3
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from camdirector.infra.postgres import PostgresStore, advisory_lock, is_unique_violation
from camdirector.infra.redaction import redacted
from camdirector.infra.sqlite import create_private
from camdirector.infra.tenants import DEFAULT_TENANT, check_tenant
from camdirector.precompute.tracks.artifact import FORMAT_VERSION, LevelArtifact, load_artifact, save_artifact
from camdirector.precompute.tracks.level_mesh import load_level_mesh
from camdirector.precompute.tracks.pipeline import precompute_level
from camdirector.precompute.tracks.track_settings import TrackSettings

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
_TENANT_SEPARATOR = "/"  # in neither a level name nor a tenant (module docstring)
_COLUMNS = (
    "name, artifact_file, format_version, source_path, navmesh_path, m_per_unit, agent_height_m, "
    "agent_radius_m, created_unix_s, counts_json, timings_json"
)
# {real}: SQLite's REAL is 8 bytes, PostgreSQL's is 4 (DOUBLE PRECISION there).
_SCHEMA = """CREATE TABLE IF NOT EXISTS levels (
    name TEXT PRIMARY KEY, artifact_file TEXT NOT NULL, format_version INTEGER NOT NULL,
    source_path TEXT NOT NULL, navmesh_path TEXT, m_per_unit {real} NOT NULL, agent_height_m {real} NOT NULL,
    agent_radius_m {real} NOT NULL, created_unix_s {real} NOT NULL, counts_json TEXT NOT NULL, timings_json TEXT NOT NULL)"""
_INSERT = f"INSERT INTO levels ({_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)"


def check_level_name(name: str) -> None:
    """Raises ValueError unless name is 1-64 letters, digits, '.', '_' or '-', starting with a letter or digit."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(f"level name {name!r}: use 1-64 letters, digits, '.', '_' or '-', starting with a letter or digit")


def qualified_name(name: str, tenant: str) -> str:
    """The index's name of `tenant`'s level `name` (module docstring); ValueError for a bad name or tenant."""
    check_level_name(name)
    check_tenant(tenant)
    return name if tenant == DEFAULT_TENANT else f"{tenant}{_TENANT_SEPARATOR}{name}"


def _split_qualified(qualified: str) -> tuple[str, str]:
    """(tenant, name) of an index name."""
    tenant, _, name = qualified.rpartition(_TENANT_SEPARATOR)
    return tenant or DEFAULT_TENANT, name


def default_data_dir() -> Path:
    """$XDG_DATA_HOME/camdirector, else ~/.local/share/camdirector (the server's default too)."""
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local", "share")
    return Path(base) / "camdirector"


class LevelExists(Exception):
    """add_level without replace found the name taken (by another node or process meanwhile)."""


class LevelsUnavailable(RuntimeError):
    """The index's database (PostgreSQL) cannot be reached; the message is one line that says why."""


@dataclass(frozen=True)
class LevelRecord:
    """One registry row; artifact_path is absolute; name is the tenant's (unqualified)."""

    name: str
    tenant: str
    artifact_path: Path
    format_version: int
    source_path: str
    navmesh_path: str | None
    m_per_unit: float
    agent_height_m: float
    agent_radius_m: float
    created_unix_s: float
    counts: dict
    timings_ms: dict


# -- the index: one interface, two implementations -------------------------------------------------


class LevelIndex:
    """The rows of the registry (tuples in _COLUMNS' order; artifact_file relative to the levels
    folder). Thread-safe. Subclasses give `_tx()` (one transaction holding the write lock, yielding
    something with `execute(sql, args) -> cursor`), `_read()` (the same for one read),
    `_is_duplicate(exc)` and `close()`."""

    def _tx(self) -> contextlib.AbstractContextManager:
        raise NotImplementedError

    def _read(self) -> contextlib.AbstractContextManager:
        raise NotImplementedError

    def _is_duplicate(self, exc: Exception) -> bool:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def get(self, name: str) -> tuple | None:
        with self._read() as db:
            return db.execute(f"SELECT {_COLUMNS} FROM levels WHERE name = ?", (name,)).fetchone()

    def list(self) -> list[tuple]:
        with self._read() as db:
            return db.execute(f"SELECT {_COLUMNS} FROM levels ORDER BY name").fetchall()

    def put(self, row: tuple, *, replace: bool) -> str | None:
        """Write `row`; returns the artifact file of the row it replaced (None if none). Without
        replace a taken name raises LevelExists: the primary key refuses the insert."""
        try:
            with self._tx() as db:
                if not replace:
                    db.execute(_INSERT, row)
                    return None
                old = db.execute("SELECT artifact_file FROM levels WHERE name = ?", (row[0],)).fetchone()
                if old is not None:
                    db.execute("DELETE FROM levels WHERE name = ?", (row[0],))
                db.execute(_INSERT, row)
                return old[0] if old is not None else None
        except Exception as exc:
            if self._is_duplicate(exc):
                raise LevelExists(f"level {_split_qualified(row[0])[1]!r} exists") from None
            raise

    def delete(self, name: str) -> str | None:
        """Remove a row; returns its artifact file, None when there was none."""
        with self._tx() as db:
            row = db.execute("SELECT artifact_file FROM levels WHERE name = ?", (name,)).fetchone()
            if row is not None:
                db.execute("DELETE FROM levels WHERE name = ?", (name,))
        return row[0] if row is not None else None


class SqliteLevelIndex(LevelIndex):
    """Rows in `<levels_dir>/index.sqlite3`: a connection per call (safe across threads and
    processes), writes as BEGIN IMMEDIATE."""

    DB_NAME = "index.sqlite3"

    def __init__(self, levels_dir: Path) -> None:
        self._db_path = Path(levels_dir) / self.DB_NAME
        create_private(self._db_path)
        with contextlib.closing(self._connect()) as db:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute(_SCHEMA.format(real="REAL"))

    def _connect(self) -> sqlite3.Connection:
        db = sqlite3.connect(self._db_path, timeout=30.0, isolation_level=None)
        db.execute("PRAGMA busy_timeout=30000")
        return db

    @contextlib.contextmanager
    def _tx(self) -> Iterator[sqlite3.Connection]:
        with contextlib.closing(self._connect()) as db:
            db.execute("BEGIN IMMEDIATE")
            try:
                yield db
            except BaseException:
                db.execute("ROLLBACK")
                raise
            db.execute("COMMIT")

    @contextlib.contextmanager
    def _read(self) -> Iterator[sqlite3.Connection]:
        with contextlib.closing(self._connect()) as db:
            yield db

    def _is_duplicate(self, exc: Exception) -> bool:
        return isinstance(exc, sqlite3.IntegrityError)

    def close(self) -> None:
        pass


# Key of the advisory lock under which nodes starting together create the table once ("camL").
_SCHEMA_LOCK_KEY = 0x63616D4C


class PostgresLevelIndex(PostgresStore, LevelIndex):
    """Rows in the `levels` table of the PostgreSQL database at `url` (created when missing),
    through infra/postgres.py's PostgresStore; a write locks the table (readers do not wait on
    it), so the table is created under an advisory lock of its own. Raises LevelsUnavailable
    when the database cannot be reached."""

    def __init__(self, url: str) -> None:
        PostgresStore.__init__(
            self,
            url,
            "level index",
            LevelsUnavailable,
            [_SCHEMA.format(real="DOUBLE PRECISION")],
            write_lock="LOCK TABLE levels IN SHARE ROW EXCLUSIVE MODE",
            schema_lock=advisory_lock(_SCHEMA_LOCK_KEY),
        )

    def _is_duplicate(self, exc: Exception) -> bool:
        return is_unique_violation(exc)


def open_level_index(records_url: str, levels_dir: Path) -> LevelIndex:
    """The index `records_url` names: "" is SQLite in `levels_dir`, postgresql://... PostgreSQL."""
    if not records_url:
        return SqliteLevelIndex(levels_dir)
    if records_url.startswith(("postgresql://", "postgres://")):
        return PostgresLevelIndex(records_url)
    raise ValueError(f"level index {redacted(records_url)!r}: expected empty (SQLite) or a postgresql:// URL")


# -- the registry -----------------------------------------------------------------------------------


class LevelRegistry:
    """The registry in data_dir (created if missing). records_url: where its index lives, "" for
    SQLite in data_dir (the default), or the postgresql:// URL of the records database the nodes
    of a cluster share (their `--job-store`). Raises LevelsUnavailable when PostgreSQL is down."""

    def __init__(self, data_dir: Path | str | None = None, records_url: str = ""):
        self.data_dir = Path(data_dir) if data_dir is not None else default_data_dir()
        self.levels_dir = self.data_dir / "levels"
        self.levels_dir.mkdir(parents=True, exist_ok=True)
        self.records_url = records_url
        self.index = open_level_index(records_url, self.levels_dir)

    def close(self) -> None:
        self.index.close()

    def __enter__(self) -> LevelRegistry:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _record(self, row) -> LevelRecord:
        tenant, name = _split_qualified(row[0])
        return LevelRecord(
            name=name,
            tenant=tenant,
            artifact_path=self.levels_dir / row[1],
            format_version=row[2],
            source_path=row[3],
            navmesh_path=row[4],
            m_per_unit=row[5],
            agent_height_m=row[6],
            agent_radius_m=row[7],
            created_unix_s=row[8],
            counts=json.loads(row[9]),
            timings_ms=json.loads(row[10]),
        )

    def add_level(
        self,
        name: str,
        level_path: Path,
        navmesh_path: Path | None = None,
        *,
        scale: float = 1.0,
        agent_height_m: float = 2.0,
        agent_radius_m: float = 0.6,
        progress: Callable[[float], None] | None = None,
        seed: int = 0,
        replace: bool = True,
        tenant: str = DEFAULT_TENANT,
    ) -> LevelRecord:
        """Precompute a level file (OBJ/GLB in units of `scale` metres, or a Quake BSP, already in
        metres, times `scale`) and index it under name in `tenant`'s namespace, replacing a level
        of that name (unless `replace` is false: then LevelExists when the name is taken by the
        time the precompute is done; nothing is left behind). Raises ValueError (MeshError) on a bad name, tenant or file."""
        qualified = qualified_name(name, tenant)
        settings = TrackSettings(agent_height_m=agent_height_m, agent_radius_m=agent_radius_m)
        mesh = load_level_mesh(Path(level_path), scale)
        navmesh = load_level_mesh(Path(navmesh_path), scale) if navmesh_path is not None else None
        artifact = precompute_level(
            mesh, settings, np.random.default_rng(seed), navmesh=navmesh, m_per_unit=scale, progress=progress
        )
        file_name = f"{qualified}.{secrets.token_hex(6)}.npz"  # in the tenant's folder unless `default`
        (self.levels_dir / file_name).parent.mkdir(exist_ok=True)
        save_artifact(artifact, self.levels_dir / file_name)
        row = (
            qualified,
            file_name,
            FORMAT_VERSION,
            str(Path(level_path).resolve()),
            str(Path(navmesh_path).resolve()) if navmesh_path is not None else None,
            scale,
            agent_height_m,
            agent_radius_m,
            time.time(),
            json.dumps(artifact.counts),
            json.dumps(artifact.timings_ms),
        )
        try:
            old = self.index.put(row, replace=replace)
        except BaseException:
            (self.levels_dir / file_name).unlink(missing_ok=True)  # never a file no row points at
            raise
        if old is not None and old != file_name:
            (self.levels_dir / old).unlink(missing_ok=True)
        record = self.get(name, tenant)  # as the index holds it (SQLite's REAL makes an int scale a float)
        return record if record is not None else self._record(row)  # None: another writer deleted it since

    def get(self, name: str, tenant: str = DEFAULT_TENANT) -> LevelRecord | None:
        """`tenant`'s level `name`; None when it has none (a malformed name or tenant included)."""
        try:
            qualified = qualified_name(name, tenant)
        except ValueError:
            return None
        row = self.index.get(qualified)
        return self._record(row) if row else None

    def list(self, tenant: str = DEFAULT_TENANT) -> list[LevelRecord]:
        """`tenant`'s levels, by name."""
        return [record for record in map(self._record, self.index.list()) if record.tenant == tenant]

    def load(self, name: str, tenant: str = DEFAULT_TENANT) -> LevelArtifact:
        """The level's artifact; KeyError when unknown, ArtifactVersionError when of another format."""
        for _ in range(3):
            record = self.get(name, tenant)
            if record is None:
                raise KeyError(f"no level named {name!r}")
            try:
                return load_artifact(record.artifact_path)
            except ValueError:
                if record.artifact_path.exists():
                    raise
        raise KeyError(f"level {name!r} keeps changing under the reader")

    def delete(self, name: str, tenant: str = DEFAULT_TENANT) -> bool:
        """Remove `tenant`'s level `name`; False when there was none."""
        try:
            qualified = qualified_name(name, tenant)
        except ValueError:
            return False
        file_name = self.index.delete(qualified)
        if file_name is None:
            return False
        (self.levels_dir / file_name).unlink(missing_ok=True)
        return True
