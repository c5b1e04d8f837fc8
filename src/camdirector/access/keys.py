"""API keys, the owners of sessions, and the audit trail: one interface (`AccessStore`), two
implementations (tests/access/test_keys.py runs every test on both).

    SqliteAccessStore     `<data_dir>/access.sqlite3` (WAL): the single node's records
    PostgresAccessStore   tables in the cluster's records database (the nodes' `--job-store`), so
                          every node knows every key, every session's tenant and one audit trail

A key reads `cdk_<id>_<secret>`: the id (12 hex digits) names the row, the secret (32 random bytes,
URL-safe base64) is stored only as its SHA-256. A salted slow hash (bcrypt, argon2) protects
passwords people choose; a 256-bit random secret cannot be guessed from its hash, and a fast one
keeps checking a streaming frame's key within its budget (docs/security.md).

Revocation sets `revoked_s`; `revoked_since(t)` is what each node's guard polls (access/guard.py),
with the dashboard's logins: the secret that signs them (`LOGIN_SECRET`, replaced by `camdirector
keys rotate-secret`) and the logins ended by logout (`ended_logins`, kept until their cookies would
have expired).
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import hmac
import json
import os
import secrets
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from camdirector.access.roles import ROLES
from camdirector.infra.postgres import PostgresStore, advisory_lock
from camdirector.infra.redaction import redacted
from camdirector.infra.sqlite import SqliteStore
from camdirector.infra.tenants import DEFAULT_TENANT, check_tenant

KEY_PREFIX = "cdk_"
ADMIN_KEY_FILE = "admin.key"
LOGIN_SECRET = "dashboard-cookie"  # the shared secret that signs the dashboard's login cookies


class AccessUnavailable(RuntimeError):
    """The records database holding the keys cannot be reached."""


class KeyNotFound(KeyError):
    pass


@dataclass(frozen=True)
class ApiKey:
    """One key's record (never its secret). Times are seconds since the epoch."""

    key_id: str
    name: str
    role: str
    tenant: str
    created_s: float
    revoked_s: float | None = None

    @property
    def revoked(self) -> bool:
        return self.revoked_s is not None

    def as_public(self) -> dict[str, Any]:
        return {
            "id": self.key_id,
            "name": self.name,
            "role": self.role,
            "tenant": self.tenant,
            "created_s": self.created_s,
            "revoked_s": self.revoked_s,
        }


_HEX_DIGITS = frozenset("0123456789abcdef")  # a key id's, secrets.token_hex's


def split_key(token: str) -> tuple[str, str] | None:
    """(id, secret) of a key's text, None when it is not shaped like one (an id of 12 hex digits:
    nothing else reaches the database, where PostgreSQL refuses some text, a NUL, with an error)."""
    if not token.startswith(KEY_PREFIX):
        return None
    key_id, sep, secret = token[len(KEY_PREFIX) :].partition("_")
    if not sep or len(key_id) != 12 or not _HEX_DIGITS.issuperset(key_id) or not secret or len(secret) > 128:
        return None
    return key_id, secret


def read_key_file(path: str) -> str:
    """The key in the file at `path` ("-": standard input), alone on its line: how a command takes a
    key without it showing in the process's arguments (`ps`, shell history). ValueError, never
    naming the key, when the file cannot be read or holds no key."""
    try:
        text = sys.stdin.read() if path == "-" else Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--key-file {path}: cannot read it ({exc.__class__.__name__})") from None
    token = text.strip()
    if split_key(token) is None:
        raise ValueError(f"--key-file {path}: it does not hold a key (cdk_<id>_<secret>, alone on one line)")
    return token


def secret_hash(secret: str) -> str:
    return hashlib.sha256(secret.encode()).hexdigest()


def secret_matches(secret: str, stored_hash: str) -> bool:
    return hmac.compare_digest(secret_hash(secret), stored_hash)


_COLUMNS = "id, name, role, tenant, created_s, revoked_s"

