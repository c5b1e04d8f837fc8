"""Levels and offline jobs belong to tenants, on a real server with keys: another tenant's level,
level job or overview job answers 404 as an unknown one on every route; two tenants each have
their own "arena", and a TRACKS session finds its own tenant's (also once restored on a new worker
from its checkpoint), a tenant without one gets NOT_FOUND; a tenant past its share of jobs or of
stored uploads is answered 429; adding and deleting a level are in the tenant's audit trail.

Keys of other tenants are made in the server's own records database (its data directory), as
`camdirector keys create --tenant` makes them."""

from __future__ import annotations

import os
import signal
import time

import grpc
import httpx
import pytest

from camdirector.access.keys import open_access_store
from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from tests.precompute.tracks.tiny_levels import corridor, l_room
from tests.service.test_bad_input import expect
from tests.service.tracks_sessions import actor_frames, check_directed, corridor_walk, obj_text, tracks_request
from tests.service.wire_client import GrpcRaw

pytestmark = pytest.mark.shared_data

START = (2.0, 0.0, 2.0)
OVERVIEW_FILES = ("", "/result", "/preview.mp4", "/contact-sheet.png")


@pytest.fixture(scope="module")
def service(tmp_path_factory, run_bvh):
    """A server with keys, one job at a time, and tenant shares of 2 jobs and 2.5 run clips of
    uploads; keys of tenants acme and beta (admins), gamma (a director) and beta's viewer."""
    data_dir = tmp_path_factory.mktemp("tenants")
    srv = ServerProcess(
        "--workers",
        "1",
        "--data-dir",
        str(data_dir),
        "--max-concurrent-jobs",
        "1",
        "--tenant-max-queued-jobs",
        "2",
        "--tenant-max-upload-bytes",
        str(int(2.5 * len(run_bvh))),
        auth=True,
    )
    store = open_access_store("", data_dir)
    keys = {
        "default": srv.admin_key,
        **{
            f"{tenant}-{role}": store.create_key(role, tenant)[1]
            for tenant, role in (("acme", "admin"), ("beta", "admin"), ("beta", "viewer"), ("gamma", "director"))
        },
    }
    store.close()
    clients = {
        who: httpx.Client(base_url=f"http://{srv.http}", headers={"Authorization": f"Bearer {key}"}, timeout=30.0)
        for who, key in keys.items()
    }
    yield srv, keys, clients
    for client in clients.values():
        client.close()
    assert srv.stop() == 0, "server did not exit cleanly"


