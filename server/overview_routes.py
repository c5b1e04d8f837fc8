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

Conventions as on the wire: right-handed, +Y up, metres, in the clip's world frame.
"""
from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import numpy as np
from fastapi import APIRouter, FastAPI, File, Form, HTTPException, Query, UploadFile
from fastapi.responses import FileResponse, JSONResponse
from pydantic import BaseModel, Field

from camdirector.precompute.overview.body_parts import map_body_parts
from camdirector.precompute.overview.bvh import MotionClip, forward_kinematics, parse_bvh
from camdirector.precompute.overview.pipeline import OverviewResult, plan_overview
from camdirector.precompute.overview.preview import PreviewCamera, render_preview
from camdirector.precompute.overview.settings import OverviewSettings
from camdirector.server.jobs import (JobError, JobKind, JobNotFound, JobRegistry, JobRunner,
                                     JobSettings, JobState, QueueFull)

KIND = "overview"
CLIP_FILE = "clip.bvh"
RESULT_JSON = "result.json"
PREVIEW_MP4 = "preview.mp4"
CONTACT_SHEET_PNG = "contact-sheet.png"

# OverviewSettings fields a client may set (the paper's parameters, and the frame's aspect).
PAPER_PARAMETERS = ("c1", "c2", "c3", "c4", "c5", "max_speed_heights_per_s",
                    "max_angular_speed_deg_per_s", "friction_speed_heights_per_s",
                    "split_quality", "split_max_saliency", "min_shot_s",
                    "max_shots_per_1000_frames", "analysis_rate_hz")


# -- the job ------------------------------------------------------------------------------------

def load_clip_bytes(data: bytes, *, scale: float | None, skip_frames: int) -> MotionClip:
    """Parse and run forward kinematics; raises ValueError with a message meant for the client."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError("not a BVH file: it is not UTF-8 text") from None
    clip = forward_kinematics(parse_bvh(text), scale_m_per_unit=scale, skip_frames=skip_frames)
    if not np.all(np.isfinite(clip.positions_m)):
        raise ValueError("bad BVH motion: forward kinematics gives non-finite positions")
    return clip


def result_document(result: OverviewResult, *, skip_frames: int = 0,
                    metrics: dict | None = None) -> dict:
    """The result JSON: fps; frames (one per clip frame after skip_frames; "frame" counts from
    0 at the first kept frame) with position, look_at, up (metres, world, +Y up),
    vertical_fov_deg and shot; shots [{start, end}] inclusive frames; metrics."""
    frames = [{"frame": i,
               "position": [round(float(v), 5) for v in result.camera_position_m[i]],
               "look_at": [round(float(v), 5) for v in result.look_at_m[i]],
               "up": [round(float(v), 6) for v in result.up[i]],
               "vertical_fov_deg": round(float(result.vertical_fov_deg[i]), 4),
               "shot": int(result.shot_index[i])}
              for i in range(len(result.camera_position_m))]
    e = result.energy
    q = result.quality
    sal = result.analysis.saliency.pose
    base = {"E": e.total, "E_internal": e.internal, "E_external": e.external, "V_sum": e.v_sum,
            "quality_mean": float(np.mean(q)),
            "quality_saliency_weighted": float(np.dot(sal, q) / max(float(sal.sum()), 1e-12)),
            "shot_count": int(len(result.shots)), "character_height_m": result.character_height_m,
            "max_speed_m_per_s": result.max_speed_m_per_s, "skip_frames": int(skip_frames),
            "analysis_frames": int(len(result.analysis_frames))}
    base.update(metrics or {})
    return {"fps": 1.0 / result.frame_time_s, "frames": frames,
            "shots": [{"start": int(a), "end": int(b)} for a, b in result.shots],
            "metrics": base}


def comparison_metrics(result: OverviewResult) -> dict[str, float]:
    """Figure 10 for this path: E, E_external and -V of ours and of the two baselines, each
    divided by |best static camera's| (evaluation.py; lower is better, static = -1)."""
    from camdirector.precompute.overview.evaluation import compare_with_baselines

    cmp = compare_with_baselines(result)
    out = {}
    for name, score in (("ours", cmp.ours), ("static", cmp.static), ("greedy", cmp.greedy)):
        out[f"{name}_E_norm"] = score.e
        out[f"{name}_E_external_norm"] = score.e_external
        out[f"{name}_V_norm"] = score.neg_v
    return out


