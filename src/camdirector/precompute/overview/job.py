"""The "overview" job kind's body (runs in a job process) and what the CLI shares with it:
parse an uploaded BVH clip, plan the overview (pipeline.py), write the result JSON, the preview
video and the contact sheet. Job files: the upload is `input/clip.bvh`, the parameters are the
job's JSON; the job writes `result.json`, `preview.mp4` and `contact-sheet.png`."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from camdirector.infra.job_errors import JobError
from camdirector.precompute.overview.bvh import MotionClip, forward_kinematics, parse_bvh
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.pipeline import OverviewResult, plan_overview
from camdirector.precompute.overview.preview import PreviewCamera, render_preview

KIND = "overview"
CLIP_FILE = "clip.bvh"
RESULT_JSON = "result.json"
PREVIEW_MP4 = "preview.mp4"
CONTACT_SHEET_PNG = "contact-sheet.png"

# OverviewSettings fields a client may set (the paper's parameters, and the frame's aspect).
PAPER_PARAMETERS = (
    "c1",
    "c2",
    "c3",
    "c4",
    "c5",
    "max_speed_heights_s",
    "max_angular_speed_deg_s",
    "friction_speed_heights_s",
    "split_quality",
    "split_max_saliency",
    "min_shot_s",
    "max_shots_per_1000_frames",
    "analysis_rate_hz",
)


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


def result_document(result: OverviewResult, *, skip_frames: int = 0, metrics: dict | None = None) -> dict:
    """The result JSON: fps; frames (one per clip frame after skip_frames; "frame" counts from
    0 at the first kept frame) with position, look_at, up (metres, world, +Y up),
    vertical_fov_deg and shot; shots [{start, end}] inclusive frames; metrics."""
    frames = [
        {
            "frame": i,
            "position": [round(float(v), 5) for v in result.camera_position_m[i]],
            "look_at": [round(float(v), 5) for v in result.look_at_m[i]],
            "up": [round(float(v), 6) for v in result.up[i]],
            "vertical_fov_deg": round(float(result.vertical_fov_deg[i]), 4),
            "shot": int(result.shot_index[i]),
        }
        for i in range(len(result.camera_position_m))
    ]
    e = result.energy
    q = result.quality
    sal = result.analysis.saliency.pose
    base = {
        "E": e.total,
        "E_internal": e.internal,
        "E_external": e.external,
        "V_sum": e.v_sum,
        "quality_mean": float(np.mean(q)),
        "quality_saliency_weighted": float(np.dot(sal, q) / max(float(sal.sum()), 1e-12)),
        "shot_count": int(len(result.shots)),
        "character_height_m": result.character_height_m,
        "max_speed_m_s": result.max_speed_m_s,
        "skip_frames": int(skip_frames),
        "analysis_frames": int(len(result.analysis_frames)),
    }
    base.update(metrics or {})
    return {
        "fps": 1.0 / result.frame_time_s,
        "frames": frames,
        "shots": [{"start": int(a), "end": int(b)} for a, b in result.shots],
        "metrics": base,
    }


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


def write_overview_outputs(
    clip: MotionClip, result: OverviewResult, out_dir: Path, *, skip_frames: int = 0, metrics: dict | None = None, progress=None
) -> dict[str, float]:
    """result.json, preview.mp4 and contact-sheet.png into out_dir; returns timings in ms."""
    t = time.perf_counter()
    doc = result_document(result, skip_frames=skip_frames, metrics=metrics)
    (out_dir / RESULT_JSON).write_text(json.dumps(doc, separators=(",", ":")))
    timings = {"result_json": (time.perf_counter() - t) * 1e3}
    if progress is not None:
        progress(0.8)
    timings.update(
        render_preview(
            clip, result.analysis.parts, PreviewCamera.from_result(result), out_dir / PREVIEW_MP4, out_dir / CONTACT_SHEET_PNG
        )
    )
    return timings


def run_overview_job(params: dict, input_dir: Path, output_dir: Path, progress) -> dict[str, float]:
    """The "overview" job kind (runs in a job process): plan the camera, write the outputs."""
    t = time.perf_counter()
    try:
        clip = load_clip_bytes(
            (input_dir / CLIP_FILE).read_bytes(), scale=params.get("scale"), skip_frames=int(params.get("skip_frames", 0))
        )
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
    timings.update(
        write_overview_outputs(
            clip, result, output_dir, skip_frames=int(params.get("skip_frames", 0)), metrics=metrics, progress=progress
        )
    )
    progress(1.0)
    return timings
