"""REST routes of the level registry (issue 4), and the "level" job kind that precomputes a level.

    POST /v1/levels              multipart: name, level (.obj/.glb/.bsp), optional navmesh, scale,
                                 agent_height, agent_radius, replace -> 202 {id, status, name}
    GET  /v1/level-jobs?status=&limit=   {"jobs": [...]} newest first
    GET  /v1/level-jobs/{id}     {id, status, progress, error?, timings, name}
    DELETE /v1/level-jobs/{id}   cancel a queued or running level job -> its status
    GET  /v1/levels              {"levels": [level, ...]} by name
    GET  /v1/levels/{name}       one level: scale, agent, counts, stage timings (ms)
    DELETE /v1/levels/{name}     remove a level from the registry -> the level removed

The upload is checked before a job is made, so a bad one answers 4xx and never becomes a job:
the name (422; the registry's rule), the files' suffixes (400), that each parses into a mesh with
at least one triangle of non-zero area after scaling (400), the sizes (413, each file and the
whole body), the scale and agent (422, TrackSettings' limits). What only the precompute can tell
(no walkable surface, no camera track) fails the job with the reason in `error`.

Duplicate names: a name the registry holds, or one a queued or running level job is adding, is
refused with 409 unless `replace=true`; then the new version replaces the old one when its job
succeeds (sessions already on the old version keep it; new sessions get the new one). The job
writes into the registry only when the precompute has succeeded (the artifact to a temporary file
renamed into place, then the index row: LevelRegistry.add_level), so a failed or cancelled job
leaves the registry as it was (a job process killed in the middle of that write can leave an
artifact file no row points at, never a row without its file).

Removing a level (DELETE) takes its row and then its artifact file away: new sessions on it get
NOT_FOUND, sessions already on it keep the copy they loaded. A level that a queued or running job
is adding or replacing answers 409 (cancel the job first), so a removal is never undone by a job
that finishes after it.

The job runs in a job process (jobs/: the local runner or a queue worker); the uploads stay in
the job's `input/`. The registry's index lives where the job records do (`JobSettings.job_store`:
SQLite in the data directory, or the PostgreSQL database the nodes share; the job's params carry
that URL beside the data directory), so every node lists, fetches and serves the same levels; two
nodes' jobs adding one name at once give one level and one failed job (the index's primary key),
and PostgreSQL down answers 503.

Tenants: levels and level jobs are the tenant's of the key that added them (the registry keeps a
namespace per tenant, registry.py): each tenant has its own "arena", another tenant's level or job
answers 404 as an unknown one, and a TRACKS session finds only its own tenant's levels. Reading
(GET) needs the verb level.read; adding, deleting and cancelling a level job level.write (admin).
A level added (when its job is submitted) and a level deleted go into the tenant's audit trail
(GET /v1/audit).
"""

from __future__ import annotations

import math
import threading
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends, FastAPI, File, Form, HTTPException, Query, Request, UploadFile
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field

from camdirector.access.guard import Identity
from camdirector.access.roles import Verb
from camdirector.front.http.auth import require
from camdirector.front.http.body_limits import allow_body
from camdirector.front.http.routes.job_resources import (
    MAX_LISTED_JOBS,
    IdempotencyKey,
    JobCreated,
    Jobs,
    JobStatus,
    answer_unavailable,
    answer_unavailable_jobs,
    cancel_job,
    created_headers,
    earlier_job,
    job_of_kind,
    known_form_fields,
    list_jobs,
    submit_job,
)
from camdirector.geometry.meshes import MeshError
from camdirector.jobs import JobSettings, JobState
from camdirector.precompute.tracks.job import KIND
from camdirector.precompute.tracks.level_mesh import LEVEL_SUFFIXES, decode_level_mesh
from camdirector.precompute.tracks.registry import LevelRecord, LevelRegistry, LevelsUnavailable, check_level_name
from camdirector.precompute.tracks.track_settings import TrackSettings

LEVELS_PREFIX = "/v1/levels"
JOBS_PREFIX = "/v1/level-jobs"
# Multipart framing around the two files: boundaries, part headers and the small form fields.
_FORM_OVERHEAD_BYTES = 64 * 1024


