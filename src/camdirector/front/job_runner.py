"""The front's local job runner (one node, no queue): one thread of the front process that claims
queued records in submission order, `max_concurrent_jobs` at a time, and hands them to its executor
(jobs/executor.py), which runs each in a job process.

Restart: a runner that starts finds queued jobs and runs them; jobs found `running` (the previous
front process died while they ran) are queued again and rerun, or failed with a reason once they
have been started `max_attempts` times. A runner stopped cleanly puts its running jobs back in the
queue without counting the attempt. One runner owns a data directory (runner.lock).

A record store that goes down (PostgreSQL, `job_store`) stops nothing: running jobs run on and
their outcomes are recorded when it is back (executor.py), and no queued job is claimed until it
answers again, asked every `RECORD_RETRY_S[1]` at most.

`open_jobs` gives the front its jobs: this runner, or a client of the shared queue
(jobs/queue.py) when `job_queue` is set; front/main.py opens them with the service's kinds
(jobs/kinds.py) and hands them to the job routes.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import multiprocessing
import multiprocessing.connection
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from camdirector.jobs.executor import POLL_S, PURGE_INTERVAL_S, RECORD_RETRY_S, Attempt, JobExecutor, purge_expired
from camdirector.jobs.job_settings import JobSettings
from camdirector.jobs.kinds import JobRegistry
from camdirector.jobs.queue import QueueClient
from camdirector.jobs.records import Job, JobsUnavailable, open_store

log = logging.getLogger("camdirector.jobs")


class JobRunner:
    """Runs the queued jobs of `<data_dir>/jobs/` in job processes, `max_concurrent_jobs` at a
    time, from one thread of this process (module docstring).

    Thread-safe; `submit`, `cancel` and `get` are quick (SQLite and small files) and may be called
    from an asyncio handler's thread pool. `start()` recovers interrupted jobs and starts the
    runner thread; `stop()` ends running jobs and requeues them.
    """

    def __init__(
        self,
        data_dir: str | Path,
        registry: JobRegistry,
        settings: JobSettings = JobSettings(),
        *,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.settings = settings
        self._clock = clock  # Unix seconds, for the retention of finished jobs
        self.registry = registry
        self.store = open_store(settings.job_store, Path(data_dir) / "jobs")
        self._executor = JobExecutor(self.store, registry, settings)
        self._running: dict[str, Attempt] = {}
        self._mp = multiprocessing.get_context("forkserver")
        self._wake_r, self._wake_w = self._mp.Pipe(duplex=False)
        self._wake_lock = threading.Lock()
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock_file: TextIO | None = None
        self._store_back_at = 0.0  # time.monotonic() before which a store found down is not asked to claim

    # -- lifetime -----------------------------------------------------------------------------

    def start(self) -> None:
        """Take the folder's runner lock, recover jobs from a previous run, start the thread.
        Raises RuntimeError when another runner holds the folder."""
        if self._thread is not None:
            raise RuntimeError("JobRunner already started")
        self._lock_file = lock_file = open(self.store.root / "runner.lock", "w")
        try:
            fcntl.flock(lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock_file.close()
            self._lock_file = None
            raise RuntimeError(f"another job runner uses {self.store.root}") from None
        self._executor.start()
        requeued, failed = self.store.recover(self.settings.max_attempts)
        if requeued or failed:
            log.info("recovered jobs: %d requeued, %d failed after too many attempts", len(requeued), len(failed))
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

    def submit(
        self, kind: str, params: dict, files: dict[str, bytes], tenant: str = "default", idempotency_key: str | None = None
    ) -> Job:
        """Queue a job of `tenant` (or answer the earlier one with `idempotency_key`: records.py,
        "Idempotency"). Raises KeyError for an unknown kind, QueueFull when the queue is full,
        TenantLimitReached beyond the tenant's share (JobSettings), IdempotencyConflict."""
        self.registry.get(kind)
        job = self.store.submit(
            kind, params, files, tenant=tenant, idempotency_key=idempotency_key, **self.settings.submit_limits()
        )
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
                if time.monotonic() >= self._store_back_at:
                    try:
                        self._start_queued()
                        if time.monotonic() >= next_purge:
                            next_purge = time.monotonic() + PURGE_INTERVAL_S
                            self.purge_expired()
                    except JobsUnavailable as exc:  # claims wait for the store (module docstring)
                        log.warning("no job is started until the job store is back: %s", exc)
                        self._store_back_at = time.monotonic() + RECORD_RETRY_S[1]
                waitables = [self._wake_r]
                for a in self._running.values():
                    waitables += a.waitables()
                ready = multiprocessing.connection.wait(waitables, timeout=POLL_S)
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


def open_jobs(data_dir: str | Path, registry: JobRegistry, settings: JobSettings) -> JobRunner | QueueClient:
    """The front's jobs: this process's own runner when `settings.job_queue` is empty, else a
    client of the queue. Raises JobsUnavailable when Redis or PostgreSQL cannot be reached."""
    if settings.job_queue:
        return QueueClient(data_dir, registry, settings)
    return JobRunner(data_dir, registry, settings)
