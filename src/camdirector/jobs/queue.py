"""Jobs on a distributed queue: Dramatiq over Redis, for many nodes (`job_queue = redis://...`).

Why Dramatiq (of Celery, RQ and Dramatiq, all on PyPI and well kept): its Redis broker moves a
fetched message into an acknowledgement set of the worker that fetched it, every worker beats into
a heartbeat set on every command, and the broker's maintenance step puts the unacknowledged
messages of a worker silent for `heartbeat_timeout` back on their queue. So a job whose worker
died is run again after a timeout we set (`worker_heartbeat_timeout_s`, seconds in the tests), the
same for a 2 s job as for a 2 h one. Celery's Redis transport redelivers only after its
`visibility_timeout`, which also redelivers a job that is still running once it runs longer than
that, so it must exceed the longest job (an hour by default). RQ moves a dead worker's job from
its StartedJobRegistry after the job's heartbeat TTL, its monitoring interval plus a fixed 60 s,
and then to the FailedJobRegistry unless the job carries a Retry.

Roles:

    QueueClient     the front's jobs (`serve --job-queue`): records the job (record store,
                    files in the shared data directory), then sends one message naming it
    run_queue_worker  `camdirector job-worker`: Dramatiq worker threads, one per concurrent job;
                    each claims the record its message names and runs the job in a job process
                    (runner.JobExecutor), as the local runner does

Redelivery and exactly-once: a message is acknowledged only after its job ended, so the job of a
worker killed mid-run stays in that worker's acknowledgement set and is queued again once the
worker has been silent `worker_heartbeat_timeout_s`; a surviving worker takes it at its next job.
Every worker beats and runs the maintenance step every quarter of that timeout from a thread of its
own (`broker.do_qsize` on the jobs queue: the broker's consumers stop beating on a queue while their
worker is busy). The new attempt claims the record (attempts + 1); only the latest attempt may record
an outcome (compare-and-set, records.py), so a worker that was only slow, not dead, finds its job
taken over, ends its process and records nothing. A job interrupted `max_attempts` times fails.
Cancel: the record is cancelled; the worker running it sees that within 0.25 s and ends the
process; a queued job's message is dropped when it comes.

Each worker fetches only as many messages as it runs jobs (prefetch = concurrency): a busy worker
never holds a job that an idle one could run, and a killed worker holds only the jobs it ran.

Failures: Redis or PostgreSQL unreachable at start: `JobsUnavailable`, one line (the node refuses
to start). Redis down at a submit: the job is failed ("could not be queued") and the submit raises
JobsUnavailable (HTTP 503). PostgreSQL down while a worker takes a message: the message is retried
with Dramatiq's Retries (backoff 1 s to 30 s, up to `_STORE_RETRIES` times). Redis keeps the queue
in memory: a Redis that restarts without persistence loses queued messages (their records stay
queued); run the queue's Redis with `appendonly yes` in production.
"""
from __future__ import annotations

import contextlib
import logging
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import dramatiq
import redis
from dramatiq.brokers.redis import MAINTENANCE_SCALE, RedisBroker
from dramatiq.middleware import Retries

from camdirector.jobs.records import Job, JobState, JobStore, JobsUnavailable, open_store
from camdirector.jobs.runner import (
    PURGE_INTERVAL_S,
    JobExecutor,
    JobKind,
    JobRegistry,
    JobRunner,
    JobSettings,
    purge_expired,
)

log = logging.getLogger("camdirector.jobs.queue")

QUEUE_NAME = "camdirector-jobs"
ACTOR_NAME = "camdirector_run_job"
_STORE_RETRIES = 100             # times a message is retried while the record store is unreachable
_RETRY_BACKOFF_MS = (1000, 30_000)
# Orphaned files (a folder without a record, an abandoned .tmp-*) are removed by queue workers only
# once untouched this long past the job timeout: other nodes submit and run jobs meanwhile, s.
_ORPHAN_GRACE_S = 3600.0


