"""Every job and level route with the job store (PostgreSQL) or the job queue (Redis) down, in
queue mode on real services: 503 with Retry-After and words that name no URL, host or port,
never a 500. Redis down refuses only what needs the queue (a submit); reading and cancelling
need only the records. Uses a PostgreSQL of its own, which it stops and starts."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from camdirector.access.guard import Guard
from camdirector.deploy.services import PostgresServer
from camdirector.front.http.routes.levels import install_level_routes
from camdirector.front.http.routes.overview import install_overview_routes
from camdirector.front.job_runner import open_jobs
from camdirector.jobs import JobSettings, service_kinds
from tests.conftest import service_or_skip
from tests.precompute.tracks.tiny_levels import corridor
from tests.service.tracks_sessions import obj_text

pytestmark = pytest.mark.shared_data

JOB_ID = "0123456789abcdef0123456789abcdef"


@pytest.fixture
def own_postgres(tmp_path) -> Iterator[PostgresServer]:
    server = service_or_skip(lambda: PostgresServer(tmp_path / "pg").start())
    yield server
    server.stop()


@pytest.fixture
def client(tmp_path, own_postgres, redis_url) -> Iterator[TestClient]:
    settings = JobSettings(job_store=own_postgres.url, job_queue=redis_url)
    app = FastAPI()
    app.state.guard = Guard(None)  # authentication off, as a `--no-auth` node's app
    jobs = open_jobs(tmp_path / "data", service_kinds(), settings)
    install_overview_routes(app, jobs, settings)
    install_level_routes(app, jobs, tmp_path / "data", settings)
    with TestClient(app, raise_server_exceptions=False) as client:
        yield client
    jobs.close()


def submits(client: TestClient, run_bvh: bytes) -> dict:
    return {
        "POST /v1/overview-jobs": lambda: client.post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)}),
        "POST /v1/levels": lambda: client.post(
            "/v1/levels", data={"name": "corridor"}, files={"level": ("level.obj", obj_text(corridor()).encode())}
        ),
    }


def reads_and_cancels(client: TestClient) -> dict:
    return {
        f"{method} {path}": (lambda method=method, path=path: client.request(method, path))
        for method, path in [
            ("GET", "/v1/overview-jobs"),
            ("GET", f"/v1/overview-jobs/{JOB_ID}"),
            ("GET", f"/v1/overview-jobs/{JOB_ID}/result"),
            ("GET", f"/v1/overview-jobs/{JOB_ID}/preview.mp4"),
            ("GET", f"/v1/overview-jobs/{JOB_ID}/contact-sheet.png"),
            ("DELETE", f"/v1/overview-jobs/{JOB_ID}"),
            ("GET", "/v1/level-jobs"),
            ("GET", f"/v1/level-jobs/{JOB_ID}"),
            ("DELETE", f"/v1/level-jobs/{JOB_ID}"),
            ("GET", "/v1/levels"),
            ("GET", "/v1/levels/corridor"),
            ("DELETE", "/v1/levels/corridor"),
        ]
    }


def assert_unavailable(name: str, reply, hidden: list[str]) -> None:
    assert reply.status_code == 503, (name, reply.status_code, reply.text)
    assert reply.headers["retry-after"].isdigit(), name
    assert "retry later" in reply.json()["detail"], (name, reply.text)
    assert not [word for word in hidden if word in reply.text], (name, reply.text)


def test_the_job_store_down_answers_503_everywhere(client, own_postgres, run_bvh):
    hidden = ["postgresql", "127.0.0.1", str(own_postgres.port)]
    own_postgres.stop(keep_data=True)
    try:
        for name, call in {**submits(client, run_bvh), **reads_and_cancels(client)}.items():
            assert_unavailable(name, call(), hidden)
    finally:
        own_postgres.start()
    assert client.get("/v1/level-jobs").status_code == 200  # back with the store


def test_the_job_queue_down_refuses_submits_only(client, redis_server, run_bvh):
    hidden = ["redis", "127.0.0.1", str(redis_server.port)]
    redis_server.stop()
    try:
        for name, call in submits(client, run_bvh).items():
            assert_unavailable(name, call(), hidden)
        for name, call in reads_and_cancels(client).items():
            assert call().status_code in (200, 404), name  # no such job or level: the records answer
    finally:
        redis_server.start()
    assert client.get("/v1/overview-jobs").json()["jobs"][0]["error"] == "could not be queued: the job queue is unreachable"
