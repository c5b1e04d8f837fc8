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
    QueueWorker     `camdirector job-worker` (queue_worker.py): Dramatiq worker threads, one per
                    concurrent job; each claims the record its message names and runs the job in a
                    job process (executor.JobExecutor), as the front's local runner does

Redelivery and exactly-once: a message is acknowledged only after its job ended, so the job of a
worker killed mid-run stays in that worker's acknowledgement set and is queued again once the
worker has been silent `worker_heartbeat_timeout_s`; a surviving worker takes it at its next job.
Every worker beats and runs the maintenance step every quarter of that timeout from a thread of its
own (`broker.do_qsize` on the jobs queue: the broker's consumers stop beating on a queue while their
worker is busy). The new attempt claims the record (attempts + 1), unless the holder's lease in the record store
is fresh (records.py, "Claims": a live worker that Redis lost sight of), when the message waits
instead; only the latest attempt may record an outcome (compare-and-set, records.py), so a worker
that was only slow, not dead, finds its job taken over, ends its process and records nothing. A
job interrupted `max_attempts` times fails.
Cancel: the record is cancelled; the worker running it sees that within 0.25 s and ends the
process; a queued job's message is dropped when it comes.

Each worker fetches only as many messages as it runs jobs (prefetch = concurrency): a busy worker
never holds a job that an idle one could run, and a killed worker holds only the jobs it ran.

Failures: Redis or PostgreSQL unreachable at start: `JobsUnavailable`, one line (the node refuses
to start). Redis down at a submit: the job is failed ("could not be queued") and the submit raises
JobsUnavailable (HTTP 503). PostgreSQL down while a worker takes a message: the worker asks again
until it answers (queue_worker.py), keeping the message. Redis keeps the queue
in memory: a Redis that restarts without persistence loses queued messages (their records stay
queued); run the queue's Redis with `appendonly yes` in production. PostgreSQL down while a job
runs: the job runs on and its outcome is recorded when the store is back (executor.py), its
attempt counted once. Every Redis call is bounded: the connect (REDIS_CONNECT_TIMEOUT_S), each
reply (REDIS_READ_TIMEOUT_S) and a silent peer (TCP keepalives, REDIS_KEEPALIVE).
"""

from __future__ import annotations

import logging
import socket
from pathlib import Path

import dramatiq
import redis
from dramatiq.brokers.redis import MAINTENANCE_SCALE, RedisBroker
from dramatiq.middleware import Retries

from camdirector.infra.host_address import redis_pool
from camdirector.infra.redaction import redacted
from camdirector.jobs.job_settings import JobSettings
from camdirector.jobs.kinds import JobRegistry
from camdirector.jobs.records import Job, JobState, JobsUnavailable, open_store

log = logging.getLogger("camdirector.jobs.queue")

QUEUE_NAME = "camdirector-jobs"
ACTOR_NAME = "camdirector_run_job"
STORE_RETRIES = 100  # times a message is retried when the record store fails past its claim (a launch that cannot record)
_RETRY_BACKOFF_MS = (1000, 30_000)
REDIS_CONNECT_TIMEOUT_S = 5.0  # a connection to Redis not made in this long: the queue is down, s
REDIS_READ_TIMEOUT_S = 5.0  # a command's reply not read in this long: the queue is down (none of ours blocks), s
# TCP keepalive of an idle connection: first probe after 5 s, then every 2 s, dropped after 3 unanswered.
REDIS_KEEPALIVE = {socket.TCP_KEEPIDLE: 5, socket.TCP_KEEPINTVL: 2, socket.TCP_KEEPCNT: 3}
REDIS_HEALTH_CHECK_S = 15  # a connection idle this long is checked with a PING before it is used, s


def redis_reason(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def broker_for(settings: JobSettings, *, worker: bool) -> RedisBroker:
    """A Redis broker for `settings.job_queue`, checked with a PING (JobsUnavailable when Redis
    does not answer). Only workers run the maintenance step that requeues dead workers' messages
    (a client's heartbeat timeout is not the workers')."""
    url = settings.job_queue
    # the pool made here, not from `url` by Dramatiq, which would drop these bounds; its host name
    # looked up off the calls' path (infra/host_address.py)
    pool, _ = redis_pool(
        url,
        socket_connect_timeout=REDIS_CONNECT_TIMEOUT_S,
        socket_timeout=REDIS_READ_TIMEOUT_S,
        socket_keepalive=True,
        socket_keepalive_options=REDIS_KEEPALIVE,
        health_check_interval=REDIS_HEALTH_CHECK_S,
    )
    broker = RedisBroker(
        connection_pool=pool,
        middleware=[Retries(min_backoff=_RETRY_BACKOFF_MS[0], max_backoff=_RETRY_BACKOFF_MS[1])] if worker else [],
        heartbeat_timeout=int(settings.worker_heartbeat_timeout_s * 1000),
        maintenance_chance=MAINTENANCE_SCALE if worker else 0,
    )
    try:
        broker.client.ping()
    except redis.RedisError as exc:
        raise JobsUnavailable(f"job queue {redacted(url)} is unreachable: {redis_reason(exc)}") from None
    return broker


class QueueClient:
    """The front's jobs in queue mode: the same calls as `JobRunner` (submit, get, cancel,
    result_dir, store, add_kind, start, close), with jobs run by queue workers on any node."""

    def __init__(self, data_dir: str | Path, registry: JobRegistry, settings: JobSettings) -> None:
        self.settings = settings
        self.registry = registry
        self.store = open_store(settings.job_store, Path(data_dir) / "jobs")
        try:
            self._broker = broker_for(settings, worker=False)
        except JobsUnavailable:
            self.store.close()
            raise
        self._actor = dramatiq.actor(broker=self._broker, actor_name=ACTOR_NAME, queue_name=QUEUE_NAME)(_unbound_job_message)

    def start(self) -> None:
        """Nothing runs here: the constructor has checked Redis and PostgreSQL."""

    def close(self) -> None:
        self._broker.client.close()
        self.store.close()

    def submit(
        self, kind: str, params: dict, files: dict[str, bytes], tenant: str = "default", idempotency_key: str | None = None
    ) -> Job:
        """Record a job of `tenant` and queue its message (none for a replayed submit: records.py,
        "Idempotency"). Raises KeyError for an unknown kind, QueueFull when `max_queued_jobs` jobs
        are queued on the whole cluster, TenantLimitReached beyond the tenant's share
        (JobSettings), IdempotencyConflict, JobsUnavailable when Redis does not take the message
        (the job is failed then)."""
        self.registry.get(kind)
        job = self.store.submit(
            kind, params, files, tenant=tenant, idempotency_key=idempotency_key, **self.settings.submit_limits()
        )
        if job.replayed:
            return job
        try:
            self._actor.send(job.id)
        except redis.RedisError as exc:
            # the job's error is the client's to read: it names no URL or host (the log does)
            self.store.finish(
                job.id,
                JobState.FAILED,
                error="could not be queued: the job queue is unreachable",
                only_if=JobState.QUEUED,
                forget_key=True,
            )
            raise JobsUnavailable(f"job queue {redacted(self.settings.job_queue)} is unreachable: {redis_reason(exc)}") from None
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