def _redis_reason(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def _broker(settings: JobSettings, *, worker: bool) -> RedisBroker:
    """A Redis broker for `settings.job_queue`, checked with a PING (JobsUnavailable when Redis
    does not answer). Only workers run the maintenance step that requeues dead workers' messages
    (a client's heartbeat timeout is not the workers')."""
    url = settings.job_queue
    broker = RedisBroker(url=url, middleware=[Retries(min_backoff=_RETRY_BACKOFF_MS[0],
                                                      max_backoff=_RETRY_BACKOFF_MS[1])] if worker else [],
                         heartbeat_timeout=int(settings.worker_heartbeat_timeout_s * 1000),
                         maintenance_chance=MAINTENANCE_SCALE if worker else 0,
                         socket_connect_timeout=5, socket_timeout=30)
    try:
        broker.client.ping()
    except redis.RedisError as exc:
        raise JobsUnavailable(f"job queue {url} is unreachable: {_redis_reason(exc)}") from None
    return broker


def builtin_kinds() -> tuple[tuple[JobKind, str], ...]:
    """Every job kind of the REST API with its module (the forkserver preloads it): what a queue
    worker runs."""
    from camdirector.precompute.overview import job as overview_job
    from camdirector.precompute.tracks import job as level_job

    return ((JobKind(overview_job.KIND, overview_job.run_overview_job), overview_job.__name__),
            (JobKind(level_job.KIND, level_job.run_level_job), level_job.__name__))


class QueueClient:
    """The front's jobs in queue mode: the same calls as `JobRunner` (submit, get, cancel,
    result_dir, store, add_kind, start, close), with jobs run by queue workers on any node."""

    def __init__(self, data_dir: str | Path, registry: JobRegistry, settings: JobSettings) -> None:
        self.settings = settings
        self.registry = registry
        self.store = open_store(settings.job_store, Path(data_dir) / "jobs")
        try:
            self._broker = _broker(settings, worker=False)
        except JobsUnavailable:
            self.store.close()
            raise
        self._actor = dramatiq.actor(_unbound_job_message, broker=self._broker, actor_name=ACTOR_NAME,
                                     queue_name=QUEUE_NAME)

    def add_kind(self, kind: JobKind, preload: str | None = None) -> None:
        """Accept submits of one more kind (the workers run it; preload is theirs)."""
        self.registry.register(kind)

    def start(self) -> None:
        """Nothing runs here: the constructor has checked Redis and PostgreSQL."""

    def close(self) -> None:
        self._broker.client.close()
        self.store.close()

    def submit(self, kind: str, params: dict, files: dict[str, bytes]) -> Job:
        """Record a job and queue its message. Raises KeyError for an unknown kind, QueueFull
        when `max_queued_jobs` jobs are queued on the whole cluster, JobsUnavailable when Redis
        does not take the message (the job is failed then)."""
        self.registry.get(kind)
        job = self.store.submit(kind, params, files, max_queued=self.settings.max_queued_jobs)
        try:
            self._actor.send(job.id)
        except redis.RedisError as exc:
            reason = f"job queue {self.settings.job_queue} is unreachable: {_redis_reason(exc)}"
            self.store.finish(job.id, JobState.FAILED, error=f"could not be queued: {reason}",
                              only_if=JobState.QUEUED)
            raise JobsUnavailable(reason) from None
        return job

    def get(self, job_id: str) -> Job:
        return self.store.get(job_id)

    def cancel(self, job_id: str) -> Job:
        return self.store.cancel(job_id)

    def result_dir(self, job_id: str) -> Path:
        return self.store.result_dir(job_id)


def _unbound_job_message(job_id: str) -> None:
    """The actor as the client declares it: it only sends (workers declare their own)."""
    raise RuntimeError("job messages run in `camdirector job-worker`, not in the front")


def open_jobs(data_dir: str | Path, registry: JobRegistry, settings: JobSettings, *,
              preload: tuple[str, ...] = ()) -> JobRunner | QueueClient:
    """The front's jobs: this process's own runner when `settings.job_queue` is empty, else a
    client of the queue. Raises JobsUnavailable when Redis or PostgreSQL cannot be reached."""
    if settings.job_queue:
        return QueueClient(data_dir, registry, settings)
    return JobRunner(data_dir, registry, settings, preload=preload)


class QueueWorker:
    """`camdirector job-worker`'s body: Dramatiq worker threads (`max_concurrent_jobs`) that run
    the jobs of the queue in job processes, a heartbeat thread, retention. Blocks in `run()`
    until `stop()` (SIGTERM, SIGINT); running jobs go back to the queue, their attempt not counted."""

    def __init__(self, data_dir: str | Path, settings: JobSettings,
                 kinds: tuple[tuple[JobKind, str], ...] | None = None,
                 clock: Callable[[], float] = time.time) -> None:
        kinds = builtin_kinds() if kinds is None else kinds
        self.settings = settings
        self._clock = clock       # Unix seconds, for the retention of finished jobs
        self.store: JobStore = open_store(settings.job_store, Path(data_dir) / "jobs")
        try:
            self._broker = _broker(settings, worker=True)
        except JobsUnavailable:
            self.store.close()
            raise
        self._executor = JobExecutor(self.store, JobRegistry(tuple(k for k, _ in kinds)), settings,
                                     tuple(module for _, module in kinds))
        self._actor = dramatiq.actor(self._run_message, broker=self._broker, actor_name=ACTOR_NAME,
                                     queue_name=QUEUE_NAME,
                                     retry_when=lambda retries, exc: isinstance(exc, JobsUnavailable)
                                     and retries < _STORE_RETRIES)
        self._stopping = threading.Event()
        self.worker_id = self._broker.broker_id

    def run(self, ready: Callable[[], None] = lambda: None) -> None:
        """Start the forkserver and the worker threads, call `ready`, beat until `stop()`."""
        self._executor.start()
        beat_s = self.settings.worker_heartbeat_timeout_s / 4
        worker = dramatiq.Worker(self._broker, worker_threads=self.settings.max_concurrent_jobs,
                                 worker_timeout=int(min(1.0, beat_s) * 1000))
        # Dramatiq prefetches twice its threads by default; a message fetched is a job this worker
        # holds (and loses when killed), so fetch only what runs (module docstring).
        worker.queue_prefetch = self.settings.max_concurrent_jobs
        worker.start()
        log.info("queue worker %s: %d job(s) at a time from %s", self.worker_id,
                 self.settings.max_concurrent_jobs, self.settings.job_queue)
        ready()
        next_purge = 0.0
        try:
            while not self._stopping.wait(beat_s):
                self._beat()
                if time.monotonic() >= next_purge:
                    purge_expired(self.store, self.settings, self._clock())
                    self.store.remove_orphans(self.settings.job_timeout_s + _ORPHAN_GRACE_S)
                    next_purge = time.monotonic() + PURGE_INTERVAL_S
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
            log.warning("job queue %s: %s", self.settings.job_queue, _redis_reason(exc))

    def _run_message(self, job_id: str) -> None:
        """One message: claim its job and run it here; when this worker stops first, the message
        is sent again before the record goes back to queued, so neither is ever lost."""
        job = self.store.claim(job_id, self.settings.max_attempts)
        if job is None:
            return
        log.info("job %s (%s): attempt %d on worker %s", job.id, job.kind, job.attempts, self.worker_id)
        self._executor.run(job, self._stopping, hand_back=lambda: self._actor.send(job_id))


def run_job_worker(data_dir: str | Path, settings: JobSettings) -> int:
    """`camdirector job-worker`: run a QueueWorker until SIGTERM or SIGINT. Prints one JSON line
    when ready ({"event": "ready", "worker": id}); refuses to start (one line on stderr, exit 2)
    when Redis or PostgreSQL cannot be reached."""
    import json
    import sys

    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        worker = QueueWorker(data_dir, settings)
    except JobsUnavailable as exc:
        print(f"camdirector job-worker: {exc}", file=sys.stderr)
        return 2
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: worker.stop())
    with contextlib.suppress(KeyboardInterrupt):
        worker.run(lambda: print(json.dumps({"event": "ready", "worker": worker.worker_id}), flush=True))
    return 0
