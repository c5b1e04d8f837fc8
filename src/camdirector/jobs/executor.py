"""Running one claimed job: the executor that starts its process, follows it and records its
outcome, and the retention of finished jobs; shared by the front's local runner
(front/job_runner.py) and the queue workers (queue_worker.py).

A job runs in its own process (multiprocessing "forkserver": forked from a small single-threaded
server process, never from the front process that runs gRPC and asyncio, nor from a queue worker's
threads), so no event loop or broker thread ever runs a job, and a cancelled or timed-out job is
ended by terminating its process. `JobExecutor` starts the process (main.py), reads its progress
from a pipe, checks the job's record (cancelled? taken over by another worker? too long?) and
records the outcome of the attempt it started, by compare-and-set (records.py): the result folder
is renamed into `<id>/result/` inside the transaction that marks the attempt succeeded. A queue
worker's attempt renews its lease every quarter of `worker_heartbeat_timeout_s` (records.py,
"Claims"), so a duplicate of its message waits instead of running the job a second time.

The record store down (JobsUnavailable) is no failure of the job: the process runs on (only the
job timeout ends it then; cancel is seen once the store is back), progress is not written, and the
outcome is kept, its folder with it, and recorded once the store answers again, tried every
`RECORD_RETRY_S` (doubling), so the attempt counts once and the job is not run again. Recording is
idempotent: the compare-and-set changes nothing the second time, and a result folder moved in a
transaction whose commit was lost is not moved again. Every path removes the attempt's `.tmp-*`.

Retention: a finished job (its record, inputs and results) is removed `job_retention_s` after it
ended, checked at start and every `PURGE_INTERVAL_S` (by the runner, or by every queue worker).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import multiprocessing.connection
import os
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from camdirector.jobs.job_settings import JobSettings
from camdirector.jobs.kinds import JobRegistry
from camdirector.jobs.main import job_main
from camdirector.jobs.records import Job, JobNotFound, JobState, JobStore, JobsUnavailable

log = logging.getLogger("camdirector.jobs")

PURGE_INTERVAL_S = 60.0  # how often finished jobs past their retention are looked for
POLL_S = 0.25  # a running job's record is checked at least this often (cancel, take-over), s
# The record store down: first and longest wait before it is asked again for an attempt (its
# progress, cancel, outcome), doubling in between, s.
RECORD_RETRY_S = (0.5, 10.0)


def purge_expired(store: JobStore, settings: JobSettings, now_s: float) -> list[str]:
    """Remove the jobs that ended more than `job_retention_s` before `now_s` (Unix s; none when
    the retention is 0), so a long-running data directory stays bounded. Returns their ids."""
    if settings.job_retention_s <= 0:
        return []
    purged = store.purge_finished(now_s - settings.job_retention_s)
    if purged:
        log.info("removed %d jobs that ended over %g s ago", len(purged), settings.job_retention_s)
    return purged


class NotHandedBack(Exception):
    """A stopping worker could not send its job's message again (the queue down): its own
    delivery must stay unacknowledged, for the broker to send it again (queue_worker.py)."""


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
    stop_reason: str | None = None  # "cancelled", "superseded", "timeout"
    next_check: float = 0.0  # time.monotonic() of the next look at the record
    next_renew: float = 0.0  # time.monotonic() of the next renewal of a queue worker's lease
    record: Callable[[], object] | None = None  # writes the outcome once the process ended (idempotent)
    store_back_at: float = 0.0  # time.monotonic() before which the store, found down, is not asked
    store_wait_s: float = 0.0  # the wait after the next failed call (0: the store answered last)
    moved: bool = False  # the work folder was renamed to result/ (maybe in a transaction not confirmed)

    def waitables(self) -> list:
        """What to wait on: nothing once the process ended (an outcome waiting for the store)."""
        return [] if self.record is not None else [self.conn, self.process.sentinel]


class JobExecutor:
    """Runs claimed jobs in processes from a forkserver and records each attempt's outcome in
    `store`. Thread-safe: `launch` and `step` of different attempts may run in different threads."""

    def __init__(self, store: JobStore, registry: JobRegistry, settings: JobSettings) -> None:
        self.store = store
        self.registry = registry
        self.settings = settings
        self.preload = registry.modules  # imported once by the forkserver, not by every job
        self._mp = multiprocessing.get_context("forkserver")

    def start(self) -> None:
        """Start the forkserver now (not in the first job's time), preloading the job modules,
        with BLAS/OpenMP thread pools of `job_blas_threads` threads: the variables are set only
        while it is started, so this process's own environment is unchanged."""
        from multiprocessing import forkserver

        if self.preload:
            with contextlib.suppress(Exception):  # '__main__': imported once, not per job
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
            target=job_main,
            name=f"job-{job.id[:8]}",
            daemon=True,
            args=(function, job.params, str(self.store.input_dir(job.id)), str(work_dir), child_conn),
        )
        started, started_wall = time.monotonic(), time.time()
        try:
            process.start()
        except Exception as exc:  # e.g. no forkserver: fail this job, keep running others
            log.exception("cannot start the process of job %s", job.id)
            child_conn.close()
            parent_conn.close()
            shutil.rmtree(work_dir, ignore_errors=True)
            self.store.finish(
                job.id,
                JobState.FAILED,
                only_if=JobState.RUNNING,
                attempt=job.attempts,
                error=f"cannot start a job process ({type(exc).__name__}); the server's log has the details",
            )
            return None
        child_conn.close()
        return Attempt(
            job=job,
            process=process,
            conn=parent_conn,
            work_dir=work_dir,
            started_monotonic=started,
            started_wall=started_wall,
            queued_ms=max(0.0, ((job.started_s or time.time()) - job.created_s) * 1e3),
        )

    def step(self, a: Attempt) -> bool:
        """Read the attempt's messages, end its process when the job was cancelled, taken over
        or ran too long, and record the outcome once the process ended (again later while the
        store is down). True when it is over and recorded."""
        if a.record is None:
            self._read_messages(a)
            now = time.monotonic()
            if a.stop_reason is None and now >= a.next_check:
                a.next_check = now + POLL_S
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
            a.conn.close()
            a.record = self._outcome(a)
        if not self._store_call(a, a.record):
            return False
        shutil.rmtree(a.work_dir, ignore_errors=True)  # gone when it became the result
        return True

    def run(self, job: Job, stopping: threading.Event, hand_back: Callable[[], bool]) -> None:
        """Run a claimed job to its end in this thread (a queue worker's). When `stopping` is set
        first, the process is ended, `hand_back()` sends the job's message again (False: it
        could not; NotHandedBack is raised after the record was requeued) and the record is
        queued again, the attempt not counted."""
        a = self.launch(job)
        if a is None:
            return
        try:
            while not self.step(a):
                if stopping.is_set():
                    self.end([a], before_requeue=hand_back)
                    return
                multiprocessing.connection.wait(a.waitables(), timeout=POLL_S)
        except BaseException:
            self._abandon(a)  # no process or folder outlives an error here
            raise

    def end(self, attempts: list[Attempt], before_requeue: Callable[[], bool] | None = None) -> None:
        """Shutdown: end the attempts' processes (SIGTERM, SIGKILL after `cancel_grace_s`) and
        queue their jobs again without counting the attempt (`before_requeue()` first: False
        when it failed, and NotHandedBack is raised once the record was requeued). An attempt
        whose outcome waits for the store is recorded now if the store answers; one whose record
        cannot be requeued (the store down) is left `running`, for the message sent back to take
        over uncounted (records.py, "Claims")."""
        for a in attempts:
            if a.process.is_alive():
                a.process.terminate()
        deadline = time.monotonic() + self.settings.cancel_grace_s
        for a in attempts:
            a.store_back_at = 0.0  # one last try, whatever the backoff
            if a.record is not None and self.step(a):
                continue
            self._abandon(a, deadline)
            handed_back = True
            if before_requeue is not None:
                handed_back = bool(before_requeue())
            try:
                self.store.requeue(a.job.id, uncount_attempt=True, attempt=a.job.attempts)
            except JobsUnavailable as exc:
                log.warning("job %s: not requeued: %s", a.job.id, exc)
            if not handed_back:
                raise NotHandedBack(a.job.id)

    @staticmethod
    def _abandon(a: Attempt, deadline: float = 0.0) -> None:
        """End the attempt's process (SIGKILL past `deadline`, a time.monotonic()) and remove
        its work folder."""
        if a.process.is_alive():
            a.process.terminate()
        a.process.join(max(0.0, deadline - time.monotonic()))
        if a.process.is_alive():
            a.process.kill()
            a.process.join()
        a.conn.close()
        shutil.rmtree(a.work_dir, ignore_errors=True)

    def _store_call(self, a: Attempt, call: Callable[[], object]) -> bool:
        """Run `call` (a store call of this attempt) unless the store was found down and its wait
        has not passed. False when the store is down: the wait before the next try doubles, up
        to RECORD_RETRY_S[1], and the outage is logged once."""
        now = time.monotonic()
        if now < a.store_back_at:
            return False
        try:
            call()
        except JobsUnavailable as exc:
            if a.store_wait_s == 0.0:
                log.warning("job %s: %s; it runs on and its outcome is recorded when the store is back", a.job.id, exc)
            a.store_wait_s = min(max(a.store_wait_s * 2, RECORD_RETRY_S[0]), RECORD_RETRY_S[1])
            a.store_back_at = now + a.store_wait_s
            return False
        if a.store_wait_s:
            log.info("job %s: the job store answers again", a.job.id)
        a.store_wait_s = 0.0
        return True

    def _stop_reason(self, a: Attempt, now: float) -> str | None:
        found: list[Job | None] = []

        def look() -> None:
            try:
                found.append(self.store.get(a.job.id))
            except JobNotFound:
                found.append(None)

        token = a.job.claimed_by
        if token is not None and now >= a.next_renew:
            a.next_renew = now + self.settings.worker_heartbeat_timeout_s / 4
            self._store_call(a, lambda: self.store.renew(a.job.id, token))  # whether it still holds: `look` says
        if self._store_call(a, look):  # the store down: only the timeout can stop the job
            current = found[0]
            if current is None:
                return "superseded"
            if current.state is JobState.CANCELLED:
                return "cancelled"
            if current.state is not JobState.RUNNING or (current.attempts, current.claimed_by) != (a.job.attempts, token):
                return "superseded"  # another worker took over this job after a redelivery
        if now - a.started_monotonic > self.settings.job_timeout_s:
            return "timeout"
        return None

    def _read_messages(self, a: Attempt) -> None:
        """Take the process's messages; the latest progress is written once (skipped while the
        store is down: the outcome sets it)."""
        progress = None
        with contextlib.suppress(EOFError, OSError):
            while a.conn.poll():
                kind, value = a.conn.recv()
                if kind == "progress":
                    progress = value
                elif kind == "started":
                    a.process_start_ms = max(0.0, (value - a.started_wall) * 1e3)
                else:
                    a.outcome = (kind, value)
        if progress is not None:
            self._store_call(a, lambda: self.store.set_progress(a.job.id, progress, attempt=a.job.attempts))

    def _outcome(self, a: Attempt) -> Callable[[], object]:
        """What to record of the ended process: a store call that may be made again (the
        compare-and-set on the attempt changes nothing the second time)."""
        job_id, attempt = a.job.id, a.job.attempts
        run_ms = (time.monotonic() - a.started_monotonic) * 1e3
        succeeded = a.stop_reason is None and a.outcome is not None and a.outcome[0] == "ok"
        if not succeeded:  # nothing of the folder is kept: gone before the record says the job ended
            shutil.rmtree(a.work_dir, ignore_errors=True)
        if a.stop_reason in ("cancelled", "superseded"):
            return lambda: None
        if a.stop_reason == "timeout":
            error = f"timed out after {self.settings.job_timeout_s:g} s"
            return lambda: self.store.finish(job_id, JobState.FAILED, only_if=JobState.RUNNING, attempt=attempt, error=error)
        if succeeded:
            assert a.outcome is not None  # for mypy: `succeeded` says so
            timings = dict(a.outcome[1])
            timings["queued"] = a.queued_ms
            timings["job_process_total"] = run_ms
            if a.process_start_ms is not None:
                timings["job_process_start"] = a.process_start_ms
            return lambda: self._publish(a, timings)
        if a.outcome is not None:
            error = str(a.outcome[1])
        else:
            error = f"the job process exited with code {a.process.exitcode} without a result"
        failed_timings = {"job_process_total": run_ms, "queued": a.queued_ms}
        return lambda: self.store.finish(
            job_id, JobState.FAILED, error=error, only_if=JobState.RUNNING, attempt=attempt, timings_ms=failed_timings
        )

    def _publish(self, a: Attempt, timings: dict[str, float]) -> None:
        """Succeed the attempt and rename its folder to `<id>/result/` in one transaction; an
        attempt that was cancelled or taken over meanwhile changes nothing. Called again after
        the store was down: a folder already moved is not moved again, and is removed when the
        record, once readable, shows the job did not succeed (the commit was lost, and the job
        was cancelled since)."""
        result = self.store.result_dir(a.job.id)

        def rename() -> None:
            if a.moved:
                return
            shutil.rmtree(result, ignore_errors=True)  # a folder left by a rolled-back attempt
            os.rename(a.work_dir, result)
            a.moved = True

        try:
            changed = self.store.finish(
                a.job.id, JobState.SUCCEEDED, timings_ms=timings, only_if=JobState.RUNNING, attempt=a.job.attempts, publish=rename
            )
            if a.moved and not changed:
                with contextlib.suppress(JobNotFound):
                    if self.store.get(a.job.id).state is JobState.SUCCEEDED:
                        return
                shutil.rmtree(result, ignore_errors=True)
        except OSError as exc:  # the rename failed: the transaction was rolled back
            log.error("job %s: cannot store the result: %s", a.job.id, exc)  # names paths: the log's, not the client's
            self.store.finish(
                a.job.id,
                JobState.FAILED,
                only_if=JobState.RUNNING,
                attempt=a.job.attempts,
                error=f"cannot store the result ({type(exc).__name__}); the server's log has the details",
            )


# -- the local runner ---------------------------------------------------------------------------
