"""The level REST API on a real server: a level added over REST becomes a job that succeeds and a
session on it works; every bad upload answers its 4xx with a reason and leaves the registry as it
was; a cancelled job writes nothing and a removed level serves no new session; all while a TRACKS
session beside them keeps working."""

from __future__ import annotations

import math
import time

import grpc
import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from tests.precompute.tracks.tiny_levels import corridor, l_room
from tests.service.test_bad_input import expect
from tests.service.tracks_sessions import actor_frames, check_directed, corridor_walk, obj_text, tracks_canary, tracks_request
from tests.service.wire_client import GrpcRaw

UPLOAD_LIMIT = 16 * 1024
START = (2.0, 0.0, 2.0)


@pytest.fixture(scope="module")
def level_server(tmp_path_factory):
    data_dir = tmp_path_factory.mktemp("level-routes")
    srv = ServerProcess("--workers", "1", "--data-dir", str(data_dir), "--max-upload-bytes", str(UPLOAD_LIMIT))
    srv.data_dir = data_dir
    srv.http_client = httpx.Client(base_url=f"http://{srv.http}", timeout=30.0)
    yield srv
    srv.http_client.close()
    assert srv.stop() == 0, "server did not exit cleanly"


def post_level(srv, name: str, content: bytes, file_name: str = "level.obj", **form):
    return srv.http_client.post(
        "/v1/levels", data={"name": name, **{k: str(v) for k, v in form.items()}}, files={"level": (file_name, content)}
    )


def wait_job(srv, job_id: str, timeout_s: float = 60.0) -> tuple[dict, list[float]]:
    """The finished job's status, and the progress values seen while polling."""
    seen = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = srv.http_client.get(f"/v1/level-jobs/{job_id}").json()
        seen.append(job["progress"])
        if job["status"] in ("succeeded", "failed", "cancelled"):
            return job, seen
        time.sleep(0.05)
    raise AssertionError(f"job {job_id} did not finish in {timeout_s} s")


@pytest.fixture(scope="module")
def corridor_level(level_server):
    """The corridor, added over REST (the module's first job)."""
    reply = post_level(level_server, "corridor", obj_text(corridor()).encode())
    assert reply.status_code == 202, reply.text
    assert reply.headers["location"] == f"/v1/level-jobs/{reply.json()['id']}"
    job, seen = wait_job(level_server, reply.json()["id"])
    assert job["status"] == "succeeded", job
    return job, seen


def test_openapi_shows_the_level_routes(level_server):
    paths = level_server.http_client.get("/openapi.json").json()["paths"]
    assert {"post", "get"} <= set(paths["/v1/levels"]) and "get" in paths["/v1/levels/{name}"]
    assert "get" in paths["/v1/level-jobs/{job_id}"]


def test_a_level_added_over_rest_serves_a_session(level_server, corridor_level):
    job, seen = corridor_level
    assert job["name"] == "corridor" and job["progress"] == 1.0 and "error" not in job
    assert seen == sorted(seen) and all(0.0 <= p <= 1.0 for p in seen)
    assert {"skeleton", "clustering", "graph", "visibility", "job_process_total"} <= set(job["timings"])
    level = level_server.http_client.get("/v1/levels/corridor").json()
    assert level["counts"]["nodes"] > 0 and level["agent_height_m"] == 2.0 and level["m_per_unit"] == 1.0
    assert [lv["name"] for lv in level_server.http_client.get("/v1/levels").json()["levels"]] == ["corridor"]
    raw = GrpcRaw(level_server.grpc)
    session_id = raw.call("CreateSession", tracks_request("corridor", START)).session_id
    times, feet = corridor_walk(3.0)
    check_directed(raw.stream(actor_frames(session_id, times, feet)), feet)
    # the session over REST, as the dashboard sees and directs it
    http = level_server.http_client
    detail = http.get(f"/v1/sessions/{session_id}", params={"last": 10}).json()
    assert detail["style"]["rig"] == "RIG_TRACKS" and len(detail["frames"]) == 10
    assert len(detail["frames"][-1]["targets"]) == 1
    assert all(math.isfinite(f["framing_error"]) and f["framing_error"] >= 0.0 for f in detail["frames"])
    first = http.get(f"/v1/sessions/{session_id}", params={"after_frame": 0, "last": 600}).json()["frames"][0]
    assert first["cut"] and set(first["scores"]) == {
        "shot_size",
        "direct_visibility",
        "indirect_visibility",
        "total",
    }  # the first shot: no continuity terms
    moving = [f["scores"] for f in detail["frames"] if f["scores"] and not f["cut"]]
    assert moving and all(
        set(m) == {"shot_size", "direct_visibility", "indirect_visibility", "graph_distance", "total"} for m in moving
    )
    assert all(0.0 <= v <= 1.0 for m in moving for v in m.values())
    refused = http.put(f"/v1/sessions/{session_id}/style", json={"shotSize": "SHOT_SIZE_MEDIUM"})
    assert refused.status_code == 409 and "RIG_TRACKS" in refused.json()["detail"]  # the rig cannot change
    assert http.get(f"/v1/sessions/{session_id}/amap.png").status_code == 409  # no maps on tracks
    changed = http.put(f"/v1/sessions/{session_id}/style", json={"rig": "RIG_TRACKS", "shotSize": "SHOT_SIZE_MEDIUM"})
    assert changed.status_code == 200, changed.text
    more_times, more_feet = corridor_walk(1.0)
    after = raw.stream(actor_frames(session_id, more_times + times[-1] + 1 / 30, more_feet, start_frame=len(times) + 1))
    assert len(after) == len(more_times) and not any(u.stale for u in after)
    assert http.get(f"/v1/sessions/{session_id}").json()["style"]["shotSize"] == "SHOT_SIZE_MEDIUM"
    raw.close()


