"""The /v1/overview-jobs routes (front/http/routes/overview.py) on a bare FastAPI app with a real
JobRunner (real job processes): every route, every kind of bad upload with its status and detail
(and nothing left behind), a full queue, and the OpenAPI listing. Uses the 72-frame run clip."""

from __future__ import annotations

import time

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from camdirector.access.guard import Guard
from camdirector.front.http.routes.overview import install_overview_routes
from camdirector.front.job_runner import open_jobs
from camdirector.jobs import JobSettings, service_kinds

pytestmark = pytest.mark.shared_data

LIMIT = 150_000  # bytes: the run clip is 92 kB


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    data_dir = tmp_path_factory.mktemp("overview-data")
    app = FastAPI()
    app.state.guard = Guard(None)  # authentication off, as a `--no-auth` node's app
    settings = JobSettings(max_upload_bytes=LIMIT, max_concurrent_jobs=1)
    runner = open_jobs(data_dir, service_kinds(), settings)
    install_overview_routes(app, runner, settings)
    runner.start()
    with TestClient(app) as client:
        yield client, runner
    runner.close()


def wait_finished(client, job_id, timeout_s=60.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        status = client.get(f"/v1/overview-jobs/{job_id}").json()
        if status["status"] in ("succeeded", "failed", "cancelled"):
            return status
        time.sleep(0.05)
    raise AssertionError(f"job {job_id} did not finish: {status}")


@pytest.fixture(scope="module")
def finished_jobs(service, run_bvh):
    """Two jobs on the run clip: defaults, and skip_frames=10 with a square aspect."""
    client, _ = service
    a = client.post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)})
    b = client.post(
        "/v1/overview-jobs",
        files={"file": ("run.bvh", run_bvh)},
        data={"skip_frames": "10", "aspect": "1.0", "seed": "3", "c5": "2"},
    )
    assert a.status_code == 202 and b.status_code == 202, (a.text, b.text)
    assert a.json()["status"] == "queued" and a.headers["location"].endswith(a.json()["id"])
    return {"default": wait_finished(client, a.json()["id"]), "skip": wait_finished(client, b.json()["id"])}


def test_job_status_and_timings(service, finished_jobs):
    status = finished_jobs["default"]
    assert status["status"] == "succeeded", status
    assert status["progress"] == 1.0 and "error" not in status
    for stage in (
        "parse_bvh",
        "saliency",
        "limb_visibility",
        "potential",
        "annealing_and_shots",
        "framing",
        "preview_video",
        "contact_sheet",
        "job_process_total",
    ):
        assert status["timings"][stage] >= 0.0


def test_result_has_one_frame_per_clip_frame(service, finished_jobs):
    client, _ = service
    result = client.get(f"/v1/overview-jobs/{finished_jobs['default']['id']}/result").json()
    assert result["fps"] == pytest.approx(30.0, rel=1e-4)
    assert len(result["frames"]) == 72
    assert [f["frame"] for f in result["frames"]] == list(range(72))
    first = result["frames"][0]
    assert set(first) == {"frame", "position", "look_at", "up", "vertical_fov_deg", "shot"}
    assert first["up"] == [0.0, 1.0, 0.0] and 0.0 < first["vertical_fov_deg"] < 150.0
    assert result["shots"][0]["start"] == 0 and result["shots"][-1]["end"] == 71
    assert {"E", "E_external", "V_sum", "ours_E_norm", "static_E_norm"} <= set(result["metrics"])
    skipped = client.get(f"/v1/overview-jobs/{finished_jobs['skip']['id']}/result").json()
    assert len(skipped["frames"]) == 62 and skipped["metrics"]["skip_frames"] == 10


def test_preview_and_contact_sheet(service, finished_jobs):
    client, _ = service
    job_id = finished_jobs["default"]["id"]
    video = client.get(f"/v1/overview-jobs/{job_id}/preview.mp4")
    assert video.status_code == 200 and video.headers["content-type"] == "video/mp4"
    assert video.content[4:8] == b"ftyp"
    sheet = client.get(f"/v1/overview-jobs/{job_id}/contact-sheet.png")
    assert sheet.status_code == 200 and sheet.headers["content-type"] == "image/png"
    assert sheet.content[:8] == b"\x89PNG\r\n\x1a\n"


