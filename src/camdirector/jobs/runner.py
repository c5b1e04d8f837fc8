"""Running jobs: the settings, the job kinds, the job process, the executor that runs one claimed
job in a process and records its outcome, and the local runner (one node, no queue).

A job runs in its own process (multiprocessing "forkserver": forked from a small single-threaded
server process, never from the front process that runs gRPC and asyncio, nor from a queue worker's
threads), so no event loop or broker thread ever runs a job, and a cancelled or timed-out job is
ended by terminating its process. `JobExecutor` starts the process, reads its progress from a
pipe, checks the job's record (cancelled? taken over by another worker? too long?) and records
the outcome of the attempt it started, by compare-and-set (records.py): the result folder is
renamed into `<id>/result/` inside the transaction that marks the attempt succeeded.

`JobRunner` is the local mode: one thread in the front process that claims queued records in
submission order, `max_concurrent_jobs` at a time, and hands them to its executor. Restart: a
runner that starts finds queued jobs and runs them; jobs found `running` (the previous front
process died while they ran) are queued again and rerun, or failed with a reason once they have
been started `max_attempts` times. A runner stopped cleanly puts its running jobs back in the
queue without counting the attempt. One runner owns a data directory (runner.lock).

Retention: a finished job (its record, inputs and results) is removed `job_retention_s` after it
ended, checked at start and every minute (by the runner, or by every queue worker).

Job kinds: `JobKind(name, function)` in a `JobRegistry`; the function runs in the job process as
`function(params: dict, input_dir: Path, output_dir: Path, progress: Callable[[float], None])
-> dict[str, float]` (timings in milliseconds) and raises to fail the job (`JobError`'s message is
shown as is; other exceptions as "<Type>: message"). It must be a module-level function (it is
pickled by reference into the job process).
"""
from __future__ import annotations

import contextlib
import fcntl
import logging
import multiprocessing
import multiprocessing.connection
import os
import shutil
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from camdirector.infra.job_errors import JobError
from camdirector.infra.process_lifetime import die_with_parent
from camdirector.jobs.records import Job, JobNotFound, JobState, JobStore, open_store

log = logging.getLogger("camdirector.jobs")

JobFunction = Callable[[dict, Path, Path, Callable[[float], None]], dict]
PURGE_INTERVAL_S = 60.0   # how often finished jobs past their retention are looked for
_POLL_S = 0.25            # a running job's record is checked at least this often (cancel, take-over), s