# -- the routes -----------------------------------------------------------------------------


class LevelJobCreated(JobCreated):
    """Poll GET /v1/level-jobs/{id}."""

    name: str = Field(description="the level the job adds")


class LevelJobStatus(JobStatus):
    """timings: milliseconds per precompute stage and job phase."""

    name: str = Field(description="the level the job adds")


class LevelJobList(BaseModel):
    jobs: list[LevelJobStatus] = Field(description="newest first")


class LevelOut(BaseModel):
    name: str
    format_version: int = Field(description="artifact format version")
    source_file: str = Field(description="file name of the level mesh it was built from")
    m_per_unit: float = Field(description="the level file's scale, metres per unit")
    agent_height_m: float
    agent_radius_m: float
    created_unix_s: float
    counts: dict[str, int] = Field(description="sizes of the precompute's results (nodes, edges, tracks, ...)")
    timings_ms: dict[str, float] = Field(description="milliseconds per precompute stage")


class LevelList(BaseModel):
    levels: list[LevelOut]


def _level_json(record: LevelRecord) -> dict:
    return {
        "name": record.name,
        "format_version": record.format_version,
        "source_file": Path(record.source_path).name,
        "m_per_unit": record.m_per_unit,
        "agent_height_m": record.agent_height_m,
        "agent_radius_m": record.agent_radius_m,
        "created_unix_s": record.created_unix_s,
        "counts": record.counts,
        "timings_ms": {k: round(v, 3) for k, v in record.timings_ms.items()},
    }


def _mesh_file(upload: UploadFile, field: str, limit: int, scale: float) -> tuple[str, bytes]:
    """(stored file name, bytes) of an uploaded level or navmesh; HTTPException when unusable."""
    suffix = Path(upload.filename or "").suffix.lower()
    if suffix not in LEVEL_SUFFIXES:
        raise HTTPException(
            status_code=400, detail=(f"{field}: file name {upload.filename!r} must end in {' or '.join(LEVEL_SUFFIXES)}")
        )
    data = upload.file.read(limit + 1)
    if len(data) > limit:
        raise HTTPException(status_code=413, detail=f"{field}: upload larger than the limit of {limit} bytes")
    if not data:
        raise HTTPException(status_code=400, detail=f"{field}: empty upload")
    if suffix == ".obj" and b"\0" in data[:65536]:
        raise HTTPException(status_code=400, detail=f"{field}: not an OBJ file (it holds binary data)")
    try:
        mesh = decode_level_mesh(data, suffix)
    except MeshError as exc:
        raise HTTPException(status_code=400, detail=f"{field}: not a usable mesh: {exc}") from None
    extent = (mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)) * scale
    if (extent > 1e-3).sum() < 2:
        raise HTTPException(
            status_code=400,
            detail=(f"{field}: degenerate mesh: it spans {extent.round(4).tolist()} m, under 1 mm in two directions"),
        )
    return f"{field}{suffix}", data