def settings_from_params(params: dict) -> OverviewSettings:
    """OverviewSettings from job parameters (`aspect` and PAPER_PARAMETERS); ValueError if bad."""
    values = {k: params[k] for k in ("aspect",) + PAPER_PARAMETERS if params.get(k) is not None}
    return OverviewSettings(**values)


def write_overview_outputs(clip: MotionClip, result: OverviewResult, out_dir: Path, *,
                           skip_frames: int = 0, metrics: dict | None = None,
                           progress=None) -> dict[str, float]:
    """result.json, preview.mp4 and contact-sheet.png into out_dir; returns timings in ms."""
    t = time.perf_counter()
    doc = result_document(result, skip_frames=skip_frames, metrics=metrics)
    (out_dir / RESULT_JSON).write_text(json.dumps(doc, separators=(",", ":")))
    timings = {"result_json": (time.perf_counter() - t) * 1e3}
    if progress is not None:
        progress(0.8)
    timings.update(render_preview(clip, result.analysis.parts, PreviewCamera.from_result(result),
                                  out_dir / PREVIEW_MP4, out_dir / CONTACT_SHEET_PNG))
    return timings


def run_overview_job(params: dict, input_dir: Path, output_dir: Path, progress) -> dict[str, float]:
    """The "overview" job kind (runs in a job process): plan the camera, write the outputs."""
    t = time.perf_counter()
    try:
        clip = load_clip_bytes((input_dir / CLIP_FILE).read_bytes(), scale=params.get("scale"),
                               skip_frames=int(params.get("skip_frames", 0)))
        settings = settings_from_params(params)
    except ValueError as exc:
        raise JobError(str(exc)) from None
    timings = {"parse_bvh": (time.perf_counter() - t) * 1e3}
    rng = np.random.default_rng(int(params.get("seed", 0)))
    try:
        result = plan_overview(clip, settings, rng, progress=lambda f: progress(0.7 * f))
    except ValueError as exc:
        raise JobError(f"cannot plan this clip: {exc}") from None
    timings.update(result.timings_ms)
    t = time.perf_counter()
    metrics = comparison_metrics(result)
    timings["baselines"] = (time.perf_counter() - t) * 1e3
    timings.update(write_overview_outputs(clip, result, output_dir,
                                          skip_frames=int(params.get("skip_frames", 0)),
                                          metrics=metrics, progress=progress))
    progress(1.0)
    return timings


def overview_job_kind() -> JobKind:
    return JobKind(KIND, run_overview_job)


# -- the routes -----------------------------------------------------------------------------

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


def job_of_kind(runner: JobRunner, job_id: str, kind: str, noun: str):
    """The job job_id of `kind`; HTTPException 404 for an unknown id and for a job of another
    kind (one runner and job store serve every kind of job route)."""
    try:
        job = runner.get(job_id)
    except JobNotFound:
        job = None
    if job is None or job.kind != kind:
        raise HTTPException(status_code=404, detail=f"no {noun} {job_id!r}")
    return job


MAX_LISTED_JOBS = 1000


def list_jobs(runner: JobRunner, kind: str, status: JobState | None, limit: int,
              extra: Callable[[dict], dict]) -> list[dict]:
    """GET of a job collection: the newest `limit` jobs of `kind` (in `status` when given), each
    its public view with `extra(params)` added (finished jobs are kept `job_retention_s`)."""
    return [{**j.as_public(), **extra(j.params)}
            for j in runner.store.list(status, kind=kind, limit=limit, newest_first=True)]


def cancel_job(runner: JobRunner, job_id: str, noun: str = "job"):
    """DELETE of a job route: the job cancelled (a running job's process is ended), unchanged when
    it was cancelled already; HTTPException 409 when it had succeeded or failed. Cancels first and
    looks after, so a job that finishes meanwhile answers 409, not a 200 that did nothing."""
    job = runner.cancel(job_id)
    if job.state in (JobState.SUCCEEDED, JobState.FAILED):
        raise HTTPException(status_code=409, detail=f"{noun} {job_id} already {job.state.value}")
    return job


