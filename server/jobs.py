"""Offline jobs: a SQLite job store, files per job, and a runner with bounded concurrency.

Layout under `<data_dir>/jobs/`:

    jobs.sqlite3            one row per job (WAL journal): kind, parameters (JSON), state,
                            progress 0..1, error, attempts, timestamps, timings (JSON)
    runner.lock             held (flock) by the one runner that owns this folder
    <id>/input/             the job's uploaded files, written before the row exists
    <id>/result/            what the job produced, renamed into place only when it succeeded
    .tmp-*/                 work in progress; anything left here after a crash is removed

Nothing is half-written: inputs are written into `.tmp-*` and renamed to `<id>/` before the row
is inserted (a failed insert removes them); a job writes its results into `.tmp-*` and the runner
renames that folder to `<id>/result/` only after the job function returned. On start, folders
without a row and leftover `.tmp-*` folders are removed.

States: queued -> running -> succeeded | failed | cancelled (queued -> cancelled too). A job runs in
its own process (multiprocessing "forkserver": forked from a small single-threaded server process,
never from the front process that runs gRPC and asyncio), so the front's event loop never runs a
job, and a cancelled or timed-out job is ended by terminating its process. The runner is one
thread in the front process that starts job processes, reads their progress from a pipe, and is
the only writer of running/succeeded/failed states.

Restart: a runner that starts finds queued jobs and runs them in submission order; jobs found
`running` (the previous front process died while they ran) are queued again and rerun, or failed
with a reason once they have been started `max_attempts` times. A runner stopped cleanly puts its
running jobs back in the queue without counting the attempt.

Retention: a finished job (its row, inputs and results) is removed `job_retention_s` after it
ended, checked at start and every minute, so a long-running server's data directory stays bounded.

Job kinds: `JobKind(name, function)` in a `JobRegistry` (more are added to a runner by
`JobRunner.add_kind` before it starts: one runner owns a folder); the function runs in the job
process as `function(params: dict, input_dir: Path, output_dir: Path, progress: Callable[[float], None])
-> dict[str, float]` (timings in milliseconds) and raises to fail the job (`JobError`'s message is
shown as is; other exceptions as "<Type>: message"). It must be a module-level function (it is
pickled by reference into the job process).
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import multiprocessing
import multiprocessing.connection
import os
import shutil
import sqlite3
import threading
import time
import traceback
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

from camdirector.precompute.jobs import JobError
from camdirector.precompute.process_lifetime import die_with_parent

log = logging.getLogger("camdirector.jobs")

JobFunction = Callable[[dict, Path, Path, Callable[[float], None]], dict]
_PURGE_INTERVAL_S = 60.0   # how often the runner looks for jobs past their retention


@dataclass(frozen=True)
class JobSettings:
    """Limits of the offline job runner (one per process; wired into ServerSettings)."""

    max_concurrent_jobs: int = 1           # job processes running at once. [1, 64]
    max_queued_jobs: int = 16              # jobs waiting to run; a submit beyond this is refused (HTTP 429). [0, 100000]
    max_upload_bytes: int = 64 * 1024 * 1024  # largest uploaded file of a job, bytes (HTTP 413 above). [1 KiB, 4 GiB]
    max_attempts: int = 2                  # times a job may be started; one found interrupted after that fails. [1, 100]
    job_timeout_s: float = 600.0           # a running job is ended and failed after this, s. [1, 86400]
    cancel_grace_s: float = 2.0            # SIGTERM to SIGKILL of a cancelled job's process, s. [0, 60]
    job_blas_threads: int = 1              # BLAS/OpenMP threads per job process (0: library default). [0, 64]
    job_retention_s: float = 7 * 86400.0   # a finished job's row and files go this long after it ended (0 keeps all), s. [0, 1e9]

    def __post_init__(self):
        checks = [
            (1 <= self.max_concurrent_jobs <= 64, "max_concurrent_jobs must be in [1, 64]"),
            (0 <= self.max_queued_jobs <= 100_000, "max_queued_jobs must be in [0, 100000]"),
            (1024 <= self.max_upload_bytes <= 4 << 30, "max_upload_bytes must be in [1 KiB, 4 GiB]"),
            (1 <= self.max_attempts <= 100, "max_attempts must be in [1, 100]"),
            (0.0 <= self.job_retention_s <= 1e9, "job_retention_s must be in [0, 1e9]"),
            (1.0 <= self.job_timeout_s <= 86_400.0, "job_timeout_s must be in [1, 86400]"),
            (0.0 <= self.cancel_grace_s <= 60.0, "cancel_grace_s must be in [0, 60]"),
            (0 <= self.job_blas_threads <= 64, "job_blas_threads must be in [0, 64]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)


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


class JobNotFound(KeyError):
    """No job with this id."""


@dataclass(frozen=True)
class Job:
    """One row of the store. Times are Unix seconds (None until reached); timings_ms: per stage."""

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

    def as_public(self) -> dict:
        """The REST view: id, status, progress, error (only when set), timings (ms), and the
        Unix times it was submitted, started and ended (null until then)."""
        out = {"id": self.id, "status": self.state.value, "progress": round(self.progress, 4),
               "timings": self.timings_ms, "created_unix_s": self.created_s,
               "started_unix_s": self.started_s, "finished_unix_s": self.finished_s}
        if self.error is not None:
            out["error"] = self.error
        return out


@dataclass(frozen=True)
class JobKind:
    name: str
    function: JobFunction


class JobRegistry:
    """kind name -> job function."""

    def __init__(self, kinds: tuple[JobKind, ...] = ()) -> None:
        self._kinds: dict[str, JobKind] = {}
        for k in kinds:
            self.register(k)

    def register(self, kind: JobKind) -> None:
        if kind.name in self._kinds:
            raise ValueError(f"job kind {kind.name!r} is already registered")
        self._kinds[kind.name] = kind

    def get(self, name: str) -> JobKind:
        try:
            return self._kinds[name]
        except KeyError:
            raise KeyError(f"unknown job kind {name!r}") from None

    def __contains__(self, name: str) -> bool:
        return name in self._kinds


_SCHEMA = """
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
_COLUMNS = "id, kind, params, state, progress, error, attempts, created_s, started_s, finished_s, timings"