def finished(client: httpx.Client, route: str, job_id: str, timeout_s: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = client.get(f"{route}/{job_id}").json()
        if job["status"] in ("succeeded", "failed", "cancelled"):
            return job
        time.sleep(0.1)
    raise AssertionError(f"{route}/{job_id} did not finish in {timeout_s} s")


def add_level(client: httpx.Client, name: str, content: bytes) -> dict:
    posted = client.post("/v1/levels", data={"name": name}, files={"level": ("level.obj", content)})
    assert posted.status_code == 202, posted.text
    job = finished(client, "/v1/level-jobs", posted.json()["id"])
    assert job["status"] == "succeeded", job
    return job


def unknown(reply: httpx.Response, detail: str) -> bool:
    """The answer to an unknown level or job: 404 with the same words."""
    return reply.status_code == 404 and reply.json()["detail"] == detail


def test_each_tenant_has_its_own_arena_and_its_sessions_use_it(service):
    srv, keys, http = service
    acme, beta = http["acme-admin"], http["beta-admin"]
    acme_job = add_level(acme, "arena", obj_text(corridor()).encode())
    acme_arena = acme.get("/v1/levels/arena").json()
    # acme's level and its job are no one else's
    for who in ("beta-admin", "beta-viewer", "default"):
        assert unknown(http[who].get("/v1/levels/arena"), "no level named 'arena'")
        assert http[who].get("/v1/levels").json()["levels"] == []
        assert unknown(http[who].get(f"/v1/level-jobs/{acme_job['id']}"), f"no level job {acme_job['id']!r}")
        assert http[who].get("/v1/level-jobs").json()["jobs"] == []
    assert unknown(beta.delete("/v1/levels/arena"), "no level named 'arena'")
    assert unknown(beta.delete(f"/v1/level-jobs/{acme_job['id']}"), f"no level job {acme_job['id']!r}")
    assert http["beta-viewer"].post("/v1/levels", data={"name": "x"}).status_code == 403  # level.write: admins
    beta_session = GrpcRaw(srv.grpc, key=keys["beta-admin"])
    expect(
        grpc.StatusCode.NOT_FOUND,
        beta_session.call,
        "CreateSession",
        tracks_request("arena", START),
        contains="'arena' is not in this server's level registry",
    )

    beta_job = add_level(beta, "arena", obj_text(l_room()).encode())
    beta_arena = beta.get("/v1/levels/arena").json()
    assert acme.get("/v1/levels/arena").json() == acme_arena and beta_arena["counts"] != acme_arena["counts"]
    assert [level["name"] for level in beta.get("/v1/levels").json()["levels"]] == ["arena"]
    assert [j["id"] for j in beta.get("/v1/level-jobs").json()["jobs"]] == [beta_job["id"]]
    # beta's session on "arena" is beta's: it outlives its worker (restored from its checkpoint,
    # which has to find beta's level again on the new worker)
    session_id = beta_session.call("CreateSession", tracks_request("arena", START)).session_id
    times, feet = corridor_walk(2.0, speed_m_s=1.0)  # x 2..4 along the L's first arm
    check_directed(beta_session.stream(actor_frames(session_id, times[:30], feet[:30])), feet[:30])
    killed = srv.worker_pids()[0]
    os.kill(killed, signal.SIGKILL)
    deadline = time.monotonic() + 60
    while srv.worker_pids() in ([], [killed]):  # the front has noticed and started another
        assert time.monotonic() < deadline, "no worker replaced the one killed"
        time.sleep(0.05)
    after = beta_session.stream(actor_frames(session_id, times[30:], feet[30:], start_frame=31))
    assert len(after) == len(times) - 30 and not any(u.stale for u in after)
    # a tenant without an "arena" has none, also when it writes another tenant's name for it
    default_session = GrpcRaw(srv.grpc, key=keys["default"])
    for level_id in ("arena", "beta/arena"):
        expect(
            grpc.StatusCode.NOT_FOUND,
            default_session.call,
            "CreateSession",
            tracks_request(level_id, START),
            contains="is not in this server's level registry",
        )

    removed = beta.delete("/v1/levels/arena")
    assert removed.status_code == 200 and removed.json() == beta_arena
    assert acme.get("/v1/levels/arena").json() == acme_arena
    expect(
        grpc.StatusCode.NOT_FOUND,
        beta_session.call,
        "CreateSession",
        tracks_request("arena", START),
        contains="'arena' is not in this server's level registry",
    )
    beta_session.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    beta_session.close()
    default_session.close()

    def level_changes(client: httpx.Client) -> list[tuple[str, dict]]:
        trail = client.get("/v1/audit").json()["entries"]
        return [(e["action"], e["detail"]) for e in trail if e["action"].startswith("level.")]

    submitted = "job submitted: the level is registered when the job succeeds"
    assert level_changes(acme) == [
        ("level.add", {"name": "arena", "replace": False, "job_id": acme_job["id"], "stage": submitted})
    ]
    assert level_changes(beta) == [
        ("level.add", {"name": "arena", "replace": False, "job_id": beta_job["id"], "stage": submitted}),
        ("level.delete", {"name": "arena"}),
    ]
    assert level_changes(http["default"]) == []


def test_a_tenants_overview_jobs_are_its_own(service, run_bvh):
    _, _, http = service
    acme = http["acme-admin"]
    posted = acme.post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)})
    assert posted.status_code == 202, posted.text
    job_id = posted.json()["id"]
    assert finished(acme, "/v1/overview-jobs", job_id)["status"] == "succeeded"
    for path in OVERVIEW_FILES:
        assert acme.get(f"/v1/overview-jobs/{job_id}{path}").status_code == 200
    for who in ("beta-admin", "beta-viewer", "gamma-director", "default"):
        for path in OVERVIEW_FILES:
            assert unknown(http[who].get(f"/v1/overview-jobs/{job_id}{path}"), f"no overview job {job_id!r}")
        assert job_id not in {j["id"] for j in http[who].get("/v1/overview-jobs").json()["jobs"]}
    for who in ("beta-admin", "gamma-director"):
        assert unknown(http[who].delete(f"/v1/overview-jobs/{job_id}"), f"no overview job {job_id!r}")
    assert http["beta-viewer"].delete(f"/v1/overview-jobs/{job_id}").status_code == 403  # job.cancel
    assert http["beta-viewer"].post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)}).status_code == 403
    assert [j["id"] for j in acme.get("/v1/overview-jobs").json()["jobs"]] == [job_id]


def test_a_tenant_past_its_share_of_jobs_or_uploads_is_answered_429(service, run_bvh):
    _, _, http = service
    gamma = http["gamma-director"]

    def submit() -> httpx.Response:
        return gamma.post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)})

    first, second = submit(), submit()
    assert first.status_code == second.status_code == 202, (first.text, second.text)
    refused = submit()
    assert refused.status_code == 429
    assert refused.json()["detail"] == ("tenant 'gamma' has 2 jobs queued or running, its limit; retry when one has finished")
    other = http["beta-admin"].post("/v1/overview-jobs", files={"file": ("run.bvh", run_bvh)})
    assert other.status_code == 202, other.text  # beta's share is its own
    for job in (first, second, other):
        client = http["beta-admin"] if job is other else gamma
        assert client.delete(f"/v1/overview-jobs/{job.json()['id']}").json()["status"] == "cancelled"
    refused = submit()  # no job pending now, but their uploads are kept with them
    assert refused.status_code == 429
    assert refused.json()["detail"] == (
        f"tenant 'gamma''s jobs keep {2 * len(run_bvh)} bytes of uploads; {len(run_bvh)} more would pass its "
        f"limit of {int(2.5 * len(run_bvh))} bytes (a finished job's files are removed when its retention ends)"
    )
    assert len(gamma.get("/v1/overview-jobs").json()["jobs"]) == 2