_SQLITE_SCHEMA = """
CREATE TABLE IF NOT EXISTS api_keys (
    id TEXT PRIMARY KEY, name TEXT NOT NULL, role TEXT NOT NULL, tenant TEXT NOT NULL,
    secret_sha256 TEXT NOT NULL, created_s REAL NOT NULL, revoked_s REAL
);
CREATE TABLE IF NOT EXISTS session_owners (
    session_id TEXT PRIMARY KEY, tenant TEXT NOT NULL, created_s REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS audit (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, at_s REAL NOT NULL, tenant TEXT NOT NULL, key_id TEXT,
    action TEXT NOT NULL, session_id TEXT, detail TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS audit_tenant_seq ON audit (tenant, seq);
CREATE TABLE IF NOT EXISTS access_secrets (name TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS ended_logins (login_id TEXT PRIMARY KEY, ended_s REAL NOT NULL, expires_s REAL NOT NULL);
"""

_POSTGRES_SCHEMA = (
    """CREATE TABLE IF NOT EXISTS api_keys (
        id TEXT PRIMARY KEY, name TEXT NOT NULL, role TEXT NOT NULL, tenant TEXT NOT NULL,
        secret_sha256 TEXT NOT NULL, created_s DOUBLE PRECISION NOT NULL, revoked_s DOUBLE PRECISION)""",
    """CREATE TABLE IF NOT EXISTS session_owners (
        session_id TEXT PRIMARY KEY, tenant TEXT NOT NULL, created_s DOUBLE PRECISION NOT NULL)""",
    """CREATE TABLE IF NOT EXISTS audit (
        seq BIGSERIAL PRIMARY KEY, at_s DOUBLE PRECISION NOT NULL, tenant TEXT NOT NULL, key_id TEXT,
        action TEXT NOT NULL, session_id TEXT, detail TEXT NOT NULL)""",
    "CREATE INDEX IF NOT EXISTS audit_tenant_seq ON audit (tenant, seq)",
    "CREATE TABLE IF NOT EXISTS access_secrets (name TEXT PRIMARY KEY, value TEXT NOT NULL)",
    """CREATE TABLE IF NOT EXISTS ended_logins (
        login_id TEXT PRIMARY KEY, ended_s DOUBLE PRECISION NOT NULL, expires_s DOUBLE PRECISION NOT NULL)""",
)
_WRITE_LOCK_KEY = 0x63616D6B  # "camk": the access tables' advisory write lock (records.py has "camd")


def _key(row: Sequence[Any]) -> ApiKey:
    return ApiKey(*row)


def _insert_key(db: Any, role: str, tenant: str, name: str) -> tuple[ApiKey, str]:
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; expected one of {', '.join(ROLES)}")
    check_tenant(tenant)
    if len(name) > 200:
        raise ValueError("a key's name is at most 200 characters")
    key_id, secret = secrets.token_hex(6), base64.urlsafe_b64encode(secrets.token_bytes(32)).decode().rstrip("=")
    record = ApiKey(key_id, name, role, tenant, time.time())
    db.execute(
        "INSERT INTO api_keys (id, name, role, tenant, secret_sha256, created_s) VALUES (?, ?, ?, ?, ?, ?)",
        (key_id, name, role, tenant, secret_hash(secret), record.created_s),
    )
    return record, f"{KEY_PREFIX}{key_id}_{secret}"