def test_unknown_job_is_404_and_finished_job_cannot_be_cancelled(service, finished_jobs):
    client, _ = service
    for path in ("", "/result", "/preview.mp4", "/contact-sheet.png"):
        r = client.get(f"/v1/overview-jobs/0123abcd{path}")
        assert r.status_code == 404 and "no overview job" in r.json()["detail"]
    assert client.delete("/v1/overview-jobs/0123abcd").status_code == 404
    r = client.delete(f"/v1/overview-jobs/{finished_jobs['default']['id']}")
    assert r.status_code == 409 and "already succeeded" in r.json()["detail"]


def test_jobs_are_listed_newest_first_with_their_clip(service, finished_jobs):
    client, _ = service
    listed = client.get("/v1/overview-jobs").json()["jobs"]
    ids = [j["id"] for j in listed]
    first, second = finished_jobs["default"]["id"], finished_jobs["skip"]["id"]
    assert ids.index(second) < ids.index(first)
    row = next(j for j in listed if j["id"] == first)
    assert row["status"] == "succeeded" and row["file_name"] == "run.bvh" and row["frames"] == 72
    assert row["created_unix_s"] <= row["started_unix_s"] <= row["finished_unix_s"]
    assert next(j for j in listed if j["id"] == second)["frames"] == 62  # after skip_frames
    assert len(client.get("/v1/overview-jobs", params={"limit": 1}).json()["jobs"]) == 1
    assert all(j["status"] == "succeeded" for j in client.get("/v1/overview-jobs", params={"status": "succeeded"}).json()["jobs"])


@pytest.mark.parametrize(
    "query, field",
    [({"status": "done"}, "status"), ({"limit": "0"}, "limit"), ({"limit": "1001"}, "limit"), ({"limit": "x"}, "limit")],
)
def test_bad_list_queries_answer_422(service, query, field):
    client, _ = service
    r = client.get("/v1/overview-jobs", params=query)
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", field]


def _corrupt(data: bytes, kind: str) -> bytes:
    text = data.decode()
    if kind == "not_bvh":
        return b"ply\nformat ascii 1.0\nelement vertex 0\nend_header\n"
    if kind == "truncated":
        return data[: len(data) // 2]
    if kind == "truncated_hierarchy":
        return "\n".join(text.splitlines()[:20]).encode()
    if kind == "channel_count":
        return text.replace("CHANNELS 6 Xposition", "CHANNELS 5 Xposition", 1).encode()
    if kind == "row_values":
        lines = text.splitlines()
        lines[-1] = " ".join(lines[-1].split()[:-1])
        return "\n".join(lines).encode()
    if kind == "zero_frames":
        head, _, _ = text.partition("MOTION")
        return (head + "MOTION\nFrames: 0\nFrame Time: 0.0333333\n").encode()
    if kind == "empty":
        return b""
    if kind == "binary":
        return bytes(range(256)) * 4
    raise ValueError(kind)


@pytest.mark.parametrize(
    "kind, status, detail",
    [
        ("not_bvh", 400, "not a BVH file"),
        ("truncated", 400, "truncated BVH"),
        ("truncated_hierarchy", 400, "truncated BVH"),
        ("channel_count", 400, "inconsistent BVH channels"),
        ("row_values", 400, "inconsistent BVH channel count"),
        ("zero_frames", 400, "zero frames"),
        ("empty", 400, "empty upload"),
        ("binary", 400, "not a BVH file"),
    ],
)
def test_bad_uploads_answer_4xx_and_leave_nothing(service, run_bvh, kind, status, detail):
    client, runner = service
    before = (len(runner.store.list()), sorted(p.name for p in runner.store.root.iterdir()))
    r = client.post("/v1/overview-jobs", files={"file": ("clip.bvh", _corrupt(run_bvh, kind))})
    assert r.status_code == status, r.text
    assert detail in r.json()["detail"]
    assert (len(runner.store.list()), sorted(p.name for p in runner.store.root.iterdir())) == before


@pytest.mark.parametrize(
    "fields, status, detail",
    [
        ({"skip_frames": "72"}, 400, "skip_frames=72 must be in [0, 71]"),
        ({"skip_frames": "-1"}, 422, "skip_frames"),
        ({"scale": "0"}, 422, "scale"),
        ({"aspect": "9"}, 422, "aspect must be in [0.2, 5]"),
        ({"c1": "-1"}, 422, "c1..c5 must be in [0, 1e6]"),
        # the speed limits' form fields carry the settings' unit suffixes (`_heights_s`, `_deg_s`)
        ({"max_speed_heights_s": "0"}, 422, "max_speed_heights_s must be in (0, 100]"),
        ({"max_angular_speed_deg_s": "4000"}, 422, "max_angular_speed_deg_s must be in (0, 3600]"),
        ({"friction_speed_heights_s": "-1"}, 422, "friction_speed_heights_s must be in (0, 100]"),
        ({"split_quality": "nan"}, 422, "finite"),
        # a misspelt parameter is refused, not dropped (the job would run with the default)
        ({"min_shot": "3"}, 422, "unknown form field(s) min_shot; this route takes"),
        ({"c6": "1", "seeds": "2"}, 422, "unknown form field(s) c6, seeds"),
    ],
)
def test_bad_form_fields(service, run_bvh, fields, status, detail):
    client, runner = service
    count = len(runner.store.list())
    r = client.post("/v1/overview-jobs", files={"file": ("clip.bvh", run_bvh)}, data=fields)
    assert r.status_code == status, r.text
    assert detail in str(r.json()["detail"])
    assert len(runner.store.list()) == count


@pytest.mark.parametrize("size", [LIMIT + 1, 4 * LIMIT])
def test_huge_uploads_answer_413(service, run_bvh, size):
    # LIMIT + 1 is refused by the route; 4 x LIMIT by the middleware, before the body is read.
    client, runner = service
    count = len(runner.store.list())
    body = (run_bvh * (size // len(run_bvh) + 1))[:size]
    r = client.post("/v1/overview-jobs", files={"file": ("clip.bvh", body)})
    assert r.status_code == 413 and "larger than the limit" in r.json()["detail"]
    assert len(runner.store.list()) == count


def test_queue_full_429_result_409_and_cancel(tmp_path, run_bvh):
    app = FastAPI()
    app.state.guard = Guard(None)  # authentication off, as a `--no-auth` node's app
    settings = JobSettings(max_queued_jobs=1)
    runner = open_jobs(tmp_path, service_kinds(), settings)  # not started
    install_overview_routes(app, runner, settings)
    client = TestClient(app)
    first = client.post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)})
    assert first.status_code == 202
    r = client.post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)})
    assert r.status_code == 429 and "queue full" in r.json()["detail"]
    job_id = first.json()["id"]
    r = client.get(f"/v1/overview-jobs/{job_id}/result")
    assert r.status_code == 409 and "queued" in r.json()["detail"]
    r = client.delete(f"/v1/overview-jobs/{job_id}")
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    assert client.delete(f"/v1/overview-jobs/{job_id}").json()["status"] == "cancelled"
    assert client.post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)}).status_code == 202
    runner.close()