def build_level_router(runner: Jobs, job_settings: JobSettings, data_dir: Path) -> APIRouter:
    """The /v1/levels and /v1/level-jobs routes over `runner` (which must have the "level" kind)."""
    router = APIRouter(tags=["levels"])
    registry = LevelRegistry(data_dir, job_settings.job_store)
    limit = job_settings.max_upload_bytes
    submit_lock = threading.Lock()  # the duplicate check and the submit happen as one

    def pending_names(tenant: str) -> set[str]:
        """The names the tenant's queued and running level jobs are adding."""
        jobs = [
            job for state in (JobState.QUEUED, JobState.RUNNING) for job in runner.store.list(state, kind=KIND, tenant=tenant)
        ]
        return {j.params["name"] for j in jobs}

    def level_job_or_404(job_id: str, identity: Identity):
        return job_of_kind(runner, job_id, KIND, "level job", identity.tenant)

    @router.post(
        LEVELS_PREFIX,
        status_code=202,
        dependencies=[Depends(known_form_fields)],
        response_model=LevelJobCreated,
        responses={
            400: {"description": "a file is not a usable .obj/.glb mesh or .bsp map (detail says why)"},
            409: {"description": "the name is taken (registered or being added) and replace is false"},
            413: {"description": "an upload is larger than the server's limit"},
            422: {"description": "a bad name, scale or agent out of range, or an Idempotency-Key used for another request"},
            429: {"description": "the job queue is full, or the tenant holds its share of jobs or uploads"},
            503: {"description": "the job store or queue is unreachable; retry later"},
        },
    )
    def add_level(
        request: Request,
        identity: Annotated[Identity, Depends(require(Verb.LEVEL_WRITE))],
        name: Annotated[str, Form(description="1-64 letters, digits, '.', '_' or '-', starting with a letter or digit")],
        level: Annotated[
            UploadFile,
            File(description=("the level's geometry, .obj, .glb or a Quake .bsp map (decoded in metres: leave scale at 1)")),
        ],
        navmesh: Annotated[
            UploadFile | None,
            File(description="its navigation mesh, .obj or .glb (derived from the walkable surfaces when absent)"),
        ] = None,
        scale: Annotated[float, Form(gt=0, description="metres per file unit")] = 1.0,
        agent_height: Annotated[float, Form(description="agent (and actor) height, m, [0.1, 100]")] = 2.0,
        agent_radius: Annotated[float, Form(description="agent radius, m, [0, 50]")] = 0.6,
        replace: Annotated[bool, Form(description="replace a level of that name when the job succeeds")] = False,
        seed: Annotated[int, Form(ge=0, le=2**63 - 1, description="random seed of the precompute")] = 0,
        idempotency_key: IdempotencyKey = None,
    ) -> JSONResponse:
        """Submit a level for precompute (a job with progress). The files are checked now: a bad
        upload answers 4xx with the reason and never becomes a job."""
        try:
            check_level_name(name)
        except ValueError as exc:
            raise HTTPException(status_code=422, detail=str(exc)) from None
        if not all(math.isfinite(v) for v in (scale, agent_height, agent_radius)):
            raise HTTPException(status_code=422, detail="scale, agent_height and agent_radius must be finite")
        try:
            TrackSettings(agent_height_m=agent_height, agent_radius_m=agent_radius)
        except ValueError as exc:
            raise HTTPException(status_code=422, detail=f"bad parameter: {exc}") from None
        level_file, level_data = _mesh_file(level, "level", limit, scale)
        files, navmesh_file = {level_file: level_data}, None
        if navmesh is not None:
            navmesh_file, navmesh_data = _mesh_file(navmesh, "navmesh", limit, scale)
            files[navmesh_file] = navmesh_data
        params = {
            "name": name,
            "level_file": level_file,
            "navmesh_file": navmesh_file,
            "scale": scale,
            "agent_height_m": agent_height,
            "agent_radius_m": agent_radius,
            "replace": replace,
            "seed": seed,
            "data_dir": str(registry.data_dir),
            "records_url": job_settings.job_store,
            "tenant": identity.tenant,
        }
        with submit_lock:
            job = earlier_job(runner, identity.tenant, idempotency_key, KIND, params, files)
            if job is not None:  # sent again: its level is this job's, not a name taken
                return JSONResponse(
                    {"id": job.id, "status": job.state.value, "name": name},
                    status_code=202,
                    headers=created_headers(job, f"{JOBS_PREFIX}/{job.id}"),
                )
            if not replace and (registry.get(name, identity.tenant) is not None or name in pending_names(identity.tenant)):
                raise HTTPException(
                    status_code=409, detail=(f"level {name!r} exists or is being added; send replace=true to replace it")
                )
            job = submit_job(runner, KIND, params, files, identity.tenant, idempotency_key)
        request.app.state.guard.audit(
            identity,
            "level.add",
            None,
            {
                "name": name,
                "replace": replace,
                "job_id": job.id,
                "stage": "job submitted: the level is registered when the job succeeds",
            },
        )
        return JSONResponse(
            {"id": job.id, "status": job.state.value, "name": name},
            status_code=202,
            headers=created_headers(job, f"{JOBS_PREFIX}/{job.id}"),
        )

    @router.get(JOBS_PREFIX, response_model=LevelJobList)
    def list_level_jobs(
        identity: Annotated[Identity, Depends(require(Verb.LEVEL_READ))],
        status: Annotated[JobState | None, Query(description="only jobs in this state")] = None,
        limit: Annotated[int, Query(ge=1, le=MAX_LISTED_JOBS, description="at most this many")] = 100,
    ) -> dict:
        """The newest level jobs of the caller's tenant first, with the level each adds."""
        return {"jobs": list_jobs(runner, KIND, status, limit, lambda p: {"name": p["name"]}, identity.tenant)}

    @router.get(JOBS_PREFIX + "/{job_id}", response_model=LevelJobStatus, responses={404: {"description": "no such level job"}})
    def get_level_job(job_id: str, identity: Annotated[Identity, Depends(require(Verb.LEVEL_READ))]) -> JSONResponse:
        """State, progress 0..1, error and per-stage timings (ms) of a level job."""
        job = level_job_or_404(job_id, identity)
        return JSONResponse({**job.as_public(), "name": job.params["name"]})

    @router.delete(
        JOBS_PREFIX + "/{job_id}",
        response_model=LevelJobStatus,
        responses={404: {"description": "no such level job"}, 409: {"description": "the job already succeeded or failed"}},
    )
    def cancel_level_job(job_id: str, identity: Annotated[Identity, Depends(require(Verb.LEVEL_WRITE))]) -> JSONResponse:
        """Cancel a queued or running level job (a running job's process is ended; the registry
        is left as it was). Cancelling a cancelled job is a no-op; a finished job answers 409."""
        level_job_or_404(job_id, identity)
        job = cancel_job(runner, job_id, "level job")
        return JSONResponse({**job.as_public(), "name": job.params["name"]})

    @router.get(LEVELS_PREFIX, response_model=LevelList)
    def list_levels(identity: Annotated[Identity, Depends(require(Verb.LEVEL_READ))]) -> dict:
        """The caller's tenant's registered levels, by name."""
        return {"levels": [_level_json(r) for r in registry.list(identity.tenant)]}

    @router.get(LEVELS_PREFIX + "/{name}", response_model=LevelOut, responses={404: {"description": "no such level"}})
    def get_level(name: str, identity: Annotated[Identity, Depends(require(Verb.LEVEL_READ))]) -> dict:
        """One registered level: scale, agent, counts and precompute stage timings."""
        record = registry.get(name, identity.tenant)
        if record is None:
            raise HTTPException(status_code=404, detail=f"no level named {name!r}")
        return _level_json(record)

    @router.delete(
        LEVELS_PREFIX + "/{name}",
        response_model=LevelOut,
        responses={
            404: {"description": "no such level"},
            409: {"description": "a queued or running level job is adding or replacing it"},
        },
    )
    def delete_level(name: str, request: Request, identity: Annotated[Identity, Depends(require(Verb.LEVEL_WRITE))]) -> dict:
        """Remove a level from the registry (module docstring); answers the level removed."""
        with submit_lock:  # no job for this name can be submitted between the check and the delete
            if name in pending_names(identity.tenant):
                raise HTTPException(
                    status_code=409, detail=(f"a level job is adding {name!r}; cancel it (DELETE {JOBS_PREFIX}/ID) first")
                )
            record = registry.get(name, identity.tenant)
            if record is None or not registry.delete(name, identity.tenant):
                raise HTTPException(status_code=404, detail=f"no level named {name!r}")
        request.app.state.guard.audit(identity, "level.delete", None, {"name": name})
        return _level_json(record)

    return router


def install_level_routes(app: FastAPI, runner: Jobs, data_dir: str | Path, settings: JobSettings = JobSettings()) -> None:
    """Mount the level routes on `app`, over the node's jobs (opened by front/main.py with the
    service's job kinds), with an upload limit of two files plus the form."""
    app.include_router(build_level_router(runner, settings, Path(data_dir)))
    answer_unavailable_jobs(app)
    answer_unavailable(app, LevelsUnavailable, "the level index")
    allow_body(app, LEVELS_PREFIX, 2 * settings.max_upload_bytes + _FORM_OVERHEAD_BYTES)
