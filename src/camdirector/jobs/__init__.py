"""Offline jobs (motion overviews, level precompute): records, files, and where they run.

Two modes, one REST API (front/http/routes/job_resources.py and the routes of each kind):

    local (job_queue = "")       one node: the front's own JobRunner runs the jobs
                                 (front/job_runner.py)
    queue (job_queue = redis://) many nodes: fronts record jobs and queue a message (queue.py);
                                 queue workers (`camdirector job-worker`, queue_worker.py) on any
                                 node run them

Either way a job runs in a job process (main.py) started and followed by the executor
(executor.py); the kinds a job may be are listed once, in kinds.py.

Records (records.py) are SQLite in the data directory by default, or PostgreSQL
(`job_store = postgresql://...`), which the nodes of a cluster share. Files are under
`<data_dir>/jobs/`, a folder every node mounts at the same path (level jobs write to the data
directory they were submitted with):

    jobs.sqlite3            the SQLite records (WAL journal), when job_store is empty
    runner.lock             held (flock) by the one local runner that owns this folder
    <id>/input/             the job's uploaded files, written before the record exists
    <id>/result/            what the job produced, renamed into place only when it succeeded
    .tmp-*/                 work in progress; anything left here after a crash is removed

Nothing is half-written: inputs are written into `.tmp-*` and renamed to `<id>/` inside the
transaction that inserts the record (a failed insert removes them); a job writes its results into
`.tmp-*` and the executor renames that folder to `<id>/result/` inside the transaction that marks
its attempt succeeded.

States: queued -> running -> succeeded | failed | cancelled (queued -> cancelled too).
"""

from camdirector.jobs.executor import JobExecutor
from camdirector.jobs.job_settings import JobSettings
from camdirector.jobs.kinds import JobKind, JobRegistry, service_kinds
from camdirector.jobs.queue import QueueClient
from camdirector.jobs.queue_worker import QueueWorker, run_job_worker
from camdirector.jobs.records import (
    IdempotencyConflict,
    Job,
    JobHeldElsewhere,
    JobNotFound,
    JobState,
    JobStore,
    JobsUnavailable,
    PostgresJobStore,
    QueueFull,
    SqliteJobStore,
    TenantLimitReached,
    open_store,
)

__all__ = [
    "IdempotencyConflict",
    "Job",
    "JobExecutor",
    "JobKind",
    "JobNotFound",
    "JobRegistry",
    "JobSettings",
    "JobState",
    "JobStore",
    "JobHeldElsewhere",
    "JobsUnavailable",
    "PostgresJobStore",
    "QueueClient",
    "QueueFull",
    "QueueWorker",
    "SqliteJobStore",
    "TenantLimitReached",
    "open_store",
    "run_job_worker",
    "service_kinds",
]
