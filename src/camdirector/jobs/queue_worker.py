"""A queue worker process's main loop (`camdirector job-worker`): the jobs of the shared queue
(queue.py's module docstring: redelivery, heartbeats, exactly-once), each run in a job process by
the executor (executor.py), with the service's job kinds (kinds.py).
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import dramatiq
import redis

from camdirector.infra.private_files import make_private
from camdirector.infra.redaction import redacted
from camdirector.jobs.executor import PURGE_INTERVAL_S, RECORD_RETRY_S, JobExecutor, NotHandedBack, purge_expired
from camdirector.jobs.job_settings import JobSettings
from camdirector.jobs.kinds import JobRegistry, service_kinds
from camdirector.jobs.queue import ACTOR_NAME, QUEUE_NAME, STORE_RETRIES, broker_for, redis_reason
from camdirector.jobs.records import Job, JobHeldElsewhere, JobStore, JobsUnavailable, open_store

log = logging.getLogger("camdirector.jobs")

# Orphaned files (a folder without a record, an abandoned .tmp-*) are removed by queue workers only
# once untouched this long past the job timeout: other nodes submit and run jobs meanwhile, s.
_ORPHAN_GRACE_S = 3600.0
HAND_BACK_S = 5.0  # a stopping worker tries this long to send its job's message back to a queue that is down, s


class QueueWorker:
    """`camdirector job-worker`'s body: Dramatiq worker threads (`max_concurrent_jobs`) that run
    the jobs of the queue in job processes, a heartbeat thread, retention. Blocks in `run()`
    until `stop()` (SIGTERM, SIGINT); running jobs go back to the queue, their attempt not counted."""

    def __init__(
        self,
        data_dir: str | Path,
        settings: JobSettings,
        registry: JobRegistry | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.settings = settings
        self._clock = clock  # Unix seconds, for the retention of finished jobs
        self.store: JobStore = open_store(settings.job_store, Path(data_dir) / "jobs")
        try:
            self._broker = broker_for(settings, worker=True)
        except JobsUnavailable:
            self.store.close()
            raise
        self._executor = JobExecutor(self.store, service_kinds() if registry is None else registry, settings)
        self._actor = dramatiq.actor(
            broker=self._broker,
            actor_name=ACTOR_NAME,
            queue_name=QUEUE_NAME,
            retry_when=_retry_when,
        )(self._run_message)
        self._stopping = threading.Event()
        self.worker_id = self._broker.broker_id

    def run(self, ready: Callable[[], None] = lambda: None) -> None:
        """Start the forkserver and the worker threads, call `ready`, beat until `stop()`."""
        self._executor.start()
        beat_s = self.settings.worker_heartbeat_timeout_s / 4
        worker = dramatiq.Worker(
            self._broker, worker_threads=self.settings.max_concurrent_jobs, worker_timeout=int(min(1.0, beat_s) * 1000)
        )
        # Dramatiq prefetches twice its threads by default; a message fetched is a job this worker
        # holds (and loses when killed), so fetch only what runs (module docstring).
        worker.queue_prefetch = self.settings.max_concurrent_jobs
        worker.start()
        log.info(
            "queue worker %s: %d job(s) at a time from %s",
            self.worker_id,
            self.settings.max_concurrent_jobs,
            redacted(self.settings.job_queue),
        )
        ready()
        next_purge = 0.0
        try:
            while not self._stopping.wait(beat_s):
                self._beat()
                if time.monotonic() >= next_purge:
                    next_purge = time.monotonic() + PURGE_INTERVAL_S
                    try:
                        purge_expired(self.store, self.settings, self._clock())
                        self.store.remove_orphans(self.settings.job_timeout_s + _ORPHAN_GRACE_S)
                    except JobsUnavailable as exc:  # the store down stops no worker: retried next interval
                        log.warning("retention: %s", exc)
        finally:
            worker.stop(timeout=int((self.settings.cancel_grace_s + 10.0) * 1000))
            self._broker.client.close()
            self.store.close()

    def stop(self) -> None:
        self._stopping.set()

    def _beat(self) -> None:
        """Heartbeat and maintenance on the jobs queue (module docstring): a dead worker's jobs
        come back even while every consumer of this worker is busy."""
        try:
            self._broker.do_qsize(QUEUE_NAME)
        except redis.RedisError as exc:
            log.warning("job queue %s: %s", redacted(self.settings.job_queue), redis_reason(exc))

    def _run_message(self, job_id: str, handed_back_from: str | None = None) -> None:
        """One delivery of a job's message: claim its job under a token of this delivery and run
        it here (records.py, "Claims"; `handed_back_from`: the token of the worker that sent it
        back when it stopped). When this worker stops first, the message is sent again, carrying
        the token, before the record goes back to queued, so neither is ever lost and the attempt
        is not counted even when the record cannot be requeued. When the message cannot be sent
        again (Redis down too), this delivery is never acknowledged: the broker sends it again
        once this worker is gone."""
        token = f"{self.worker_id}/{uuid.uuid4().hex}"
        try:
            job = self._claim(job_id, token, handed_back_from)
            if job is None:
                return
            log.info("job %s (%s): attempt %d on worker %s", job.id, job.kind, job.attempts, self.worker_id)
            self._executor.run(job, self._stopping, hand_back=lambda: self._hand_back(job_id, token))
        except JobHeldElsewhere as exc:
            # not an error (Dramatiq logs a Retry quietly): back when the lease of a dead holder ran out
            log.info("%s: its message is tried again later", exc)
            raise dramatiq.Retry(str(exc), delay=int(self.settings.worker_heartbeat_timeout_s * 500)) from None
        except NotHandedBack:
            log.error("job %s: could not be sent back to the queue; it runs again once this worker is gone", job_id)
            threading.Event().wait()  # a daemon thread: the process ends without acknowledging it

    def _claim(self, job_id: str, token: str, handed_back_from: str | None) -> Job | None:
        """The claim, asked again while the store is down (doubling up to RECORD_RETRY_S[1]):
        a claim whose commit was made but whose reply was lost is found again by its token,
        where a delivery retried later would count a second attempt. The worker stopping
        meanwhile sends the message back and claims nothing."""
        wait_s = 0.0
        while True:
            try:
                return self.store.claim(
                    job_id,
                    self.settings.max_attempts,
                    token=token,
                    lease_timeout_s=self.settings.worker_heartbeat_timeout_s,
                    handed_back_from=handed_back_from,
                )
            except JobsUnavailable as exc:
                if wait_s == 0.0:
                    log.warning("job %s: cannot claim it: %s; asked again until the store answers", job_id, exc)
                wait_s = min(max(2 * wait_s, RECORD_RETRY_S[0]), RECORD_RETRY_S[1])
                if self._stopping.wait(wait_s):
                    if not self._hand_back(job_id, token):
                        raise NotHandedBack(job_id) from None
                    return None

    def _hand_back(self, job_id: str, token: str) -> bool:
        """The job's message sent again, carrying `token`; False when Redis does not take it
        within HAND_BACK_S."""
        deadline = time.monotonic() + HAND_BACK_S
        while True:
            try:
                self._actor.send(job_id, token)
                return True
            except redis.RedisError as exc:
                if time.monotonic() > deadline:
                    log.warning("job %s: not sent back to the queue: %s", job_id, redis_reason(exc))
                    return False
                time.sleep(0.5)


def _retry_when(retries: int, exc: Exception) -> bool:
    """Dramatiq's retry rule for a job's message: a duplicate of a job another worker runs
    (dramatiq.Retry), as long as it runs; the store down, up to STORE_RETRIES times."""
    if isinstance(exc, dramatiq.Retry):
        return True
    return isinstance(exc, JobsUnavailable) and retries < STORE_RETRIES


def run_job_worker(data_dir: str | Path, settings: JobSettings) -> int:
    """`camdirector job-worker`: run a QueueWorker until SIGTERM or SIGINT. Prints one JSON line
    when ready ({"event": "ready", "worker": id}); refuses to start (one line on stderr, exit 2)
    when Redis or PostgreSQL cannot be reached."""
    import json
    import sys

    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        make_private(data_dir)  # before the job store and the forkserver: its job processes inherit the umask
        worker = QueueWorker(data_dir, settings)
    except (JobsUnavailable, OSError) as exc:
        print(f"camdirector job-worker: {exc}", file=sys.stderr)
        return 2
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: worker.stop())
    with contextlib.suppress(KeyboardInterrupt):
        worker.run(lambda: print(json.dumps({"event": "ready", "worker": worker.worker_id}), flush=True))
    return 0