@dataclass(frozen=True)
class JobSettings:
    """Limits of the offline jobs (one per process; wired into ServerSettings)."""

    max_concurrent_jobs: int = 1           # job processes running at once, per runner or queue worker. [1, 64]
    max_queued_jobs: int = 16              # jobs waiting to run; a submit beyond this is refused (HTTP 429). [0, 100000]
    max_upload_bytes: int = 64 * 1024 * 1024  # largest uploaded file of a job, bytes (HTTP 413 above). [1 KiB, 4 GiB]
    max_attempts: int = 2                  # times a job may be started; one found interrupted after that fails. [1, 100]
    job_timeout_s: float = 600.0           # a running job is ended and failed after this, s. [1, 86400]
    cancel_grace_s: float = 2.0            # SIGTERM to SIGKILL of a cancelled job's process, s. [0, 60]
    job_blas_threads: int = 1              # BLAS/OpenMP threads per job process (0: library default). [0, 64]
    job_retention_s: float = 7 * 86400.0   # a finished job's record and files go this long after it ends (0: kept), s. [0, 1e9]
    # Where records live: "" is SQLite in the data directory; postgresql://... is shared by many nodes.
    job_store: str = ""
    # Where jobs wait: "" is this process's own runner; redis://... is the queue of `camdirector job-worker`s.
    job_queue: str = ""
    # A queue worker silent this long is taken for dead and its jobs are run again elsewhere; it beats
    # every quarter of this. Every worker must use the same value, s. [1, 3600]
    worker_heartbeat_timeout_s: float = 30.0

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
            (not self.job_store or self.job_store.startswith(("postgresql://", "postgres://")),
             "job_store must be empty (SQLite in the data directory) or a postgresql:// URL"),
            (not self.job_queue or self.job_queue.startswith("redis://"),
             "job_queue must be empty (this process's runner) or a redis:// URL"),
            (1.0 <= self.worker_heartbeat_timeout_s <= 3600.0, "worker_heartbeat_timeout_s must be in [1, 3600]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)


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


def purge_expired(store: JobStore, settings: JobSettings, now_s: float) -> list[str]:
    """Remove the jobs that ended more than `job_retention_s` before `now_s` (Unix s; none when
    the retention is 0), so a long-running data directory stays bounded. Returns their ids."""
    if settings.job_retention_s <= 0:
        return []
    purged = store.purge_finished(now_s - settings.job_retention_s)
    if purged:
        log.info("removed %d jobs that ended over %g s ago", len(purged), settings.job_retention_s)
    return purged


# -- the job process ----------------------------------------------------------------------------

def _job_main(function: JobFunction, params: dict, input_dir: str, output_dir: str,
              conn: multiprocessing.connection.Connection) -> None:
    """Entry point of a job process: messages ("started", unix_s), ("progress", f), then
    ("ok", timings) or ("error", message)."""
    conn.send(("started", time.time()))
    die_with_parent()  # a job does not outlive a killed server or queue worker
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
class Attempt:
    """One attempt of a claimed job in its process (job.attempts is the attempt's number)."""

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
    stop_reason: str | None = None    # "cancelled", "superseded", "timeout"
    next_check: float = 0.0           # time.monotonic() of the next look at the record

    def waitables(self) -> list:
        return [self.conn, self.process.sentinel]


class JobExecutor:
    """Runs claimed jobs in processes from a forkserver and records each attempt's outcome in
    `store`. Thread-safe: `launch` and `step` of different attempts may run in different threads."""

    def __init__(self, store: JobStore, registry: JobRegistry, settings: JobSettings,
                 preload: tuple[str, ...] = ()) -> None:
        self.store = store
        self.registry = registry
        self.settings = settings
        self.preload = preload
        self._mp = multiprocessing.get_context("forkserver")

    def start(self) -> None:
        """Start the forkserver now (not in the first job's time), preloading the job modules,
        with BLAS/OpenMP thread pools of `job_blas_threads` threads: the variables are set only
        while it is started, so this process's own environment is unchanged."""
        from multiprocessing import forkserver

        if self.preload:
            with contextlib.suppress(Exception):   # '__main__': imported once, not per job
                self._mp.set_forkserver_preload(["__main__", *self.preload])
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

    def launch(self, job: Job) -> Attempt | None:
        """Start the process of a claimed job (state running, this attempt's number in
        `job.attempts`). None when it could not start (the job is failed, with the reason)."""
        try:
            function = self.registry.get(job.kind).function
        except KeyError as exc:
            self.store.finish(job.id, JobState.FAILED, error=str(exc), attempt=job.attempts)
            return None
        work_dir = self.store.temp_dir()
        parent_conn, child_conn = self._mp.Pipe(duplex=False)
        process = self._mp.Process(
            target=_job_main, name=f"job-{job.id[:8]}", daemon=True,
            args=(function, job.params, str(self.store.input_dir(job.id)), str(work_dir), child_conn))
        started, started_wall = time.monotonic(), time.time()
        try:
            process.start()
        except Exception as exc:   # e.g. no forkserver: fail this job, keep running others
            log.exception("cannot start the process of job %s", job.id)
            child_conn.close()
            parent_conn.close()
            shutil.rmtree(work_dir, ignore_errors=True)
            self.store.finish(job.id, JobState.FAILED, only_if=JobState.RUNNING, attempt=job.attempts,
                              error=f"cannot start a job process: {type(exc).__name__}: {exc}")
            return None
        child_conn.close()
        return Attempt(job=job, process=process, conn=parent_conn, work_dir=work_dir,
                       started_monotonic=started, started_wall=started_wall,
                       queued_ms=max(0.0, ((job.started_s or time.time()) - job.created_s) * 1e3))

    def step(self, a: Attempt) -> bool:
        """Read the attempt's messages, end its process when the job was cancelled, taken over
        or ran too long, and record the outcome once the process ended. True when it is over."""
        self._read_messages(a)
        now = time.monotonic()
        if a.stop_reason is None and now >= a.next_check:
            a.next_check = now + _POLL_S
            a.stop_reason = self._stop_reason(a, now)
            if a.stop_reason is not None and a.process.is_alive():
                a.process.terminate()
                a.terminating_since = now
        if a.process.is_alive():
            if a.terminating_since is not None and now - a.terminating_since > self.settings.cancel_grace_s:
                a.process.kill()
            return False
        a.process.join()
        self._read_messages(a)
        self._settle(a)
        return True

    def run(self, job: Job, stopping: threading.Event, hand_back: Callable[[], None]) -> None:
        """Run a claimed job to its end in this thread (a queue worker's). When `stopping` is set
        first, `hand_back()` (the job's message sent again), then the process is ended and the
        record queued again, the attempt not counted."""
        a = self.launch(job)
        if a is None:
            return
        while not self.step(a):
            if stopping.is_set():
                self.end([a], before_requeue=hand_back)
                return
            multiprocessing.connection.wait(a.waitables(), timeout=_POLL_S)

    def end(self, attempts: list[Attempt], before_requeue: Callable[[], None] | None = None) -> None:
        """Shutdown: end the attempts' processes (SIGTERM, SIGKILL after `cancel_grace_s`) and
        queue their jobs again without counting the attempt (`before_requeue()` first)."""
        for a in attempts:
            if a.process.is_alive():
                a.process.terminate()
        deadline = time.monotonic() + self.settings.cancel_grace_s
        for a in attempts:
            a.process.join(max(0.0, deadline - time.monotonic()))
            if a.process.is_alive():
                a.process.kill()
                a.process.join()
            a.conn.close()
            shutil.rmtree(a.work_dir, ignore_errors=True)
            if before_requeue is not None:
                before_requeue()
            self.store.requeue(a.job.id, uncount_attempt=True, attempt=a.job.attempts)

    def _stop_reason(self, a: Attempt, now: float) -> str | None:
        try:
            current = self.store.get(a.job.id)
        except JobNotFound:
            return "superseded"
        if current.state is JobState.CANCELLED:
            return "cancelled"
        if current.state is not JobState.RUNNING or current.attempts != a.job.attempts:
            return "superseded"   # another worker took over this job after a redelivery
        if now - a.started_monotonic > self.settings.job_timeout_s:
            return "timeout"
        return None

    def _read_messages(self, a: Attempt) -> None:
        with contextlib.suppress(EOFError, OSError):
            while a.conn.poll():
                kind, value = a.conn.recv()
                if kind == "progress":
                    self.store.set_progress(a.job.id, value, attempt=a.job.attempts)
                elif kind == "started":
                    a.process_start_ms = max(0.0, (value - a.started_wall) * 1e3)
                else:
                    a.outcome = (kind, value)

    def _settle(self, a: Attempt) -> None:
        a.conn.close()
        job_id, attempt = a.job.id, a.job.attempts
        run_ms = (time.monotonic() - a.started_monotonic) * 1e3
        try:
            if a.stop_reason in ("cancelled", "superseded"):
                return
            if a.stop_reason == "timeout":
                self.store.finish(job_id, JobState.FAILED, only_if=JobState.RUNNING, attempt=attempt,
                                  error=f"timed out after {self.settings.job_timeout_s:g} s")
                return
            if a.outcome is not None and a.outcome[0] == "ok":
                timings = dict(a.outcome[1])
                timings["queued"] = a.queued_ms
                timings["job_process_total"] = run_ms
                if a.process_start_ms is not None:
                    timings["job_process_start"] = a.process_start_ms
                self._publish(a, timings)
                return
            if a.outcome is not None:
                error = str(a.outcome[1])
            else:
                error = f"the job process exited with code {a.process.exitcode} without a result"
            self.store.finish(job_id, JobState.FAILED, error=error, only_if=JobState.RUNNING,
                              attempt=attempt, timings_ms={"job_process_total": run_ms, "queued": a.queued_ms})
        finally:
            shutil.rmtree(a.work_dir, ignore_errors=True)

    def _publish(self, a: Attempt, timings: dict[str, float]) -> None:
        """Succeed the attempt and rename its folder to `<id>/result/` in one transaction; an
        attempt that was cancelled or taken over meanwhile changes nothing."""
        result = self.store.result_dir(a.job.id)

        def rename() -> None:
            shutil.rmtree(result, ignore_errors=True)   # a folder left by a rolled-back attempt
            os.rename(a.work_dir, result)

        try:
            self.store.finish(a.job.id, JobState.SUCCEEDED, timings_ms=timings, only_if=JobState.RUNNING,
                              attempt=a.job.attempts, publish=rename)
        except OSError as exc:   # the rename failed: the transaction was rolled back
            self.store.finish(a.job.id, JobState.FAILED, only_if=JobState.RUNNING, attempt=a.job.attempts,
                              error=f"cannot store the result: {exc}")


# -- the local runner ---------------------------------------------------------------------------

class JobRunner:
    """Runs the queued jobs of `<data_dir>/jobs/` in job processes, `max_concurrent_jobs` at a
    time, from one thread of this process (module docstring).

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
        self.store = open_store(settings.job_store, Path(data_dir) / "jobs")
        self._executor = JobExecutor(self.store, registry, settings, preload)
        self._running: dict[str, Attempt] = {}
        self._mp = multiprocessing.get_context("forkserver")
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
            self._executor.preload = (*self._executor.preload, preload)

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
        self._executor.start()
        requeued, failed = self.store.recover(self.settings.max_attempts)
        if requeued or failed:
            log.info("recovered jobs: %d requeued, %d failed after too many attempts",
                     len(requeued), len(failed))
        self.purge_expired()
        self._stopping.clear()
        self._thread = threading.Thread(target=self._loop, name="job-runner", daemon=True)
        self._thread.start()

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
        """Remove the jobs that ended more than `job_retention_s` ago (`purge_expired`). The
        runner calls it at start and every `PURGE_INTERVAL_S`. Returns their ids."""
        return purge_expired(self.store, self.settings, self._clock())

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
        next_purge = time.monotonic() + PURGE_INTERVAL_S
        try:
            while not self._stopping.is_set():
                for job_id, a in list(self._running.items()):
                    if self._executor.step(a):
                        del self._running[job_id]
                self._start_queued()
                if time.monotonic() >= next_purge:
                    self.purge_expired()
                    next_purge = time.monotonic() + PURGE_INTERVAL_S
                waitables = [self._wake_r]
                for a in self._running.values():
                    waitables += a.waitables()
                ready = multiprocessing.connection.wait(waitables, timeout=_POLL_S)
                if self._wake_r in ready:
                    with contextlib.suppress(OSError, EOFError):
                        while self._wake_r.poll():
                            self._wake_r.recv_bytes()
        except Exception:  # keep the front alive; jobs left `running` are recovered next start
            log.exception("job runner thread failed")
        finally:
            self._executor.end(list(self._running.values()))
            self._running.clear()

    def _start_queued(self) -> None:
        while len(self._running) < self.settings.max_concurrent_jobs and not self._stopping.is_set():
            job = self.store.claim_next()
            if job is None:
                return
            attempt = self._executor.launch(job)
            if attempt is not None:
                self._running[job.id] = attempt
