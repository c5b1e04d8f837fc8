"""REST routes of the motion overview jobs (issue 5), and the "overview" job kind.

    POST   /v1/overview-jobs                    multipart: file (BVH) + optional form fields -> 202 {id, status}
    GET    /v1/overview-jobs?status=&limit=     {"jobs": [...]} newest first
    GET    /v1/overview-jobs/{id}               {id, status, progress, error?, timings}
    DELETE /v1/overview-jobs/{id}               cancel (queued or running) -> {id, status, ...}
    GET    /v1/overview-jobs/{id}/result        the camera path JSON (`result_document`)
    GET    /v1/overview-jobs/{id}/preview.mp4   the clip through the camera (H.264)
    GET    /v1/overview-jobs/{id}/contact-sheet.png

The upload is parsed (BVH, forward kinematics, body-part mapping) and the settings validated
before a job is made, so a bad upload answers 4xx and never becomes a job. Job files: the upload
is `input/clip.bvh`, the parameters are the job's JSON; the job writes `result.json`,
`preview.mp4` and `contact-sheet.png`, renamed into `result/` by the runner when it succeeded.

Keys (front/http/auth.py): submitting needs the verb job.submit, reading (the list, a job, its
result, preview and contact sheet) job.read, cancelling job.cancel. A job is its tenant's
(job_resources.py): another tenant's answers 404 as an unknown one, and a tenant past its share of
jobs or uploads is answered 429.

Conventions as on the wire: right-handed, +Y up, metres, in the clip's world frame.
"""

from __future__ import annotations

import math
import os
from typing import Annotated

from fastapi import APIRouter, Depends, FastAPI, File, Form, HTTPException, Query, UploadFile
from fastapi.responses import FileResponse, JSONResponse
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
    answer_unavailable_jobs,
    cancel_job,
    created_headers,
    job_of_kind,
    known_form_fields,
    list_jobs,
    submit_job,
)
from camdirector.jobs import JobSettings, JobState
from camdirector.precompute.overview.body_parts import map_body_parts
from camdirector.precompute.overview.job import (
    CLIP_FILE,
    CONTACT_SHEET_PNG,
    KIND,
    PREVIEW_MP4,
    RESULT_JSON,
    load_clip_bytes,
    settings_from_params,
)

# -- the routes -----------------------------------------------------------------------------


class OverviewJobOut(JobStatus):
    file_name: str = Field(description="the uploaded clip's file name")
    frames: int = Field(description="clip frames after skip_frames")


class OverviewJobList(BaseModel):
    jobs: list[OverviewJobOut] = Field(description="newest first")


class FrameOut(BaseModel):
    frame: int
    position: list[float]
    look_at: list[float]
    up: list[float]
    vertical_fov_deg: float
    shot: int


class ShotOut(BaseModel):
    start: int
    end: int


class OverviewResultOut(BaseModel):
    fps: float
    frames: list[FrameOut]
    shots: list[ShotOut]
    metrics: dict[str, float]


def _status(job) -> JSONResponse:
    return JSONResponse(job.as_public())


