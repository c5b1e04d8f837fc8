"""What every job resource's routes share: the status models, submitting, looking up, listing and
cancelling a job of one kind, and the answer when the job store or queue is down (one runner, or one
queue client, and one job store serve every kind). The routes are the same in
both modes (jobs/__init__.py): `Jobs` is either.

Every job belongs to the tenant of the key that submitted it: a route's caller sees, cancels and
fetches only its tenant's jobs, and another tenant's job answers 404 with the words an unknown id
gets (access/roles.py)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Annotated, Any

from fastapi import FastAPI, Header, HTTPException, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field

from camdirector.front.job_runner import JobRunner
from camdirector.jobs import (
    IdempotencyConflict,
    Job,
    JobNotFound,
    JobState,
    JobsUnavailable,
    QueueClient,
    QueueFull,
    TenantLimitReached,
)

Jobs = JobRunner | QueueClient

# A job POST's optional key: the same key and request again answer the first job (jobs/records.py,
# "Idempotency"), so a client may send again a submit whose answer it lost.
IdempotencyKey = Annotated[
    str | None,
    Header(
        alias="Idempotency-Key",
        min_length=1,
        max_length=128,
        pattern=r"^[\x21-\x7e]+$",
        description=(
            "1-128 printable ASCII characters, new for each new job: sent again with the same request, "
            "the first job is answered (header Idempotent-Replayed: true) and nothing is run twice"
        ),
    ),
]

log = logging.getLogger("camdirector.front.http")


class JobCreated(BaseModel):
    id: str = Field(description="job id")
    status: str = Field(description="queued")


class JobStatus(BaseModel):
    id: str
    status: str = Field(description="queued | running | succeeded | failed | cancelled")
    progress: float = Field(ge=0.0, le=1.0)
    error: str | None = Field(default=None, description="why the job failed or was cancelled")
    timings: dict[str, float] = Field(description="milliseconds per stage (when finished)")
    created_unix_s: float = Field(description="when it was submitted, Unix s")
    started_unix_s: float | None = Field(default=None, description="when its last attempt started, Unix s")
    finished_unix_s: float | None = Field(default=None, description="when it ended, Unix s")


def job_of_kind(runner: Jobs, job_id: str, kind: str, noun: str, tenant: str):
    """The job job_id of `kind` and `tenant`; HTTPException 404 for an unknown id, for a job of
    another kind (one runner and job store serve every kind of job route) and for another
    tenant's job."""
    try:
        job = runner.get(job_id)
    except JobNotFound:
        job = None
    if job is None or job.kind != kind or job.tenant != tenant:
        raise HTTPException(status_code=404, detail=f"no {noun} {job_id!r}")
    return job


async def known_form_fields(request: Request) -> None:
    """A dependency of a job's multipart POST: 422 naming any form field that the route's endpoint
    does not take (a misspelt parameter would otherwise be dropped silently and the job run with
    the default). The form is parsed once: Starlette keeps it for the endpoint's own fields. The
    fields are the endpoint's body parameters, as FastAPI read them (not its dependencies: the
    caller's identity is no form field)."""
    known = {field.alias for field in request.scope["route"].dependant.body_params}
    unknown = sorted(set((await request.form()).keys()) - known)
    if unknown:
        raise HTTPException(
            status_code=422, detail=f"unknown form field(s) {', '.join(unknown)}; this route takes {', '.join(sorted(known))}"
        )


def submit_job(
    runner: Jobs, kind: str, params: dict, files: dict[str, bytes], tenant: str, idempotency_key: str | None = None
) -> Job:
    """POST of a job route: the job queued, `tenant`'s, or the earlier one its `idempotency_key`
    names (`replayed`); HTTPException 429 when the queue is full or the tenant holds its share of
    jobs or uploads (JobSettings), 422 for a key sent before with another request;
    JobsUnavailable (503 through answer_unavailable_jobs) when the job queue cannot take it (the
    job is failed then)."""
    try:
        return runner.submit(kind, params, files, tenant, idempotency_key)
    except IdempotencyConflict as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from None
    except QueueFull as exc:
        raise HTTPException(status_code=429, detail=f"job queue full: {exc}", headers={"Retry-After": "10"}) from None
    except TenantLimitReached as exc:
        raise HTTPException(status_code=429, detail=str(exc), headers={"Retry-After": "10"}) from None


def earlier_job(runner: Jobs, tenant: str, idempotency_key: str | None, kind: str, params: dict, files: dict[str, bytes]):
    """The job an earlier POST with `idempotency_key` made (submit_job's replay, for a route whose
    own checks would refuse the replay); None for a new or absent key; 422 as submit_job."""
    if idempotency_key is None:
        return None
    try:
        return runner.store.earlier_submit(tenant, idempotency_key, kind, params, files)
    except IdempotencyConflict as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from None


def created_headers(job: Job, location: str) -> dict[str, str]:
    """A job POST's 202 headers: where the job is, and whether this answer is a replay."""
    return {"Location": location, **({"Idempotent-Replayed": "true"} if job.replayed else {})}


def answer_unavailable(app: FastAPI, error: type[Exception], what: str, note: Callable[[Any], object] | None = None) -> None:
    """Any route that raises `error` (a database or queue that `what` names is down) answers 503,
    not 500, in words that name no URL, host or path; the reason, the URL's secrets hidden
    (infra/redaction.py), goes to the server's log: per request, or through `note` (given the
    exception) where the store's owner logs it once per outage."""

    async def unavailable(request: Request, exc: Exception) -> JSONResponse:
        if note is None:
            log.warning("%s %s: %s", request.method, request.url.path, exc)
        else:
            note(exc)
        return JSONResponse({"detail": f"{what} is unreachable; retry later"}, status_code=503, headers={"Retry-After": "10"})

    app.add_exception_handler(error, unavailable)


def answer_unavailable_jobs(app: FastAPI) -> None:
    """The job store (PostgreSQL) or queue (Redis) down: 503 (answer_unavailable)."""
    answer_unavailable(app, JobsUnavailable, "the job store or queue")


MAX_LISTED_JOBS = 1000


def list_jobs(
    runner: Jobs, kind: str, status: JobState | None, limit: int, extra: Callable[[dict], dict], tenant: str
) -> list[dict]:
    """GET of a job collection: the newest `limit` jobs of `kind` and `tenant` (in `status` when
    given), each its public view with `extra(params)` added (finished jobs are kept
    `job_retention_s`)."""
    return [
        {**j.as_public(), **extra(j.params)}
        for j in runner.store.list(status, kind=kind, tenant=tenant, limit=limit, newest_first=True)
    ]


def cancel_job(runner: Jobs, job_id: str, noun: str = "job"):
    """DELETE of a job route: the job cancelled (a running job's process is ended), unchanged when
    it was cancelled already; HTTPException 409 when it had succeeded or failed. Cancels first and
    looks after, so a job that finishes meanwhile answers 409, not a 200 that did nothing."""
    job = runner.cancel(job_id)
    if job.state in (JobState.SUCCEEDED, JobState.FAILED):
        raise HTTPException(status_code=409, detail=f"{noun} {job_id} already {job.state.value}")
    return job
