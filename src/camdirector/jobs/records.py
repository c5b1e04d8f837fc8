"""Job records: one interface (`JobStore`), two implementations checked by one test suite
(tests/jobs/test_records.py runs every test on both).

    SqliteJobStore     `<root>/jobs.sqlite3` (WAL journal): the embedded single-node default
    PostgresJobStore   a `jobs` table in PostgreSQL (psycopg 3): records that several nodes share

Both keep the job's files in `<root>/<id>/` (the data directory every node mounts, package
docstring) and run every call as one short transaction that holds the store's write lock
(SQLite's `BEGIN IMMEDIATE`; in PostgreSQL a transaction-scoped advisory lock), so a submit's
queue-length check and insert, and a finish's compare-and-set and result rename, are atomic on
every node alike. The SQL is written once, with `?` placeholders; the PostgreSQL connection
rewrites them to psycopg's `%s` (none of the statements has a literal `?`).

Attempts: `claim_next` (the local runner) and `claim` (a queue worker, by id) start an attempt by
adding one to `attempts`; `finish` and `requeue` take the attempt they belong to and change
nothing when the job has moved on since (cancelled, or claimed again by a worker that took over a
redelivered job). That compare-and-set is what makes a job succeed once even when two workers ran
it: only the latest attempt's outcome is recorded, and its result folder is renamed into place
inside that same transaction.

Claims (queue workers): a claim writes who holds the job (`claimed_by`, a token of that one
delivery of its message) and a lease (`lease_s`, Unix s) that the running worker renews
(`renew`). A message for a job that another worker holds with a fresh lease is a duplicate (the
broker took that worker for dead while Redis was unreachable, or a message sent twice):
`JobHeldElsewhere`, and the message is tried again later, so the job is not run twice; a stale
lease means the holder died, and the claim counts a new attempt. A claim whose reply was lost
is found again by its own token, and a job handed back by a stopping worker that could not
requeue its record (the store down) is taken over by the token its message carries: neither
counts an attempt.

Tenants: every job belongs to the tenant of the key that submitted it (access/roles.py; `default`
without keys). `list` filters by tenant, and the REST routes answer another tenant's job as an
unknown one. A submit can be held to the tenant's share in the same transaction as the node-wide
queue check (TenantLimitReached): jobs queued or running, and bytes of inputs its jobs keep (the
`input_bytes` column; inputs stay until the job is purged).

Idempotency: a submit may carry the client's key for it (HTTP `Idempotency-Key`); a second submit
of the tenant with that key and the same request (kind, parameters, files: `request_sha256`)
answers the first one's job (`Job.replayed`) and creates nothing, so a client that sends again a
submit whose answer it lost (a cut connection, a node lost mid-request) does not run the job
twice; with another request it raises IdempotencyConflict. A unique index holds it across nodes.

Columns added after the first release (`_ADDED_COLUMNS`) are added to a table that lacks them
when a store opens it, so a data directory or database from before keeps its jobs (as tenant
`default`, their inputs counted as 0 bytes).
"""

from __future__ import annotations

import builtins
import contextlib
import dataclasses
import hashlib
import json
import os
import shutil
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

from camdirector.infra.postgres import PostgresStore, advisory_lock
from camdirector.infra.redaction import redacted
from camdirector.infra.sqlite import SqliteStore
from camdirector.infra.tenants import DEFAULT_TENANT