def build_overview_router(runner: JobRunner, job_settings: JobSettings) -> APIRouter:
    """The /v1/overview-jobs routes over `runner` (which must have the "overview" kind)."""
    router = APIRouter(prefix="/v1/overview-jobs", tags=["overview jobs"])
    limit = job_settings.max_upload_bytes

    def job_or_404(job_id: str):
        return job_of_kind(runner, job_id, KIND, "overview job")

    def file_of(job_id: str, name: str, media_type: str) -> FileResponse:
        job = job_or_404(job_id)
        if job.state is not JobState.SUCCEEDED:
            raise HTTPException(status_code=409, detail=(
                f"job {job_id} is {job.state.value}: its result exists only once it succeeded"
                + (f" ({job.error})" if job.error else "")))
        path = runner.result_dir(job_id) / name
        if not path.is_file():
            raise HTTPException(status_code=404, detail=f"job {job_id} has no {name}")
        return FileResponse(path, media_type=media_type)

    @router.post("", status_code=202, response_model=JobCreated, responses={
        400: {"description": "the upload is not a usable BVH clip (detail says why)"},
        413: {"description": "the upload is larger than the server's limit"},
        422: {"description": "a form field is out of range"},
        429: {"description": "the job queue is full; retry later"}})
    def create_overview_job(
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
        max_speed_heights_per_s: Annotated[float | None, Form(description="camera speed limit, character heights/s (1/6)")] = None,
        max_angular_speed_deg_per_s: Annotated[float | None, Form(description="panning speed limit, deg/s (20)")] = None,
        friction_speed_heights_per_s: Annotated[float | None, Form(description="friction speed, heights/s (1/20)")] = None,
        split_quality: Annotated[float | None, Form(description="split a shot below this quality (0.7)")] = None,
        split_max_saliency: Annotated[float | None, Form(description="cuts only at frames below this saliency (0.8)")] = None,
        min_shot_s: Annotated[float | None, Form(description="shortest shot, s (2)")] = None,
        max_shots_per_1000_frames: Annotated[float | None, Form(description="shot cap per 1000 frames (6)")] = None,
        analysis_rate_hz: Annotated[float | None, Form(description="rate the stages run at, Hz (15)")] = None,
    ) -> JSONResponse:
        """Submit a BVH clip for a multi-shot overview camera path. The clip is parsed now: a
        bad upload answers 4xx with the reason and never becomes a job."""
        data = file.file.read(limit + 1)
        if len(data) > limit:
            raise HTTPException(status_code=413, detail=(
                f"upload larger than the limit of {limit} bytes"))
        if not data:
            raise HTTPException(status_code=400, detail="empty upload: expected a BVH file")
        params = {"scale": scale, "skip_frames": skip_frames, "aspect": aspect, "seed": seed,
                  "c1": c1, "c2": c2, "c3": c3, "c4": c4, "c5": c5,
                  "max_speed_heights_per_s": max_speed_heights_per_s,
                  "max_angular_speed_deg_per_s": max_angular_speed_deg_per_s,
                  "friction_speed_heights_per_s": friction_speed_heights_per_s,
                  "split_quality": split_quality, "split_max_saliency": split_max_saliency,
                  "min_shot_s": min_shot_s, "max_shots_per_1000_frames": max_shots_per_1000_frames,
                  "analysis_rate_hz": analysis_rate_hz}
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
        try:
            job = runner.submit(KIND, params, {CLIP_FILE: data})
        except QueueFull as exc:
            raise HTTPException(status_code=429, detail=f"job queue full: {exc}",
                                headers={"Retry-After": "10"}) from None
        return JSONResponse({"id": job.id, "status": job.state.value}, status_code=202,
                            headers={"Location": f"/v1/overview-jobs/{job.id}"})

    @router.get("", response_model=OverviewJobList)
    def list_overview_jobs(
        status: Annotated[JobState | None, Query(description="only jobs in this state")] = None,
        limit: Annotated[int, Query(ge=1, le=MAX_LISTED_JOBS, description="at most this many")] = 100,
    ) -> dict:
        """The newest overview jobs first, with the clip's file name and frame count."""
        return {"jobs": list_jobs(runner, KIND, status, limit, lambda p: {
            "file_name": p.get("file_name", CLIP_FILE), "frames": int(p.get("frames", 0))})}

    @router.get("/{job_id}", response_model=JobStatus, responses={404: {"description": "no such job"}})
    def get_overview_job(job_id: str) -> JSONResponse:
        """State, progress 0..1, error and per-stage timings (ms) of a job."""
        return _status(job_or_404(job_id))

    @router.delete("/{job_id}", response_model=JobStatus, responses={
        404: {"description": "no such job"},
        409: {"description": "the job already succeeded or failed"}})
    def cancel_overview_job(job_id: str) -> JSONResponse:
        """Cancel a queued or running job (a running job's process is ended). Cancelling a
        cancelled job is a no-op; a finished job answers 409."""
        job_or_404(job_id)
        return _status(cancel_job(runner, job_id))

    @router.get("/{job_id}/result", response_model=OverviewResultOut, responses={
        404: {"description": "no such job"}, 409: {"description": "the job has not succeeded"}})
    def get_overview_result(job_id: str) -> FileResponse:
        """The camera path: one entry per clip frame after skip_frames (metres, +Y up)."""
        return file_of(job_id, RESULT_JSON, "application/json")

    @router.get("/{job_id}/preview.mp4", response_class=FileResponse, responses={
        200: {"content": {"video/mp4": {}}}, 404: {"description": "no such job"},
        409: {"description": "the job has not succeeded"}})
    def get_overview_preview(job_id: str) -> FileResponse:
        """The clip rendered through the camera path (capsule character, shot starts flashed)."""
        return file_of(job_id, PREVIEW_MP4, "video/mp4")

    @router.get("/{job_id}/contact-sheet.png", response_class=FileResponse, responses={
        200: {"content": {"image/png": {}}}, 404: {"description": "no such job"},
        409: {"description": "the job has not succeeded"}})
    def get_overview_contact_sheet(job_id: str) -> FileResponse:
        """Start and middle frame of every shot, labelled."""
        return file_of(job_id, CONTACT_SHEET_PNG, "image/png")

    return router