def _row_to_job(row) -> Job:
    return Job(id=row[0], kind=row[1], params=json.loads(row[2]), state=JobState(row[3]),
               progress=float(row[4]), error=row[5], attempts=int(row[6]), created_s=row[7],
               started_s=row[8], finished_s=row[9], timings_ms=json.loads(row[10]))


class JobStore:
    """Jobs in `<root>/jobs.sqlite3` and their files in `<root>/<id>/`. Thread-safe (one
    connection behind a lock; every call is one short transaction)."""

    DB_NAME = "jobs.sqlite3"

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._db = sqlite3.connect(self.root / self.DB_NAME, timeout=30.0, isolation_level=None,
                                   check_same_thread=False)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.executescript(_SCHEMA)

    def close(self) -> None:
        with self._lock:
            self._db.close()

    @contextlib.contextmanager
    def _tx(self) -> Iterator[sqlite3.Connection]:
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

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

    # -- rows ---------------------------------------------------------------------------------

    def submit(self, kind: str, params: dict, files: dict[str, bytes], *,
               max_queued: int | None = None) -> Job:
        """A new queued job with `files` (name -> content) in its input folder. Raises QueueFull
        when `max_queued` jobs are queued already; nothing is left behind on any failure."""
        job_id = uuid.uuid4().hex
        params_text = json.dumps(params, sort_keys=True)
        tmp = self.temp_dir()
        try:
            (tmp / "input").mkdir()
            for name, data in files.items():
                if "/" in name or name.startswith("."):
                    raise ValueError(f"bad input file name {name!r}")
                (tmp / "input" / name).write_bytes(data)
            with self._tx() as db:
                if max_queued is not None:
                    (queued,) = db.execute("SELECT COUNT(*) FROM jobs WHERE state = ?",
                                           (JobState.QUEUED.value,)).fetchone()
                    if queued >= max_queued:
                        raise QueueFull(f"{queued} jobs are queued already (limit {max_queued}); "
                                        "retry later")
                os.rename(tmp, self.root / job_id)
                try:
                    (seq,) = db.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM jobs").fetchone()
                    db.execute(f"INSERT INTO jobs ({_COLUMNS}, seq) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                               (job_id, kind, params_text, JobState.QUEUED.value, 0.0, None, 0,
                                time.time(), None, None, "{}", seq))
                except BaseException:
                    shutil.rmtree(self.root / job_id, ignore_errors=True)
                    raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return self.get(job_id)

    def get(self, job_id: str) -> Job:
        with self._lock:
            row = self._db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is None:
            raise JobNotFound(job_id)
        return _row_to_job(row)

    def list(self, state: JobState | None = None, *, kind: str | None = None,
             limit: int | None = None, newest_first: bool = False) -> list[Job]:
        """Jobs in submission order (newest first when asked), all or those in `state` and of
        `kind`, at most `limit` of them."""
        where = [(c, v) for c, v in (("state", state.value if state else None), ("kind", kind))
                 if v is not None]
        sql = f"SELECT {_COLUMNS} FROM jobs"
        if where:
            sql += " WHERE " + " AND ".join(f"{c} = ?" for c, _ in where)
        sql += " ORDER BY seq" + (" DESC" if newest_first else "")
        args = [v for _, v in where]
        if limit is not None:
            sql += " LIMIT ?"
            args.append(int(limit))
        with self._lock:
            rows = self._db.execute(sql, args).fetchall()
        return [_row_to_job(r) for r in rows]

    def count(self, state: JobState) -> int:
        with self._lock:
            return int(self._db.execute("SELECT COUNT(*) FROM jobs WHERE state = ?",
                                        (state.value,)).fetchone()[0])

    def claim_next(self) -> Job | None:
        """The oldest queued job, now `running` with one more attempt; None when none is queued."""
        with self._tx() as db:
            row = db.execute("SELECT id FROM jobs WHERE state = ? ORDER BY seq LIMIT 1",
                             (JobState.QUEUED.value,)).fetchone()
            if row is None:
                return None
            db.execute("UPDATE jobs SET state = ?, attempts = attempts + 1, started_s = ?, "
                       "progress = 0, error = NULL WHERE id = ?",
                       (JobState.RUNNING.value, time.time(), row[0]))
        return self.get(row[0])

    def set_progress(self, job_id: str, progress: float) -> None:
        with self._tx() as db:
            db.execute("UPDATE jobs SET progress = ? WHERE id = ? AND state = ?",
                       (min(max(float(progress), 0.0), 1.0), job_id, JobState.RUNNING.value))

    def finish(self, job_id: str, state: JobState, *, error: str | None = None,
               timings_ms: dict[str, float] | None = None, only_if: JobState | None = None) -> bool:
        """Set a final state (and progress 1 on success). only_if: change nothing unless the job
        is in that state now. Returns whether the row changed."""
        assert state.finished
        with self._tx() as db:
            sql = ("UPDATE jobs SET state = ?, error = ?, finished_s = ?, timings = ?, "
                   "progress = CASE WHEN ? THEN 1.0 ELSE progress END WHERE id = ?")
            args = [state.value, error, time.time(), json.dumps(timings_ms or {}),
                    state is JobState.SUCCEEDED, job_id]
            if timings_ms is None:
                sql = sql.replace("timings = ?, ", "")
                del args[3]
            if only_if is not None:
                sql += " AND state = ?"
                args.append(only_if.value)
            changed = db.execute(sql, args).rowcount
        return changed > 0

    def cancel(self, job_id: str) -> Job:
        """A queued or running job becomes cancelled (the runner ends a running job's process).
        A finished job is returned unchanged. Raises JobNotFound."""
        job = self.get(job_id)
        if not job.state.finished:
            self.finish(job_id, JobState.CANCELLED, error="cancelled by request", only_if=job.state)
        return self.get(job_id)

    def purge_finished(self, ended_before_s: float) -> list[str]:
        """Remove the jobs that ended (succeeded, failed or were cancelled) before this Unix time,
        rows first, then their folders. Returns their ids."""
        finished = [s.value for s in JobState if s.finished]
        with self._tx() as db:
            ids = [r[0] for r in db.execute(
                f"SELECT id FROM jobs WHERE state IN ({','.join('?' * len(finished))}) "
                "AND finished_s < ?", (*finished, ended_before_s)).fetchall()]
            db.executemany("DELETE FROM jobs WHERE id = ?", [(i,) for i in ids])
        for job_id in ids:
            shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
        return ids

    def requeue(self, job_id: str, *, uncount_attempt: bool) -> None:
        with self._tx() as db:
            db.execute("UPDATE jobs SET state = ?, progress = 0, started_s = NULL, "
                       "attempts = attempts - ? WHERE id = ? AND state = ?",
                       (JobState.QUEUED.value, 1 if uncount_attempt else 0, job_id,
                        JobState.RUNNING.value))

    def recover(self, max_attempts: int) -> tuple[list[str], list[str]]:
        """After a restart: jobs found `running` are queued again, or failed once they were
        started `max_attempts` times. Removes orphaned files. Returns (requeued, failed) ids."""
        requeued, failed = [], []
        for job in self.list(JobState.RUNNING):
            if job.attempts >= max_attempts:
                self.finish(job.id, JobState.FAILED, only_if=JobState.RUNNING, error=(
                    f"interrupted: the server stopped while this job ran, {job.attempts} "
                    f"time(s) (limit {max_attempts}); not retried"))
                failed.append(job.id)
            else:
                self.requeue(job.id, uncount_attempt=False)
                requeued.append(job.id)
        known = {j.id for j in self.list()}
        for path in self.root.iterdir():
            if path.is_dir() and (path.name.startswith(".tmp-") or path.name not in known):
                shutil.rmtree(path, ignore_errors=True)
        return requeued, failed