class JobState(str, Enum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def finished(self) -> bool:
        return self in (JobState.SUCCEEDED, JobState.FAILED, JobState.CANCELLED)


class QueueFull(Exception):
    """The queue holds `max_queued_jobs` jobs already (HTTP 429)."""


class TenantLimitReached(Exception):
    """The submitting tenant holds its share of jobs or of stored inputs already (HTTP 429);
    the message says which and what to do."""


class JobNotFound(KeyError):
    """No job with this id."""


class IdempotencyConflict(Exception):
    """A submit's Idempotency-Key names an earlier submit of the tenant with another request
    (HTTP 422); the message says so."""


class JobHeldElsewhere(RuntimeError):
    """A claim of a job that another queue worker runs, its lease fresh: the message is a
    duplicate, to be tried again later (once the job ended it is dropped; once the lease ran out,
    the holder having died, it runs the job)."""


class JobsUnavailable(RuntimeError):
    """The record store (PostgreSQL) or the queue (Redis) cannot be reached: a node refuses to
    start, a submit answers HTTP 503. The message is one line that says which and why."""


@dataclass(frozen=True)
class Job:
    """One record. Times are Unix seconds (None until reached); timings_ms: per stage."""

    id: str
    kind: str
    params: dict
    state: JobState
    progress: float
    error: str | None
    attempts: int
    created_s: float
    started_s: float | None
    finished_s: float | None
    timings_ms: dict[str, float] = field(default_factory=dict)
    tenant: str = DEFAULT_TENANT
    claimed_by: str | None = None  # the claim token of the queue worker's delivery that runs it
    replayed: bool = False  # this answer is an earlier submit's, found by its Idempotency-Key (not stored)

    def as_public(self) -> dict:
        """The REST view: id, status, progress, error (only when set), timings (ms), and the
        Unix times it was submitted, started and ended (null until then)."""
        out = {
            "id": self.id,
            "status": self.state.value,
            "progress": round(self.progress, 4),
            "timings": self.timings_ms,
            "created_unix_s": self.created_s,
            "started_unix_s": self.started_s,
            "finished_unix_s": self.finished_s,
        }
        if self.error is not None:
            out["error"] = self.error
        return out


_COLUMNS = "id, kind, params, state, progress, error, attempts, created_s, started_s, finished_s, timings, tenant, claimed_by"
# Columns added since the first release: (name, SQL type and default, with {int} and {real}
# SQLite's INTEGER and REAL or PostgreSQL's BIGINT and DOUBLE PRECISION); each store adds those its
# table lacks (module docstring).
_ADDED_COLUMNS = (
    ("tenant", "TEXT NOT NULL DEFAULT 'default'"),
    ("input_bytes", "{int} NOT NULL DEFAULT 0"),  # bytes of the job's input files
    ("claimed_by", "TEXT"),  # the claim token of the running attempt (queue workers; NULL otherwise)
    ("lease_s", "{real}"),  # Unix s when its holder last showed it was alive
    ("idempotency_key", "TEXT"),  # the client's key for its submit (module docstring, "Idempotency")
    ("request_sha256", "TEXT"),  # request_digest() of that submit
)
_UNFINISHED = (JobState.QUEUED.value, JobState.RUNNING.value)


def _row_to_job(row) -> Job:
    return Job(
        id=row[0],
        kind=row[1],
        params=json.loads(row[2]),
        state=JobState(row[3]),
        progress=float(row[4]),
        error=row[5],
        attempts=int(row[6]),
        created_s=row[7],
        started_s=row[8],
        finished_s=row[9],
        timings_ms=json.loads(row[10]),
        tenant=row[11],
        claimed_by=row[12],
    )


def request_digest(kind: str, params: dict, files: dict[str, bytes]) -> str:
    """SHA-256 (hex) of what a submit asks: its kind, parameters and files (names and contents)."""
    digest = hashlib.sha256(json.dumps([kind, params], sort_keys=True).encode())
    for name in sorted(files):
        digest.update(b"\0%s\0%d\0" % (name.encode(), len(files[name])))
        digest.update(files[name])
    return digest.hexdigest()


def interrupted_error(attempts: int, max_attempts: int) -> str:
    """The error of a job that was interrupted (its runner or worker died) too often."""
    return f"interrupted: the process running this job died, {attempts} time(s) (limit {max_attempts}); not retried"


class JobStore:
    """Records of jobs and their files in `<root>/<id>/`. Thread-safe. Subclasses give the
    connection through their first base, infra's SqliteStore or PostgresStore: `_tx()` (one
    transaction holding the write lock, yielding something with `execute(sql, args) -> cursor`)
    and `_read()` (the same for one read)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    # -- the connection (subclasses) ---------------------------------------------------------

    _NEXT_SEQ: str  # SQL giving a new job's place in submission order

    def _tx(self) -> contextlib.AbstractContextManager:
        raise NotImplementedError

    def _read(self) -> contextlib.AbstractContextManager:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    # -- paths --------------------------------------------------------------------------------

    def job_dir(self, job_id: str) -> Path:
        if not job_id or not all(c.isalnum() or c == "-" for c in job_id):
            raise JobNotFound(job_id)
        return self.root / job_id

    def input_dir(self, job_id: str) -> Path:
        return self.job_dir(job_id) / "input"

    def result_dir(self, job_id: str) -> Path:
        return self.job_dir(job_id) / "result"

    def temp_dir(self) -> Path:
        """A fresh empty `.tmp-*` folder on the store's file system (renames are atomic)."""
        path = self.root / f".tmp-{uuid.uuid4().hex}"
        path.mkdir()
        return path

    # -- records ------------------------------------------------------------------------------

    def submit(
        self,
        kind: str,
        params: dict,
        files: dict[str, bytes],
        *,
        max_queued: int | None = None,
        tenant: str = DEFAULT_TENANT,
        tenant_max_queued_jobs: int | None = None,
        tenant_max_upload_bytes: int | None = None,
        idempotency_key: str | None = None,
    ) -> Job:
        """A new queued job of `tenant` with `files` (name -> content) in its input folder, as
        created (state queued, whatever a runner did since); with an `idempotency_key` the tenant
        used before for the same request, that job as it is now, `replayed` (module docstring).
        Raises QueueFull when `max_queued` jobs are queued already (all tenants), and
        TenantLimitReached when the tenant has `tenant_max_queued_jobs` jobs queued or running,
        or its jobs' inputs and these would pass `tenant_max_upload_bytes` (None: no such limit);
        IdempotencyConflict for a key used before for another request. Nothing is left behind on
        any failure."""
        job_id = uuid.uuid4().hex
        digest = request_digest(kind, params, files) if idempotency_key is not None else None
        params_text = json.dumps(params, sort_keys=True)
        input_bytes = sum(len(data) for data in files.values())
        tmp = self.temp_dir()
        try:
            (tmp / "input").mkdir()
            for name, data in files.items():
                if "/" in name or name.startswith("."):
                    raise ValueError(f"bad input file name {name!r}")
                (tmp / "input" / name).write_bytes(data)
            with self._tx() as db:
                earlier = self._earlier(db, tenant, idempotency_key, digest)
                if earlier is not None:
                    return earlier
                if max_queued is not None:
                    (queued,) = db.execute("SELECT COUNT(*) FROM jobs WHERE state = ?", (JobState.QUEUED.value,)).fetchone()
                    if queued >= max_queued:
                        raise QueueFull(f"{queued} jobs are queued already (limit {max_queued}); retry later")
                self._check_tenant_share(db, tenant, input_bytes, tenant_max_queued_jobs, tenant_max_upload_bytes)
                os.rename(tmp, self.root / job_id)
                try:
                    db.execute(
                        f"INSERT INTO jobs ({_COLUMNS}, input_bytes, idempotency_key, request_sha256, seq) "
                        f"VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,{self._NEXT_SEQ})",
                        (
                            job_id,
                            kind,
                            params_text,
                            JobState.QUEUED.value,
                            0.0,
                            None,
                            0,
                            time.time(),
                            None,
                            None,
                            "{}",
                            tenant,
                            None,  # claimed_by
                            input_bytes,
                            idempotency_key,
                            digest,
                        ),
                    )
                    # read in the same transaction: the job as created, before a runner claims it
                    created = _row_to_job(db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE id = ?", (job_id,)).fetchone())
                except BaseException:
                    shutil.rmtree(self.root / job_id, ignore_errors=True)
                    raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return created

    def earlier_submit(self, tenant: str, idempotency_key: str, kind: str, params: dict, files: dict[str, bytes]) -> Job | None:
        """The job of `tenant`'s earlier submit with `idempotency_key`, `replayed`, when it asked
        the same; None when the key is new. Raises IdempotencyConflict when it asked otherwise.
        For a route that must answer a replay before checks of its own (a level's name)."""
        with self._read() as db:
            return self._earlier(db, tenant, idempotency_key, request_digest(kind, params, files))

    @staticmethod
    def _earlier(db, tenant: str, idempotency_key: str | None, digest: str | None) -> Job | None:
        if idempotency_key is None:
            return None
        row = db.execute(
            f"SELECT {_COLUMNS}, request_sha256 FROM jobs WHERE tenant = ? AND idempotency_key = ?", (tenant, idempotency_key)
        ).fetchone()
        if row is None:
            return None
        if row[-1] != digest:
            raise IdempotencyConflict(
                f"Idempotency-Key {idempotency_key!r} was sent before with another request (job {row[0]}); "
                "use a new key for a new request"
            )
        return dataclasses.replace(_row_to_job(row[:-1]), replayed=True)

    @staticmethod
    def _check_tenant_share(db, tenant: str, input_bytes: int, max_jobs: int | None, max_bytes: int | None) -> None:
        """TenantLimitReached when a new job of `input_bytes` would take `tenant` past its share
        (submit's transaction, so two nodes' submits cannot both take the last place)."""
        if max_jobs is not None:
            (jobs,) = db.execute(
                "SELECT COUNT(*) FROM jobs WHERE tenant = ? AND state IN (?, ?)", (tenant, *_UNFINISHED)
            ).fetchone()
            if jobs >= max_jobs:
                raise TenantLimitReached(
                    f"tenant {tenant!r} has {jobs} jobs queued or running, its limit; retry when one has finished"
                )
        if max_bytes is not None:
            (held,) = db.execute("SELECT COALESCE(SUM(input_bytes), 0) FROM jobs WHERE tenant = ?", (tenant,)).fetchone()
            if int(held) + input_bytes > max_bytes:
                raise TenantLimitReached(
                    f"tenant {tenant!r}'s jobs keep {int(held)} bytes of uploads; {input_bytes} more would "
                    f"pass its limit of {max_bytes} bytes (a finished job's files are removed when its "
                    "retention ends)"
                )

    def get(self, job_id: str) -> Job:
        with self._read() as db:
            row = db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is None:
            raise JobNotFound(job_id)
        return _row_to_job(row)

    def list(
        self,
        state: JobState | None = None,
        *,
        kind: str | None = None,
        tenant: str | None = None,
        limit: int | None = None,
        newest_first: bool = False,
    ) -> list[Job]:
        """Jobs in submission order (newest first when asked), all or those in `state`, of
        `kind` and of `tenant`, at most `limit` of them."""
        where = [
            (c, v) for c, v in (("state", state.value if state else None), ("kind", kind), ("tenant", tenant)) if v is not None
        ]
        sql = f"SELECT {_COLUMNS} FROM jobs"
        if where:
            sql += " WHERE " + " AND ".join(f"{c} = ?" for c, _ in where)
        sql += " ORDER BY seq" + (" DESC" if newest_first else "")
        args: builtins.list[str | int] = [v for _, v in where]
        if limit is not None:
            sql += " LIMIT ?"
            args.append(int(limit))
        with self._read() as db:
            rows = db.execute(sql, args).fetchall()
        return [_row_to_job(r) for r in rows]

    def count(self, state: JobState) -> int:
        with self._read() as db:
            return int(db.execute("SELECT COUNT(*) FROM jobs WHERE state = ?", (state.value,)).fetchone()[0])

    def _start_attempt(self, db, job_id: str, token: str | None = None, *, counted: bool = True) -> None:
        now = time.time()
        db.execute(
            "UPDATE jobs SET state = ?, attempts = attempts + ?, started_s = ?, progress = 0, error = NULL, "
            "claimed_by = ?, lease_s = ? WHERE id = ?",
            (JobState.RUNNING.value, 1 if counted else 0, now, token, now if token else None, job_id),
        )

    def claim_next(self) -> Job | None:
        """The oldest queued job, now `running` with one more attempt; None when none is queued."""
        with self._tx() as db:
            row = db.execute("SELECT id FROM jobs WHERE state = ? ORDER BY seq LIMIT 1", (JobState.QUEUED.value,)).fetchone()
            if row is None:
                return None
            self._start_attempt(db, row[0])
        return self.get(row[0])

    def claim(
        self, job_id: str, max_attempts: int, *, token: str, lease_timeout_s: float, handed_back_from: str | None = None
    ) -> Job | None:
        """A queue worker's claim of the job its message names, as the delivery `token` (module
        docstring, "Claims"). A queued job becomes `running` with one more attempt; so does a
        running one whose holder's lease is older than `lease_timeout_s` (it died), or it fails
        once started `max_attempts` times. A running job held under `token` already (a claim
        whose reply was lost) is returned as it is; one held under `handed_back_from` (its
        stopping worker's token, carried by the message it sent back) is taken over without
        counting. Raises JobHeldElsewhere when another holder's lease is fresh. None when there
        is nothing to run (finished, cancelled, failed here, or removed)."""
        with self._tx() as db:
            row = db.execute("SELECT state, attempts, claimed_by, lease_s FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None or JobState(row[0]).finished:
                return None
            state, attempts, holder, lease_s = row
            if state == JobState.RUNNING.value and holder != token:
                if handed_back_from is not None and holder == handed_back_from:
                    self._start_attempt(db, job_id, token, counted=False)
                elif holder is not None and lease_s is not None and (age_s := time.time() - lease_s) < lease_timeout_s:
                    raise JobHeldElsewhere(f"job {job_id} runs on another worker (its lease renewed {age_s:.1f} s ago)")
                elif attempts >= max_attempts:
                    db.execute(
                        "UPDATE jobs SET state = ?, error = ?, finished_s = ? WHERE id = ?",
                        (JobState.FAILED.value, interrupted_error(attempts, max_attempts), time.time(), job_id),
                    )
                    return None
                else:
                    self._start_attempt(db, job_id, token)
            elif state == JobState.QUEUED.value:
                self._start_attempt(db, job_id, token)
        return self.get(job_id)

    def renew(self, job_id: str, token: str) -> bool:
        """The lease of the attempt claimed as `token`, renewed now. False when the job is no
        longer running under that token (cancelled, finished, taken over)."""
        with self._tx() as db:
            return (
                db.execute(
                    "UPDATE jobs SET lease_s = ? WHERE id = ? AND state = ? AND claimed_by = ?",
                    (time.time(), job_id, JobState.RUNNING.value, token),
                ).rowcount
                > 0
            )

    def set_progress(self, job_id: str, progress: float, *, attempt: int | None = None) -> None:
        sql = "UPDATE jobs SET progress = ? WHERE id = ? AND state = ?"
        args = [min(max(float(progress), 0.0), 1.0), job_id, JobState.RUNNING.value]
        if attempt is not None:
            sql += " AND attempts = ?"
            args.append(attempt)
        with self._tx() as db:
            db.execute(sql, args)

    def finish(
        self,
        job_id: str,
        state: JobState,
        *,
        error: str | None = None,
        timings_ms: dict[str, float] | None = None,
        only_if: JobState | None = None,
        attempt: int | None = None,
        publish: Callable[[], None] | None = None,
        forget_key: bool = False,
    ) -> bool:
        """Set a final state (and progress 1 on success). only_if: change nothing unless the job
        is in that state now; attempt: nor unless this is its latest attempt. publish: called
        inside the transaction once the record changed (the runner renames the result folder
        into place there; if it raises, nothing changes). forget_key: the job's Idempotency-Key
        is freed (a submit refused after its record was made: the client's retry makes a new
        job). Returns whether the record changed."""
        assert state.finished
        sql = (
            "UPDATE jobs SET state = ?, error = ?, finished_s = ?, timings = ?, "
            "progress = CASE WHEN ? THEN 1.0 ELSE progress END WHERE id = ?"
        )
        args = [state.value, error, time.time(), json.dumps(timings_ms or {}), state is JobState.SUCCEEDED, job_id]
        if timings_ms is None:
            sql = sql.replace("timings = ?, ", "")
            del args[3]
        if forget_key:
            sql = sql.replace("SET state = ?, ", "SET state = ?, idempotency_key = NULL, ")
        for column, value in (("state", only_if.value if only_if else None), ("attempts", attempt)):
            if value is not None:
                sql += f" AND {column} = ?"
                args.append(value)
        with self._tx() as db:
            changed = db.execute(sql, args).rowcount > 0
            if changed and publish is not None:
                publish()
        return changed

    def cancel(self, job_id: str) -> Job:
        """A queued or running job becomes cancelled (whoever runs it ends its process). A
        finished job is returned unchanged. Raises JobNotFound."""
        job = self.get(job_id)
        if not job.state.finished:
            self.finish(job_id, JobState.CANCELLED, error="cancelled by request", only_if=job.state)
        return self.get(job_id)

    def purge_finished(self, ended_before_s: float) -> builtins.list[str]:  # builtins: list is a method here
        """Remove the jobs that ended (succeeded, failed or were cancelled) before this Unix time,
        records first, then their folders. Returns their ids."""
        finished = [s.value for s in JobState if s.finished]
        with self._tx() as db:
            ids = [
                r[0]
                for r in db.execute(
                    f"SELECT id FROM jobs WHERE state IN ({','.join('?' * len(finished))}) AND finished_s < ?",
                    (*finished, ended_before_s),
                ).fetchall()
            ]
            for job_id in ids:
                db.execute("DELETE FROM jobs WHERE id = ?", (job_id,))
        for job_id in ids:
            shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
        return ids

    def requeue(self, job_id: str, *, uncount_attempt: bool, attempt: int | None = None) -> None:
        """A running job (of this attempt, when given) goes back to `queued`."""
        sql = (
            "UPDATE jobs SET state = ?, progress = 0, started_s = NULL, attempts = attempts - ?, claimed_by = NULL, "
            "lease_s = NULL WHERE id = ? AND state = ?"
        )
        args = [JobState.QUEUED.value, 1 if uncount_attempt else 0, job_id, JobState.RUNNING.value]
        if attempt is not None:
            sql += " AND attempts = ?"
            args.append(attempt)
        with self._tx() as db:
            db.execute(sql, args)

    def recover(self, max_attempts: int) -> tuple[builtins.list[str], builtins.list[str]]:
        """After a restart of the one local runner: jobs found `running` are queued again, or
        failed once they were started `max_attempts` times. Removes orphaned files. Returns
        (requeued, failed) ids."""
        requeued, failed = [], []
        for job in self.list(JobState.RUNNING):
            if job.attempts >= max_attempts:
                self.finish(
                    job.id, JobState.FAILED, only_if=JobState.RUNNING, error=interrupted_error(job.attempts, max_attempts)
                )
                failed.append(job.id)
            else:
                self.requeue(job.id, uncount_attempt=False)
                requeued.append(job.id)
        self.remove_orphans(older_than_s=0.0)
        return requeued, failed

    def remove_orphans(self, older_than_s: float) -> builtins.list[str]:
        """Remove `.tmp-*` folders and folders without a record, untouched for `older_than_s`
        (0 when no one else writes here: the local runner's start; queue workers wait longer
        than a job may run, as other nodes submit and run jobs meanwhile). Returns their names."""
        known = {j.id for j in self.list()}
        cutoff = time.time() - older_than_s
        removed = []
        for path in self.root.iterdir():
            if path.is_dir() and (path.name.startswith(".tmp-") or path.name not in known):
                with contextlib.suppress(FileNotFoundError):
                    if older_than_s > 0 and path.stat().st_mtime > cutoff:
                        continue
                shutil.rmtree(path, ignore_errors=True)
                removed.append(path.name)
        return removed


# -- SQLite -------------------------------------------------------------------------------------

_SQLITE_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    params TEXT NOT NULL,
    state TEXT NOT NULL,
    progress REAL NOT NULL DEFAULT 0,
    error TEXT,
    attempts INTEGER NOT NULL DEFAULT 0,
    created_s REAL NOT NULL,
    started_s REAL,
    finished_s REAL,
    timings TEXT NOT NULL DEFAULT '{}',
    seq INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS jobs_state_seq ON jobs (state, seq);
"""
_TENANT_INDEX = "CREATE INDEX IF NOT EXISTS jobs_tenant_state ON jobs (tenant, state)"  # after the migration
_IDEMPOTENCY_INDEX = (  # after the migration; one key per tenant, on every node
    "CREATE UNIQUE INDEX IF NOT EXISTS jobs_idempotency ON jobs (tenant, idempotency_key) WHERE idempotency_key IS NOT NULL"
)


class SqliteJobStore(SqliteStore, JobStore):
    """Records in `<root>/jobs.sqlite3` through infra/sqlite.py's SqliteStore: one connection
    behind a lock, every call one short transaction (writes as BEGIN IMMEDIATE)."""

    DB_NAME = "jobs.sqlite3"
    _NEXT_SEQ = "(SELECT COALESCE(MAX(seq), 0) + 1 FROM jobs)"

    def __init__(self, root: str | Path) -> None:
        JobStore.__init__(self, root)
        SqliteStore.__init__(self, self.root / self.DB_NAME, _SQLITE_SCHEMA)
        with self._tx() as db:
            present = {row[1] for row in db.execute("PRAGMA table_info(jobs)")}
            for name, sql_type in _ADDED_COLUMNS:
                if name not in present:
                    db.execute(f"ALTER TABLE jobs ADD COLUMN {name} {sql_type.format(int='INTEGER', real='REAL')}")
            db.execute(_TENANT_INDEX)
            db.execute(_IDEMPOTENCY_INDEX)


# -- PostgreSQL ---------------------------------------------------------------------------------

_POSTGRES_SCHEMA = (
    """CREATE TABLE IF NOT EXISTS jobs (
        id TEXT PRIMARY KEY,
        kind TEXT NOT NULL,
        params TEXT NOT NULL,
        state TEXT NOT NULL,
        progress DOUBLE PRECISION NOT NULL DEFAULT 0,
        error TEXT,
        attempts INTEGER NOT NULL DEFAULT 0,
        created_s DOUBLE PRECISION NOT NULL,
        started_s DOUBLE PRECISION,
        finished_s DOUBLE PRECISION,
        timings TEXT NOT NULL DEFAULT '{}',
        seq BIGSERIAL NOT NULL
    )""",
    "CREATE INDEX IF NOT EXISTS jobs_state_seq ON jobs (state, seq)",
    *(
        f"ALTER TABLE jobs ADD COLUMN IF NOT EXISTS {name} {sql_type.format(int='BIGINT', real='DOUBLE PRECISION')}"
        for name, sql_type in _ADDED_COLUMNS
    ),
    _TENANT_INDEX,
    _IDEMPOTENCY_INDEX,
)
# Key of the transaction-scoped advisory lock that serializes writes, as BEGIN IMMEDIATE does in
# SQLite (any constant that no other user of the database takes; these are "camd" in ASCII).
_WRITE_LOCK_KEY = 0x63616D64


class PostgresJobStore(PostgresStore, JobStore):
    """Records in the `jobs` table of the PostgreSQL database at `url` (created when missing),
    through infra/postgres.py's PostgresStore; files in `root` as for SQLite. Raises
    JobsUnavailable when the database cannot be reached."""

    _NEXT_SEQ = "DEFAULT"

    def __init__(self, url: str, root: str | Path) -> None:
        JobStore.__init__(self, root)
        PostgresStore.__init__(
            self, url, "job store", JobsUnavailable, _POSTGRES_SCHEMA, write_lock=advisory_lock(_WRITE_LOCK_KEY)
        )


def open_store(url: str, root: str | Path) -> JobStore:
    """The record store that `url` names: "" is SQLite in `root`, postgresql://... PostgreSQL.
    Files are in `root` either way."""
    if not url:
        return SqliteJobStore(root)
    if url.startswith(("postgresql://", "postgres://")):
        return PostgresJobStore(url, root)
    raise ValueError(f"job store {redacted(url)!r}: expected empty (SQLite) or a postgresql:// URL")
