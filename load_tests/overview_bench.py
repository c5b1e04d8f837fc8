"""Motion-overview benchmark: 1000-frame clips end to end through the REST API, against the planning alone.

    python -m load_tests.overview_bench [--data-dir ../shared/data] [--reps 3] [--frames 1000]
                                        [--clips NAME...] --json FILE

The issue's target: "a 1000-frame clip takes under 10 s end to end on this machine" (by default
the three shared clips longer than that; `--clips` takes any of the seven). Per clip, the
first `--frames` frames after the clip's skip (SOURCES.md) are cut into a BVH of their own and
submitted `--reps` times to a real `camdirector serve` (HTTP only, its default single job worker):
end to end is POST to `succeeded` as the client sees it, so it includes the upload, the job
process, the result JSON, the preview video and the contact sheet; the job's own stage timings are
reported as medians. The baseline, measured in the same run on the same frames, is
`plan_overview` in this process (the algorithm alone, no preview, no process start), and
`ratio_end_to_end_vs_planning` is the cost of serving it. The first job of a server also pays for
its worker's imports, as every job of a fresh server does; its time is listed apart (`first_s`)
and the medians are over all reps. Prints JSON (and writes it to --json); asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import urllib.request
import uuid
from pathlib import Path

import numpy as np

from camdirector.deploy.server_process import ServerProcess
from camdirector.precompute.overview.bvh import load_motion
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.pipeline import plan_overview
from load_tests.report import SHARED_DATA_DIR, emit, shared_subfolder, summary

# name -> (path under mocap/, leading frames to skip: T-pose or rest pose, SOURCES.md section 2)
CLIPS = {
    "bandai_dance_30fps": ("bandai_namco/dataset-1_dance-short_normal_001.bvh", 0),
    "cmu_01_01_120fps": ("cmu/01_01.bvh", 1),
    "perfume_a_40fps": ("perfume/A_test.bvh", 1),
    "bandai_walk_30fps": ("bandai_namco/dataset-1_walk_normal_001.bvh", 0),
    "bandai_run_30fps": ("bandai_namco/dataset-1_run_active_001.bvh", 0),
    "bandai_kick_30fps": ("bandai_namco/dataset-1_kick_normal_001.bvh", 0),
    "bandai_punch_30fps": ("bandai_namco/dataset-1_punch_normal_001.bvh", 0),
}
LONG_CLIPS = ("bandai_dance_30fps", "cmu_01_01_120fps", "perfume_a_40fps")  # over 1000 frames each
JOB_TIMEOUT_S = 300.0


def cut_bvh(text: str, skip: int, frames: int) -> bytes:
    """The BVH with only frames [skip, skip + frames) of its motion."""
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().lower().startswith("frame time"))
    motion = [line for line in lines[at + 1 :] if line.strip()][skip : skip + frames]
    header = [f"Frames: {len(motion)}" if line.strip().lower().startswith("frames:") else line for line in lines[: at + 1]]
    return ("\n".join(header + motion) + "\n").encode()


def _post(http: str, clip: bytes) -> str:
    boundary = uuid.uuid4().hex
    body = (
        (
            f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="clip.bvh"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n"
        ).encode()
        + clip
        + f"\r\n--{boundary}--\r\n".encode()
    )
    request = urllib.request.Request(
        f"http://{http}/v1/overview-jobs",
        data=body,
        method="POST",
        headers={"Content-Type": f"multipart/form-data; boundary={boundary}"},
    )
    with urllib.request.urlopen(request, timeout=60) as reply:
        return json.loads(reply.read())["id"]


def _wait(http: str, job_id: str) -> dict:
    deadline = time.monotonic() + JOB_TIMEOUT_S
    while time.monotonic() < deadline:
        status = json.loads(urllib.request.urlopen(f"http://{http}/v1/overview-jobs/{job_id}", timeout=30).read())
        if status["status"] in ("succeeded", "failed", "cancelled"):
            return status
        time.sleep(0.02)
    raise TimeoutError(f"job {job_id} still {status['status']} after {JOB_TIMEOUT_S} s")


def bench_clip(http: str, path: Path, skip: int, frames: int, reps: int) -> dict:
    clip_bytes = cut_bvh(path.read_text(), skip, frames)
    end_to_end, stages = [], []
    for _ in range(reps):
        start = time.perf_counter()
        status = _wait(http, _post(http, clip_bytes))
        end_to_end.append(time.perf_counter() - start)
        if status["status"] != "succeeded":
            raise RuntimeError(f"{path.name}: job {status['status']}: {status.get('error')}")
        stages.append(status.get("timings") or {})
    planning = []
    with tempfile.NamedTemporaryFile(suffix=".bvh") as cut:
        cut.write(clip_bytes)
        cut.flush()
        clip = load_motion(cut.name)
    for rep in range(reps):
        start = time.perf_counter()
        plan_overview(clip, OverviewSettings(), np.random.default_rng(rep))
        planning.append(time.perf_counter() - start)
    keys = sorted({k for s in stages for k in s})
    e2e, plan = summary(end_to_end), summary(planning)
    return {
        "frames": clip.frame_count,
        "fps": round(1.0 / clip.frame_time_s, 3),
        "end_to_end_s": e2e,
        "first_s": round(end_to_end[0], 3),
        "planning_only_s": plan,
        "ratio_end_to_end_vs_planning": round(e2e["median"] / plan["median"], 3),
        "under_10_s": e2e["median"] < 10.0,
        "job_stage_ms_median": {k: round(float(np.median([s[k] for s in stages if k in s])), 1) for k in keys},
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", type=Path, default=SHARED_DATA_DIR)
    parser.add_argument("--frames", type=int, default=1000, help="frames per clip (a shorter clip is taken whole)")
    parser.add_argument("--reps", type=int, default=3)
    parser.add_argument(
        "--clips",
        nargs="+",
        choices=sorted(CLIPS),
        default=list(LONG_CLIPS),
        help="default: the three clips longer than 1000 frames",
    )
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    mocap = shared_subfolder(args.data_dir, "mocap", "overview_bench")
    if mocap is None:
        return 2
    out = {"benchmark": "overview_end_to_end", "frames_per_clip": args.frames, "reps": args.reps, "clips": {}}
    with tempfile.TemporaryDirectory() as data_dir, ServerProcess("--data-dir", data_dir, transports=("http",)) as server:
        for name in args.clips:
            relative, skip = CLIPS[name]
            out["clips"][name] = bench_clip(server.http, mocap / relative, skip, args.frames, args.reps)
    emit(out, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