@pytest.fixture
def canary(level_server, corridor_level):
    """A TRACKS session on the REST-added level, streamed before and after each test."""
    with tracks_canary(level_server, "corridor", START):
        yield


def artifact_files(srv) -> set[str]:
    return {
        p.name
        for p in (srv.data_dir / "levels").iterdir()
        if p.name != "index.sqlite3" and "-wal" not in p.name and "-shm" not in p.name
    }


def test_bad_uploads_answer_4xx_and_write_nothing(level_server, canary):
    files_before = artifact_files(level_server)
    good = obj_text(l_room()).encode()
    cases = [
        (dict(name="../escape", content=good), 422, "level name '../escape'"),
        (dict(name="", content=good), 422, ""),
        (dict(name="x" * 65, content=good), 422, "1-64 letters"),
        (dict(name="notes", content=good, file_name="level.txt"), 400, "must end in .obj or .glb"),
        (dict(name="empty", content=b""), 400, "level: empty upload"),
        (dict(name="text", content=b"hello, not a mesh\n"), 400, "not a usable mesh: obj payload holds no triangles"),
        (dict(name="binary", content=b"\x00\x01\x02" * 50), 400, "not an OBJ file"),
        (dict(name="flat", content=b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"), 400, "degenerate"),
        (dict(name="glb", content=b"garbage", file_name="level.glb"), 400, "glTF magic"),
        (dict(name="tiny", content=obj_text(l_room()).encode(), scale=1e-7), 400, "degenerate mesh"),
        (dict(name="huge", content=b"# " + b"x" * (UPLOAD_LIMIT + 10) + b"\n" + good), 413, "larger than the limit"),
        (dict(name="noscale", content=good, scale=0), 422, ""),
        (dict(name="giant", content=good, agent_height=500), 422, "agent_height_m must be in [0.1, 100]"),
        (dict(name="typo", content=good, agent_heigth=1.8), 422, "unknown form field(s) agent_heigth"),
        (dict(name="corridor", content=good), 409, "level 'corridor' exists"),
    ]
    for kwargs, status, detail in cases:
        reply = post_level(level_server, **kwargs)
        assert reply.status_code == status, (kwargs["name"], reply.text)
        assert detail in str(reply.json()["detail"]), (kwargs["name"], reply.text)
    no_file = level_server.http_client.post("/v1/levels", data={"name": "nofile"})
    assert no_file.status_code == 422 and "level" in no_file.text
    assert level_server.http_client.get("/v1/levels/nosuch").status_code == 404
    assert level_server.http_client.get("/v1/level-jobs/0123abc").status_code == 404
    # a mesh that parses but has nothing to walk on (its one triangle faces down) fails its job
    reply = post_level(level_server, "ceiling", b"v 0 0 0\nv 10 0 0\nv 0 0 10\nf 1 2 3\n")
    assert reply.status_code == 202, reply.text
    job, _ = wait_job(level_server, reply.json()["id"])
    assert job["status"] == "failed" and "no walkable surface" in job["error"], job
    assert level_server.http_client.get("/v1/levels/ceiling").status_code == 404
    names = [lv["name"] for lv in level_server.http_client.get("/v1/levels").json()["levels"]]
    assert names == ["corridor"] and artifact_files(level_server) == files_before


def test_duplicate_names_need_replace(level_server, canary):
    first = post_level(level_server, "room", obj_text(l_room()).encode())
    assert first.status_code == 202, first.text
    pending = post_level(level_server, "room", obj_text(l_room()).encode())
    assert pending.status_code == 409 and "being added" in pending.json()["detail"]
    assert wait_job(level_server, first.json()["id"])[0]["status"] == "succeeded"
    created = level_server.http_client.get("/v1/levels/room").json()["created_unix_s"]
    assert post_level(level_server, "room", obj_text(l_room()).encode()).status_code == 409
    again = post_level(level_server, "room", obj_text(l_room()).encode(), replace="true")
    assert again.status_code == 202
    assert wait_job(level_server, again.json()["id"])[0]["status"] == "succeeded"
    assert level_server.http_client.get("/v1/levels/room").json()["created_unix_s"] > created
    raw = GrpcRaw(level_server.grpc)
    session_id = raw.call("CreateSession", tracks_request("room", START)).session_id
    times, feet = corridor_walk(1.0, speed_m_s=1.0)  # x 2..3 along the L's first arm
    check_directed(raw.stream(actor_frames(session_id, times, feet)), feet)
    raw.close()


def test_a_level_submit_sent_again_with_its_idempotency_key_answers_the_first_job(level_server, canary):
    """The name is being added by the first submit: a replay with its key is answered that job,
    not 409; the key with another level is 422."""
    key = {"Idempotency-Key": "add-hall-1"}
    post = lambda content: level_server.http_client.post(  # noqa: E731
        "/v1/levels", data={"name": "hall"}, files={"level": ("level.obj", content)}, headers=key
    )
    first = post(obj_text(l_room()).encode())
    assert first.status_code == 202, first.text
    again = post(obj_text(l_room()).encode())
    assert again.status_code == 202 and again.json()["id"] == first.json()["id"]
    assert again.headers["idempotent-replayed"] == "true"
    other = post(obj_text(corridor()).encode())
    assert other.status_code == 422 and "another request" in other.json()["detail"]
    assert wait_job(level_server, first.json()["id"])[0]["status"] == "succeeded"
    assert post(obj_text(l_room()).encode()).json()["id"] == first.json()["id"]  # the level exists now: still the replay


def test_cancelled_jobs_and_removed_levels(level_server, canary):
    http = level_server.http_client
    added = post_level(level_server, "gone", obj_text(l_room()).encode())
    assert wait_job(level_server, added.json()["id"])[0]["status"] == "succeeded"
    gone_file = level_server.http_client.get("/v1/levels/gone").json()
    raw = GrpcRaw(level_server.grpc)
    on_gone = raw.call("CreateSession", tracks_request("gone", START)).session_id
    # one job runs at a time: the replace queues behind this one, so both answers below come
    # while it is still pending
    blocker = post_level(level_server, "blocker", obj_text(corridor()).encode())
    replacing = post_level(level_server, "gone", obj_text(l_room()).encode(), replace="true")
    assert blocker.status_code == replacing.status_code == 202
    busy = http.delete("/v1/levels/gone")
    assert busy.status_code == 409 and "cancel it" in busy.json()["detail"]
    cancelled = http.delete(f"/v1/level-jobs/{replacing.json()['id']}")
    assert cancelled.status_code == 200, cancelled.text
    assert cancelled.json()["status"] == "cancelled" and cancelled.json()["name"] == "gone"
    assert http.delete(f"/v1/level-jobs/{replacing.json()['id']}").json()["status"] == "cancelled"  # no-op
    assert wait_job(level_server, blocker.json()["id"])[0]["status"] == "succeeded"
    finished = http.delete(f"/v1/level-jobs/{blocker.json()['id']}")
    assert finished.status_code == 409 and "already succeeded" in finished.json()["detail"]
    assert http.delete("/v1/level-jobs/no-such-job").status_code == 404
    listed = http.get("/v1/level-jobs").json()["jobs"]  # newest first, with the level's name
    assert [(j["id"], j["name"], j["status"]) for j in listed[:2]] == [
        (replacing.json()["id"], "gone", "cancelled"),
        (blocker.json()["id"], "blocker", "succeeded"),
    ]
    assert [j["id"] for j in http.get("/v1/level-jobs", params={"status": "cancelled"}).json()["jobs"]] == [
        replacing.json()["id"]
    ]
    assert http.get("/v1/level-jobs", params={"status": "done"}).status_code == 422
    # the overview routes share the job store but do not see level jobs
    assert http.get("/v1/overview-jobs").json()["jobs"] == []
    assert http.get(f"/v1/overview-jobs/{blocker.json()['id']}").status_code == 404
    assert http.delete(f"/v1/overview-jobs/{blocker.json()['id']}").status_code == 404
    # the cancelled replace wrote nothing: the level is the first version
    assert http.get("/v1/levels/gone").json() == gone_file

    before = artifact_files(level_server)
    removed = http.delete("/v1/levels/gone")
    assert removed.status_code == 200 and removed.json()["name"] == "gone"
    assert http.get("/v1/levels/gone").status_code == 404
    assert "gone" not in {level["name"] for level in http.get("/v1/levels").json()["levels"]}
    assert len(before - artifact_files(level_server)) == 1 and not artifact_files(level_server) - before
    assert http.delete("/v1/levels/gone").status_code == 404
    expect(
        grpc.StatusCode.NOT_FOUND,
        raw.call,
        "CreateSession",
        tracks_request("gone", START),
        contains="'gone' is not in this server's level registry",
    )
    times, feet = corridor_walk(1.0, speed_m_s=1.0)  # the session made before keeps its copy
    check_directed(raw.stream(actor_frames(on_gone, times, feet)), feet)
    raw.close()