def test_openapi_lists_the_routes(service):
    client, _ = service
    spec = client.get("/openapi.json").json()
    paths = spec["paths"]
    assert set(paths["/v1/overview-jobs"]) == {"get", "post"}
    assert set(paths["/v1/overview-jobs/{job_id}"]) == {"get", "delete"}
    for suffix in ("result", "preview.mp4", "contact-sheet.png"):
        assert "get" in paths[f"/v1/overview-jobs/{{job_id}}/{suffix}"]
    form = paths["/v1/overview-jobs"]["post"]["requestBody"]["content"]["multipart/form-data"]
    assert client.get("/docs").status_code == 200
    assert form["schema"]["$ref"]


def test_a_submit_sent_again_with_its_idempotency_key_answers_the_first_job(tmp_path, run_bvh):
    app = FastAPI()
    app.state.guard = Guard(None)
    settings = JobSettings(max_queued_jobs=1)
    runner = open_jobs(tmp_path, service_kinds(), settings)  # not started: the job stays queued
    install_overview_routes(app, runner, settings)
    client = TestClient(app)
    post = lambda key, **data: client.post(  # noqa: E731
        "/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)}, data=data, headers={"Idempotency-Key": key}
    )
    first = post("lost-answer-1")
    assert first.status_code == 202 and "idempotent-replayed" not in first.headers
    again = post("lost-answer-1")  # the queue is full now: a replay is answered all the same
    assert again.status_code == 202 and again.json() == first.json(), again.text
    assert again.headers["idempotent-replayed"] == "true" and again.headers["location"] == first.headers["location"]
    assert len(client.get("/v1/overview-jobs").json()["jobs"]) == 1
    other = post("lost-answer-1", seed="9")
    assert other.status_code == 422 and "another request" in other.json()["detail"]
    assert post("x" * 129).status_code == 422  # longer than 128
    assert post("tab\there").status_code == 422  # not printable ASCII
    assert post("new-key").status_code == 429  # a new key is a new job: the queue is full
    runner.close()