def build_overview_router(runner: Jobs, job_settings: JobSettings) -> APIRouter:
    """The /v1/overview-jobs routes over `runner` (which must have the "overview" kind)."""
    router = APIRouter(prefix=PREFIX, tags=["overview jobs"])
    limit = job_settings.max_upload_bytes

    def job_or_404(job_id: str, identity: Identity):
        return job_of_kind(runner, job_id, KIND, "overview job", identity.tenant)

    def file_of(job_id: str, identity: Identity, name: str, media_type: str) -> FileResponse:
        job = job_or_404(job_id, identity)
        if job.state is not JobState.SUCCEEDED:
            raise HTTPException(
                status_code=409,
                detail=(
                    f"job {job_id} is {job.state.value}: its result exists only once it succeeded"
                    + (f" ({job.error})" if job.error else "")
                ),
            )
        path = runner.result_dir(job_id) / name
        if not path.is_file():
            raise HTTPException(status_code=404, detail=f"job {job_id} has no {name}")
        return FileResponse(path, media_type=media_type)

    @router.post(
        "",
        status_code=202,
        dependencies=[Depends(known_form_fields)],
        response_model=JobCreated,
        responses={
            400: {"description": "the upload is not a usable BVH clip (detail says why)"},
            413: {"description": "the upload is larger than the server's limit"},
            422: {"description": "a form field is out of range, or an Idempotency-Key sent before with another request"},
            429: {"description": "the job queue is full, or the tenant holds its share of jobs or uploads"},
            503: {"description": "the job store or queue is unreachable; retry later"},
        },
    )
    def create_overview_job(
        identity: Annotated[Identity, Depends(require(Verb.JOB_SUBMIT))],
        file: Annotated[UploadFile, File(description="BVH motion capture clip")],
        scale: Annotated[float | None, Form(gt=0, description="metres per file unit (default: inferred: cm, CMU or m)")] = None,
        skip_frames: Annotated[int, Form(ge=0, description="leading frames to ignore (T-pose)")] = 0,
        aspect: Annotated[float | None, Form(description="frame width / height, [0.2, 5] (default 16/9)")] = None,
        seed: Annotated[int, Form(ge=0, le=2**63 - 1, description="random seed of the annealing")] = 0,
        c1: Annotated[float | None, Form(description="acceleration weight (paper: 10)")] = None,
        c2: Annotated[float | None, Form(description="speed-limit weight (10)")] = None,
        c3: Annotated[float | None, Form(description="angular acceleration weight (5)")] = None,
        c4: Annotated[float | None, Form(description="angular speed-limit weight (5)")] = None,
        c5: Annotated[float | None, Form(description="friction weight (2)")] = None,
        max_speed_heights_s: Annotated[float | None, Form(description="camera speed limit, character heights/s (1/6)")] = None,
        max_angular_speed_deg_s: Annotated[float | None, Form(description="panning speed limit, deg/s (20)")] = None,
        friction_speed_heights_s: Annotated[float | None, Form(description="friction speed, heights/s (1/20)")] = None,
        split_quality: Annotated[float | None, Form(description="split a shot below this quality (0.7)")] = None,
        split_max_saliency: Annotated[float | None, Form(description="cuts only at frames below this saliency (0.8)")] = None,
        min_shot_s: Annotated[float | None, Form(description="shortest shot, s (2)")] = None,
        max_shots_per_1000_frames: Annotated[float | None, Form(description="shot cap per 1000 frames (6)")] = None,
        analysis_rate_hz: Annotated[float | None, Form(description="rate the stages run at, Hz (15)")] = None,
        idempotency_key: IdempotencyKey = None,
    ) -> JSONResponse:
        """Submit a BVH clip for a multi-shot overview camera path. The clip is parsed now: a
        bad upload answers 4xx with the reason and never becomes a job."""
        data = file.file.read(limit + 1)
        if len(data) > limit:
            raise HTTPException(status_code=413, detail=(f"upload larger than the limit of {limit} bytes"))
        if not data:
            raise HTTPException(status_code=400, detail="empty upload: expected a BVH file")
        params: dict[str, float | str | None] = {
            "scale": scale,
            "skip_frames": skip_frames,
            "aspect": aspect,
            "seed": seed,
            "c1": c1,
            "c2": c2,
            "c3": c3,
            "c4": c4,
            "c5": c5,
            "max_speed_heights_s": max_speed_heights_s,
            "max_angular_speed_deg_s": max_angular_speed_deg_s,
            "friction_speed_heights_s": friction_speed_heights_s,
            "split_quality": split_quality,
            "split_max_saliency": split_max_saliency,
            "min_shot_s": min_shot_s,
            "max_shots_per_1000_frames": max_shots_per_1000_frames,
            "analysis_rate_hz": analysis_rate_hz,
        }
        params = {k: v for k, v in params.items() if v is not None}
        if any(isinstance(v, float) and not math.isfinite(v) for v in params.values()):
            raise HTTPException(status_code=422, detail="form fields must be finite numbers")
        try:
            settings_from_params(params)
        except ValueError as exc:
            raise HTTPException(status_code=422, detail=f"bad parameter: {exc}") from None
        try:
            clip = load_clip_bytes(data, scale=scale, skip_frames=skip_frames)
            map_body_parts(clip)
        except ValueError as exc:
            raise HTTPException(status_code=400, detail=str(exc)) from None
        params["frames"] = clip.frame_count
        params["file_name"] = os.path.basename(file.filename or CLIP_FILE)[:200]
        job = submit_job(runner, KIND, params, {CLIP_FILE: data}, identity.tenant, idempotency_key)
        return JSONResponse(
            {"id": job.id, "status": job.state.value},
            status_code=202,
            headers=created_headers(job, f"/v1/overview-jobs/{job.id}"),
        )

    @router.get("", response_model=OverviewJobList)
    def list_overview_jobs(
        identity: Annotated[Identity, Depends(require(Verb.JOB_READ))],
        status: Annotated[JobState | None, Query(description="only jobs in this state")] = None,
        limit: Annotated[int, Query(ge=1, le=MAX_LISTED_JOBS, description="at most this many")] = 100,
    ) -> dict:
        """The newest overview jobs of the caller's tenant first, with the clip's file name and frame count."""
        return {
            "jobs": list_jobs(
                runner,
                KIND,
                status,
                limit,
                lambda p: {"file_name": p.get("file_name", CLIP_FILE), "frames": int(p.get("frames", 0))},
                identity.tenant,
            )
        }

    @router.get("/{job_id}", response_model=JobStatus, responses={404: {"description": "no such job"}})
    def get_overview_job(job_id: str, identity: Annotated[Identity, Depends(require(Verb.JOB_READ))]) -> JSONResponse:
        """State, progress 0..1, error and per-stage timings (ms) of a job."""
        return _status(job_or_404(job_id, identity))

    @router.delete(
        "/{job_id}",
        response_model=JobStatus,
        responses={404: {"description": "no such job"}, 409: {"description": "the job already succeeded or failed"}},
    )
    def cancel_overview_job(job_id: str, identity: Annotated[Identity, Depends(require(Verb.JOB_CANCEL))]) -> JSONResponse:
        """Cancel a queued or running job (a running job's process is ended). Cancelling a
        cancelled job is a no-op; a finished job answers 409."""
        job_or_404(job_id, identity)
        return _status(cancel_job(runner, job_id))

    @router.get(
        "/{job_id}/result",
        response_model=OverviewResultOut,
        responses={404: {"description": "no such job"}, 409: {"description": "the job has not succeeded"}},
    )
    def get_overview_result(job_id: str, identity: Annotated[Identity, Depends(require(Verb.JOB_READ))]) -> FileResponse:
        """The camera path: one entry per clip frame after skip_frames (metres, +Y up)."""
        return file_of(job_id, identity, RESULT_JSON, "application/json")

    @router.get(
        "/{job_id}/preview.mp4",
        response_class=FileResponse,
        responses={
            200: {"content": {"video/mp4": {}}},
            404: {"description": "no such job"},
            409: {"description": "the job has not succeeded"},
        },
    )
    def get_overview_preview(job_id: str, identity: Annotated[Identity, Depends(require(Verb.JOB_READ))]) -> FileResponse:
        """The clip rendered through the camera path (capsule character, shot starts flashed)."""
        return file_of(job_id, identity, PREVIEW_MP4, "video/mp4")

    @router.get(
        "/{job_id}/contact-sheet.png",
        response_class=FileResponse,
        responses={
            200: {"content": {"image/png": {}}},
            404: {"description": "no such job"},
            409: {"description": "the job has not succeeded"},
        },
    )
    def get_overview_contact_sheet(job_id: str, identity: Annotated[Identity, Depends(require(Verb.JOB_READ))]) -> FileResponse:
        """Start and middle frame of every shot, labelled."""
        return file_of(job_id, identity, CONTACT_SHEET_PNG, "image/png")

    return router


PREFIX = "/v1/overview-jobs"  # POST here takes the upload
# Multipart framing around the file: boundaries, part headers and the small form fields.
_FORM_OVERHEAD_BYTES = 64 * 1024


def install_overview_routes(app: FastAPI, runner: Jobs, settings: JobSettings = JobSettings()) -> None:
    """Mount the overview routes and the upload limit on `app`, over the node's jobs (a JobRunner or
    a client of the job queue, opened by front/main.py with the service's job kinds)."""
    app.include_router(build_overview_router(runner, settings))
    answer_unavailable_jobs(app)
    allow_body(app, PREFIX, settings.max_upload_bytes + _FORM_OVERHEAD_BYTES)