class UploadLimit:
    """ASGI middleware: answers 413 to a POST under `path_prefix` whose body is larger than
    `max_body_bytes`, from Content-Length before reading, or while streaming a chunked body, so
    a huge upload is never spooled to disk."""

    def __init__(self, app, max_body_bytes: int, path_prefix: str = "/v1/overview-jobs") -> None:
        self.app = app
        self.max_body_bytes = max_body_bytes
        self.path_prefix = path_prefix

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] != "POST" or \
                not scope["path"].startswith(self.path_prefix):
            return await self.app(scope, receive, send)
        for name, value in scope.get("headers", []):
            if name == b"content-length":
                try:
                    too_big = int(value) > self.max_body_bytes
                except ValueError:
                    too_big = False
                if too_big:
                    return await self._reject(send)
        seen = 0

        async def limited_receive():
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_body_bytes:
                    raise _TooLarge()
            return message

        try:
            await self.app(scope, limited_receive, send)
        except _TooLarge:
            await self._reject(send)

    async def _reject(self, send) -> None:
        body = json.dumps({"detail": f"upload larger than the limit of {self.max_body_bytes} "
                                     "bytes"}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"),
                                (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})


class _TooLarge(Exception):
    pass


# Multipart framing around the file: boundaries, part headers and the small form fields.
_FORM_OVERHEAD_BYTES = 64 * 1024


def install_overview_jobs(app: FastAPI, data_dir: str | Path,
                          settings: JobSettings = JobSettings()) -> JobRunner:
    """Mount the overview routes and the upload limit on `app`; returns the (not yet started)
    JobRunner over `<data_dir>/jobs`. Call `runner.start()` at startup and `runner.close()` at
    shutdown (both blocking, fast: call them from the event loop's thread or a thread)."""
    registry = JobRegistry((overview_job_kind(),))
    runner = JobRunner(data_dir, registry, settings, preload=("camdirector.server.overview_routes",))
    app.include_router(build_overview_router(runner, settings))
    app.add_middleware(UploadLimit, max_body_bytes=settings.max_upload_bytes + _FORM_OVERHEAD_BYTES)
    return runner