class AccessStore:
    """Keys, session owners, audit. Thread-safe; every call one short transaction. Subclasses
    give `_tx()`, `_read()` and `close()` through their first base, infra's SqliteStore or
    PostgresStore, as jobs/records.py's stores do."""

    where: str

    def _tx(self) -> contextlib.AbstractContextManager[Any]:
        raise NotImplementedError

    def _read(self) -> contextlib.AbstractContextManager[Any]:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    # -- keys
    def create_key(self, role: str, tenant: str = DEFAULT_TENANT, name: str = "") -> tuple[ApiKey, str]:
        """A new key: its record and its text (shown once, never stored)."""
        with self._tx() as db:
            return _insert_key(db, role, tenant, name)

    def create_first_admin(self) -> str | None:
        """An admin key of tenant `default` when no active admin key exists (its text), else None;
        one transaction, so nodes starting together make one."""
        with self._tx() as db:
            if db.execute("SELECT 1 FROM api_keys WHERE role = 'admin' AND revoked_s IS NULL LIMIT 1").fetchone():
                return None
            return _insert_key(db, "admin", DEFAULT_TENANT, "first admin (made at start)")[1]

    def lookup(self, key_id: str) -> tuple[ApiKey, str] | None:
        """The key's record and stored secret hash, None for an unknown id."""
        with self._read() as db:
            row = db.execute(f"SELECT {_COLUMNS}, secret_sha256 FROM api_keys WHERE id = ?", (key_id,)).fetchone()
        return (_key(row[:6]), row[6]) if row is not None else None

    def list_keys(self, tenant: str | None = None) -> list[ApiKey]:
        with self._read() as db:
            if tenant is None:
                rows = db.execute(f"SELECT {_COLUMNS} FROM api_keys ORDER BY created_s, id").fetchall()
            else:
                rows = db.execute(
                    f"SELECT {_COLUMNS} FROM api_keys WHERE tenant = ? ORDER BY created_s, id", (tenant,)
                ).fetchall()
        return [_key(r) for r in rows]

    def revoke(self, key_id: str, tenant: str | None = None) -> ApiKey:
        """Revokes the key (again is a no-op); KeyNotFound for an unknown id or, with `tenant`,
        another tenant's key."""
        with self._tx() as db:
            row = db.execute(f"SELECT {_COLUMNS} FROM api_keys WHERE id = ?", (key_id,)).fetchone()
            if row is None or (tenant is not None and row[3] != tenant):
                raise KeyNotFound(key_id)
            if row[5] is None:
                db.execute("UPDATE api_keys SET revoked_s = ? WHERE id = ?", (time.time(), key_id))
            row = db.execute(f"SELECT {_COLUMNS} FROM api_keys WHERE id = ?", (key_id,)).fetchone()
        return _key(row)

    def revoked_since(self, since_s: float) -> list[tuple[str, float]]:
        """(id, revoked_s) of keys revoked at or after `since_s`."""
        with self._read() as db:
            return [
                tuple(r) for r in db.execute("SELECT id, revoked_s FROM api_keys WHERE revoked_s >= ?", (since_s,)).fetchall()
            ]

    # -- session owners
    def set_session_owner(self, session_id: str, tenant: str) -> None:
        with self._tx() as db:
            db.execute("DELETE FROM session_owners WHERE session_id = ?", (session_id,))
            db.execute(
                "INSERT INTO session_owners (session_id, tenant, created_s) VALUES (?, ?, ?)", (session_id, tenant, time.time())
            )

    def session_owner(self, session_id: str) -> str | None:
        with self._read() as db:
            row = db.execute("SELECT tenant FROM session_owners WHERE session_id = ?", (session_id,)).fetchone()
        return row[0] if row is not None else None

    def forget_session(self, session_id: str) -> None:
        with self._tx() as db:
            db.execute("DELETE FROM session_owners WHERE session_id = ?", (session_id,))

    # -- audit
    def audit(
        self, tenant: str, key_id: str | None, action: str, session_id: str | None = None, detail: dict[str, Any] | None = None
    ) -> None:
        with self._tx() as db:
            db.execute(
                "INSERT INTO audit (at_s, tenant, key_id, action, session_id, detail) VALUES (?, ?, ?, ?, ?, ?)",
                (time.time(), tenant, key_id, action, session_id, json.dumps(detail or {}, sort_keys=True)),
            )

    def audit_trail(self, tenant: str, after_seq: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        with self._read() as db:
            rows = db.execute(
                "SELECT seq, at_s, key_id, action, session_id, detail FROM audit "
                "WHERE tenant = ? AND seq > ? ORDER BY seq LIMIT ?",
                (tenant, after_seq, limit),
            ).fetchall()
        return [
            {"seq": r[0], "at_s": r[1], "key_id": r[2], "action": r[3], "session_id": r[4], "detail": json.loads(r[5])}
            for r in rows
        ]

    # -- secrets the nodes share (LOGIN_SECRET), and the logins ended by logout
    def shared_secret(self, name: str) -> bytes:
        """The named random secret, made by the first node that asks. Read first, outside a write
        transaction: every node's guard reads it at each poll."""
        with self._read() as db:
            row = db.execute("SELECT value FROM access_secrets WHERE name = ?", (name,)).fetchone()
        if row is not None:
            return bytes.fromhex(row[0])
        with self._tx() as db:
            row = db.execute("SELECT value FROM access_secrets WHERE name = ?", (name,)).fetchone()
            if row is None:
                row = (secrets.token_hex(32),)
                db.execute("INSERT INTO access_secrets (name, value) VALUES (?, ?)", (name, row[0]))
        return bytes.fromhex(row[0])

    def rotate_secret(self, name: str) -> None:
        """Replaces the named secret with a new random one: what the old one signed is refused by
        every node from its next poll (access/guard.py)."""
        with self._tx() as db:
            db.execute("DELETE FROM access_secrets WHERE name = ?", (name,))
            db.execute("INSERT INTO access_secrets (name, value) VALUES (?, ?)", (name, secrets.token_hex(32)))

    def end_login(self, login_id: str, expires_s: float) -> None:
        """Records a login as ended until `expires_s`, when its cookie expires anyway; the records of
        logins past that go in the same transaction."""
        now = time.time()
        with self._tx() as db:
            db.execute("DELETE FROM ended_logins WHERE expires_s <= ? OR login_id = ?", (now, login_id))
            db.execute("INSERT INTO ended_logins (login_id, ended_s, expires_s) VALUES (?, ?, ?)", (login_id, now, expires_s))

    def ended_logins(self, since_s: float) -> list[tuple[str, float]]:
        """(login id, expires_s) of the logins ended at or after `since_s` whose cookies have not
        expired yet."""
        with self._read() as db:
            rows = db.execute(
                "SELECT login_id, expires_s FROM ended_logins WHERE ended_s >= ? AND expires_s > ?", (since_s, time.time())
            ).fetchall()
        return [(r[0], r[1]) for r in rows]


class SqliteAccessStore(SqliteStore, AccessStore):
    """The tables in `<data_dir>/access.sqlite3`, through infra/sqlite.py's SqliteStore."""

    DB_NAME = "access.sqlite3"

    def __init__(self, data_dir: str | Path) -> None:
        root = Path(data_dir)
        root.mkdir(parents=True, exist_ok=True)
        self.where = str(root / self.DB_NAME)
        SqliteStore.__init__(self, self.where, _SQLITE_SCHEMA)
        os.chmod(self.where, 0o600)  # key hashes and the cookie secret: the node's user only


class PostgresAccessStore(PostgresStore, AccessStore):
    """The tables in the PostgreSQL database at `url` (created when missing), through
    infra/postgres.py's PostgresStore. Raises AccessUnavailable when it cannot be reached."""

    def __init__(self, url: str) -> None:
        self.where = "PostgreSQL"
        PostgresStore.__init__(
            self, url, "records database (keys)", AccessUnavailable, _POSTGRES_SCHEMA, write_lock=advisory_lock(_WRITE_LOCK_KEY)
        )


def open_access_store(records_url: str, data_dir: str | Path) -> AccessStore:
    """The store `records_url` names (the nodes' `--job-store`): "" is SQLite in `data_dir`."""
    if not records_url:
        return SqliteAccessStore(data_dir)
    if records_url.startswith(("postgresql://", "postgres://")):
        return PostgresAccessStore(records_url)
    raise ValueError(f"records database {redacted(records_url)!r}: expected empty (SQLite) or a postgresql:// URL")


def ensure_admin_key(store: AccessStore, data_dir: str | Path) -> Path | None:
    """With no active admin key anywhere, makes one and writes it to DIR/admin.key (mode 0600);
    returns that path, None when an admin key existed already."""
    text = store.create_first_admin()
    if text is None:
        return None
    path = Path(data_dir) / ADMIN_KEY_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text + "\n")
    os.chmod(path, 0o600)  # an older file keeps its mode through O_TRUNC
    return path