# -- the job process --------------------------------------------------------------------------

def _job_main(function: JobFunction, params: dict, input_dir: str, output_dir: str,
              conn: multiprocessing.connection.Connection) -> None:
    """Entry point of a job process: messages ("progress", f), then ("ok", timings) or
    ("error", message)."""
    conn.send(("started", time.time()))
    die_with_parent()  # a job does not outlive a killed server
    last = [0.0, -1.0]

    def progress(fraction: float) -> None:
        now = time.monotonic()
        if now - last[0] >= 0.05 or fraction >= 1.0:   # at most 20 messages a second
            last[0] = now
            conn.send(("progress", float(fraction)))

    start = time.perf_counter()
    try:
        timings = {k: float(v) for k, v in (function(params, Path(input_dir), Path(output_dir),
                                                     progress) or {}).items()}
        timings["job_function_total"] = (time.perf_counter() - start) * 1e3
        conn.send(("ok", timings))
    except JobError as exc:
        conn.send(("error", str(exc)))
    except BaseException as exc:  # report everything: the parent only sees the exit code otherwise
        log.error("job failed:\n%s", traceback.format_exc())
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        conn.close()


@dataclass
class _Running:
    job: Job
    process: multiprocessing.process.BaseProcess
    conn: multiprocessing.connection.Connection
    work_dir: Path
    started_monotonic: float
    queued_ms: float
    started_wall: float = 0.0
    process_start_ms: float | None = None
    outcome: tuple | None = None
    terminating_since: float | None = None
    stop_reason: str | None = None    # "cancelled", "timeout", "shutdown"


class JobRunner:
    """Runs queued jobs of a `JobStore` in worker processes, `max_concurrent_jobs` at a time.

    Thread-safe; `submit`, `cancel` and `get` are quick (SQLite and small files) and may be called
    from an asyncio handler's thread pool. `start()` recovers interrupted jobs and starts the
    runner thread; `stop()` ends running jobs and requeues them.
    """

    def __init__(self, data_dir: str | Path, registry: JobRegistry,
                 settings: JobSettings = JobSettings(), *, preload: tuple[str, ...] = (),
                 clock: Callable[[], float] = time.time) -> None:
        self.settings = settings
        self._clock = clock            # Unix seconds, for the retention of finished jobs
        self.registry = registry
        self.store = JobStore(Path(data_dir) / "jobs")
        self._mp = multiprocessing.get_context("forkserver")
        self._preload = preload
        self._running: dict[str, _Running] = {}
        self._wake_r, self._wake_w = self._mp.Pipe(duplex=False)
        self._wake_lock = threading.Lock()
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock_file = None

    # -- lifetime -----------------------------------------------------------------------------

    def add_kind(self, kind: JobKind, preload: str | None = None) -> None:
        """Register one more job kind (several route modules share the folder's one runner);
        preload: its module, imported once by the forkserver instead of by every job. Before start()."""
        if self._thread is not None:
            raise RuntimeError("add job kinds before the runner starts")
        self.registry.register(kind)
        if preload is not None:
            self._preload = (*self._preload, preload)

    def start(self) -> None:
        """Take the folder's runner lock, recover jobs from a previous run, start the thread.
        Raises RuntimeError when another runner holds the folder."""
        if self._thread is not None:
            raise RuntimeError("JobRunner already started")
        self._lock_file = open(self.store.root / "runner.lock", "w")
        try:
            fcntl.flock(self._lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock_file.close()
            self._lock_file = None
            raise RuntimeError(f"another job runner uses {self.store.root}") from None
        if self._preload:
            with contextlib.suppress(Exception):   # '__main__': imported once, not per job
                self._mp.set_forkserver_preload(["__main__", *self._preload])
        self._start_forkserver()
        requeued, failed = self.store.recover(self.settings.max_attempts)
        if requeued or failed:
            log.info("recovered jobs: %d requeued, %d failed after too many attempts",
                     len(requeued), len(failed))
        self.purge_expired()
        self._stopping.clear()
        self._thread = threading.Thread(target=self._loop, name="job-runner", daemon=True)
        self._thread.start()

    def _start_forkserver(self) -> None:
        """Start the forkserver now (not in the first job's time) with BLAS/OpenMP thread pools
        of `job_blas_threads` threads: the variables are set only while it is started, so the
        front's own environment is unchanged."""
        from multiprocessing import forkserver

        names = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
        saved = {n: os.environ.get(n) for n in names}
        try:
            if self.settings.job_blas_threads > 0:
                os.environ.update({n: str(self.settings.job_blas_threads) for n in names})
            forkserver.ensure_running()
        except Exception:
            log.exception("cannot start the forkserver now; it starts with the first job")
        finally:
            for n, v in saved.items():
                if v is None:
                    os.environ.pop(n, None)
                else:
                    os.environ[n] = v

    def stop(self, timeout_s: float = 10.0) -> None:
        """End running job processes (their jobs go back to the queue, the attempt not counted),
        stop the thread and release the folder. Safe to call twice."""
        if self._thread is None:
            return
        self._stopping.set()
        self._wake()
        self._thread.join(timeout_s)
        self._thread = None
        if self._lock_file is not None:
            self._lock_file.close()
            self._lock_file = None

    def close(self) -> None:
        self.stop()
        self.store.close()

    def __enter__(self) -> JobRunner:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- API ----------------------------------------------------------------------------------

    def submit(self, kind: str, params: dict, files: dict[str, bytes]) -> Job:
        """Queue a job. Raises KeyError for an unknown kind, QueueFull when the queue is full."""
        self.registry.get(kind)
        job = self.store.submit(kind, params, files, max_queued=self.settings.max_queued_jobs)
        self._wake()
        return job

    def get(self, job_id: str) -> Job:
        return self.store.get(job_id)

    def cancel(self, job_id: str) -> Job:
        job = self.store.cancel(job_id)
        self._wake()
        return job

    def result_dir(self, job_id: str) -> Path:
        return self.store.result_dir(job_id)

    def purge_expired(self) -> list[str]:
        """Remove the jobs that ended more than `job_retention_s` ago (none when it is 0), so the
        data directory does not grow without bound. The runner calls it at start and every
        `_PURGE_INTERVAL_S`. Returns their ids."""
        if self.settings.job_retention_s <= 0:
            return []
        purged = self.store.purge_finished(self._clock() - self.settings.job_retention_s)
        if purged:
            log.info("removed %d jobs that ended over %g s ago", len(purged), self.settings.job_retention_s)
        return purged

    def wait(self, job_id: str, timeout_s: float = 60.0, poll_s: float = 0.05) -> Job:
        """Block until the job is finished (for tests and the CLI). Raises TimeoutError."""
        deadline = time.monotonic() + timeout_s
        while True:
            job = self.store.get(job_id)
            if job.state.finished:
                return job
            if time.monotonic() > deadline:
                raise TimeoutError(f"job {job_id} still {job.state.value} after {timeout_s} s")
            time.sleep(poll_s)

    # -- the runner thread --------------------------------------------------------------------

    def _wake(self) -> None:
        with self._wake_lock, contextlib.suppress(OSError):
            self._wake_w.send_bytes(b"1")

    def _loop(self) -> None:
        next_purge = time.monotonic() + _PURGE_INTERVAL_S
        try:
            while not self._stopping.is_set():
                self._reap()
                self._start_queued()
                if time.monotonic() >= next_purge:
                    self.purge_expired()
                    next_purge = time.monotonic() + _PURGE_INTERVAL_S
                waitables = [self._wake_r]
                for r in self._running.values():
                    waitables += [r.conn, r.process.sentinel]
                ready = multiprocessing.connection.wait(waitables, timeout=0.25)
                if self._wake_r in ready:
                    with contextlib.suppress(OSError, EOFError):
                        while self._wake_r.poll():
                            self._wake_r.recv_bytes()
                self._read_messages()
        except Exception:  # keep the front alive; jobs left `running` are recovered next start
            log.exception("job runner thread failed")
        finally:
            self._shutdown_running()

    def _start_queued(self) -> None:
        while len(self._running) < self.settings.max_concurrent_jobs and not self._stopping.is_set():
            job = self.store.claim_next()
            if job is None:
                return
            try:
                function = self.registry.get(job.kind).function
            except KeyError as exc:
                self.store.finish(job.id, JobState.FAILED, error=str(exc))
                continue
            work_dir = self.store.temp_dir()
            parent_conn, child_conn = self._mp.Pipe(duplex=False)
            process = self._mp.Process(
                target=_job_main, name=f"job-{job.id[:8]}", daemon=True,
                args=(function, job.params, str(self.store.input_dir(job.id)), str(work_dir),
                      child_conn))
            started, started_wall = time.monotonic(), time.time()
            try:
                process.start()
            except Exception as exc:   # e.g. no forkserver: fail this job, keep the runner
                log.exception("cannot start the process of job %s", job.id)
                child_conn.close()
                parent_conn.close()
                shutil.rmtree(work_dir, ignore_errors=True)
                self.store.finish(job.id, JobState.FAILED, only_if=JobState.RUNNING,
                                  error=f"cannot start a job process: {type(exc).__name__}: {exc}")
                continue
            child_conn.close()
            self._running[job.id] = _Running(
                job=job, process=process, conn=parent_conn, work_dir=work_dir,
                started_monotonic=started, started_wall=started_wall,
                queued_ms=max(0.0, ((job.started_s or time.time()) - job.created_s) * 1e3))

    def _read_messages(self) -> None:
        for job_id, r in list(self._running.items()):
            with contextlib.suppress(EOFError, OSError):
                while r.conn.poll():
                    kind, value = r.conn.recv()
                    if kind == "progress":
                        self.store.set_progress(job_id, value)
                    elif kind == "started":
                        r.process_start_ms = max(0.0, (value - r.started_wall) * 1e3)
                    else:
                        r.outcome = (kind, value)

    def _reap(self) -> None:
        now = time.monotonic()
        for job_id, r in list(self._running.items()):
            if r.stop_reason is None:
                current = self.store.get(job_id).state
                if current is JobState.CANCELLED:
                    r.stop_reason = "cancelled"
                elif now - r.started_monotonic > self.settings.job_timeout_s:
                    r.stop_reason = "timeout"
                if r.stop_reason is not None and r.process.is_alive():
                    r.process.terminate()
                    r.terminating_since = now
            if r.terminating_since is not None and r.process.is_alive():
                if now - r.terminating_since > self.settings.cancel_grace_s:
                    r.process.kill()
                continue
            if r.process.is_alive():
                continue
            r.process.join()
            self._read_messages()
            self._settle(job_id, r)

    def _settle(self, job_id: str, r: _Running) -> None:
        del self._running[job_id]
        r.conn.close()
        run_ms = (time.monotonic() - r.started_monotonic) * 1e3
        try:
            if r.stop_reason == "cancelled":
                return
            if r.stop_reason == "timeout":
                self.store.finish(job_id, JobState.FAILED, only_if=JobState.RUNNING,
                                  error=f"timed out after {self.settings.job_timeout_s:g} s")
                return
            if r.outcome is not None and r.outcome[0] == "ok":
                timings = dict(r.outcome[1])
                timings["queued"] = r.queued_ms
                timings["job_process_total"] = run_ms
                if r.process_start_ms is not None:
                    timings["job_process_start"] = r.process_start_ms
                result = self.store.result_dir(job_id)
                shutil.rmtree(result, ignore_errors=True)
                os.rename(r.work_dir, result)
                if not self.store.finish(job_id, JobState.SUCCEEDED, timings_ms=timings,
                                         only_if=JobState.RUNNING):
                    shutil.rmtree(result, ignore_errors=True)   # cancelled at the last moment
                return
            if r.outcome is not None:
                error = str(r.outcome[1])
            else:
                error = f"the job process exited with code {r.process.exitcode} without a result"
            self.store.finish(job_id, JobState.FAILED, error=error, only_if=JobState.RUNNING,
                              timings_ms={"job_process_total": run_ms, "queued": r.queued_ms})
        finally:
            shutil.rmtree(r.work_dir, ignore_errors=True)

    def _shutdown_running(self) -> None:
        for r in self._running.values():
            if r.process.is_alive():
                r.process.terminate()
        deadline = time.monotonic() + self.settings.cancel_grace_s
        for job_id, r in list(self._running.items()):
            r.process.join(max(0.0, deadline - time.monotonic()))
            if r.process.is_alive():
                r.process.kill()
                r.process.join()
            r.conn.close()
            shutil.rmtree(r.work_dir, ignore_errors=True)
            self.store.requeue(job_id, uncount_attempt=True)
        self._running.clear()
