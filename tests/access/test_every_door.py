"""Every door of a real server (each gRPC method, each ZeroMQ RPC, each REST route) walked with no
key, a revoked key, a key of each role and a key of another tenant, each answer checked against
the tables of docs/security.md, which are read from the page itself: the page is the contract.

The other tenant's key is an admin's (it holds every verb), so its only reason to be refused is
the tenant: its answer must be, word for word, the answer for an id that does not exist. The
owner's answer must not be that (the thing exists for it), nor 401/403 when its role has the verb.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import grpc
import httpx
import pytest
from fastapi.routing import iter_route_contexts
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha.proto_reflection_descriptor_database import ProtoReflectionDescriptorDatabase
from starlette.routing import Mount, Route

from camdirector.access.roles import ROLE_VERBS, Verb, allows
from camdirector.deploy.server_process import ServerProcess
from camdirector.front.http.app import build_app
from camdirector.front.http.routes.levels import install_level_routes
from camdirector.front.http.routes.overview import install_overview_routes
from camdirector.front.job_runner import open_jobs
from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionRouter
from camdirector.front.session_calls import RPCS
from camdirector.jobs import JobSettings, service_kinds
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from tests.precompute.tracks.tiny_levels import corridor
from tests.service import wire_client as wc
from tests.service.tracks_sessions import obj_text

DOC = Path(__file__).resolve().parents[2] / "docs" / "security.md"
ROLES = ("engine", "director", "viewer", "admin")
MISSING = {"session": "0123456789abcdef0123456789abcdef", "level": "nolevel", "job": "nojob", "key": "0badc0ffee00"}
UNAUTHENTICATED = {"401", "UNAUTHENTICATED"}
DENIED = {"403", "PERMISSION_DENIED"}


# -- the page -------------------------------------------------------------------------------------


def _table(heading: str) -> list[list[str]]:
    """The body rows (cells stripped of backticks) of the table in the page's section `heading`."""
    section = DOC.read_text().split(f"\n## {heading}\n", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("|")][2:]  # after the header and its rule
    return [[cell.strip().strip("`") for cell in row.strip().strip("|").split("|")] for row in rows]


@dataclass(frozen=True)
class Door:
    transport: str  # gRPC, ZeroMQ, HTTP
    name: str  # RPC name, or "METHOD /path"
    verb: str  # a Verb's value, "open" or "any key"
    owned: str  # "session", "level", "job", "key" or "" (what it reaches by id)


def doors() -> list[Door]:
    return [Door(*row) for row in _table("Every door")]


def test_the_role_table_of_the_page_is_the_code():
    table = {row[0]: {role for role, cell in zip(ROLES, row[2:]) if cell == "yes"} for row in _table("Roles and verbs")}
    assert set(table) == {verb.value for verb in Verb}
    for verb in Verb:
        assert table[verb.value] == {role for role in ROLES if verb in ROLE_VERBS[role]}, verb


def served_http_routes(data_dir: Path) -> set[str]:
    """Every route of the HTTP app as `camdirector serve` builds it (front/main.py: the app, then
    the job routes), documented or not, as "METHOD /path"; a mount is "GET /path/"."""
    settings = ServerSettings(workers=0, data_dir=str(data_dir))
    app = build_app(SessionRouter(settings, Metrics()), {"http": settings.http_addr})
    job_settings = JobSettings.for_server(settings)
    jobs = open_jobs(data_dir, service_kinds(), job_settings)  # not started
    install_overview_routes(app, jobs, job_settings)
    install_level_routes(app, jobs, data_dir, job_settings)
    served = set()
    for route in iter_route_contexts(app.routes):  # included routers' routes with their prefixes
        if isinstance(route.original_route, Mount):
            served.add(f"GET {route.path}/")
        else:
            assert isinstance(route.original_route, Route), route.original_route  # nothing else (no WebSocket)
            served |= {f"{method} {route.path}" for method in route.methods or () if method != "HEAD"}
    return served


def test_every_door_of_the_server_is_in_the_page(world, tmp_path):
    """Every route the app serves, the undocumented ones included (`/`, the dashboard's files, the
    OpenAPI document), is in the table; the document an admin reads names none other."""
    listed = {(d.transport, d.name) for d in doors()}
    routes = served_http_routes(tmp_path)
    openapi = httpx.get(f"{world.http}/openapi.json", headers=_auth(world.keys["admin"])).json()
    assert {f"{method.upper()} {path}" for path, ops in openapi["paths"].items() for method in ops} <= routes
    served = {("HTTP", route) for route in routes}
    served |= {("gRPC", m.name) for m in pb.DESCRIPTOR.services_by_name["Director"].methods}
    served |= {
        ("gRPC", "grpc.health.v1.Health/Check"),
        ("gRPC", "grpc.reflection.v1alpha.ServerReflection"),
    }
    served |= {("ZeroMQ", name) for name in RPCS if name != "StreamFrames"}
    assert listed == served


@pytest.mark.parametrize("path", ["/docs", "/redoc", "/docs/oauth2-redirect"])
def test_no_page_loads_scripts_from_elsewhere(world, path):
    """FastAPI's Swagger UI and ReDoc pages (scripts from a CDN in the cookie's origin) are not served."""
    assert httpx.get(world.http + path, headers=_auth(world.keys["admin"])).status_code == 404


# -- the server, its keys and one tenant's things ------------------------------------------------


@dataclass
class World:
    server: ServerProcess
    http: str
    keys: dict[str, str]  # caller -> key ("none": "")
    session_id: str
    level: str
    level_job: str
    overview_job: str
    frame: int = 100


def _cli_key(data_dir: Path, role: str, tenant: str) -> str:
    out = subprocess.run(
        [sys.executable, "-m", "camdirector", "keys", "create", "--role", role, "--tenant", tenant, "--data-dir", str(data_dir)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert len(out.splitlines()) == 1, out  # the key alone on one line
    return out.strip()


def _wait_job(http: str, route: str, job_id: str, key: str) -> str:
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        status = httpx.get(f"{http}{route}/{job_id}", headers=_auth(key), timeout=10).json()["status"]
        if status in ("succeeded", "failed", "cancelled"):
            return status
        time.sleep(0.2)
    raise AssertionError(f"{route}/{job_id} did not finish")


def _auth(key: str) -> dict:
    return {"Authorization": f"Bearer {key}"} if key else {}


@pytest.fixture(scope="module")
def world(tmp_path_factory, run_bvh):
    data_dir = tmp_path_factory.mktemp("doors")
    server = ServerProcess("--workers", "1", "--data-dir", str(data_dir), "--tenant-max-fps", "10000", auth=True)
    try:
        keys = {"none": ""}
        for role in ROLES:
            keys[role] = _cli_key(data_dir, role, "alpha")
        keys["other tenant"] = _cli_key(data_dir, "admin", "beta")
        keys["revoked"] = _cli_key(data_dir, "admin", "alpha")
        subprocess.run(
            [sys.executable, "-m", "camdirector", "keys", "revoke", keys["revoked"], "--data-dir", str(data_dir)],
            check=True,
            capture_output=True,
        )
        http = f"http://{server.http}"
        raw = wc.GrpcRaw(server.grpc, key=keys["engine"])
        session_id = raw.call("CreateSession", wc.two_target_request()).session_id
        raw.stream(wc.walk(session_id, 30))
        raw.close()
        posted = httpx.post(
            f"{http}/v1/levels",
            data={"name": "corridor"},
            headers=_auth(keys["admin"]),
            files={"level": ("level.obj", obj_text(corridor()))},
            timeout=30,
        )
        assert posted.status_code == 202, posted.text
        assert _wait_job(http, "/v1/level-jobs", posted.json()["id"], keys["admin"]) == "succeeded"
        overview = httpx.post(
            f"{http}/v1/overview-jobs", headers=_auth(keys["director"]), files={"file": ("run.bvh", run_bvh)}, timeout=30
        )
        assert overview.status_code == 202, overview.text
        assert _wait_job(http, "/v1/overview-jobs", overview.json()["id"], keys["director"]) == "succeeded"
        yield World(server, http, keys, session_id, "corridor", posted.json()["id"], overview.json()["id"])
    finally:
        assert server.stop() == 0, server.log_tail()


# -- calling a door -------------------------------------------------------------------------------


def _normal(text: str, ids: list[str]) -> str:
    for value in filter(None, ids):
        text = text.replace(value, "<ID>")
    return re.sub(r"[0-9a-f]{32}", "<ID>", text)


def _target(world: World, door: Door, owned: bool) -> str:
    """The id the door is called with: the alpha tenant's thing, or one that does not exist."""
    if not owned:
        return MISSING[door.owned]
    if door.name in ("CloseSession",):  # each call closes a fresh session of alpha's
        raw = wc.GrpcRaw(world.server.grpc, key=world.keys["engine"])
        session_id = raw.call("CreateSession", wc.two_target_request()).session_id
        raw.close()
        return session_id
    if door.owned == "key":  # each call revokes a fresh key of alpha's
        made = httpx.post(f"{world.http}/v1/keys", json={"role": "viewer"}, headers=_auth(world.keys["admin"]))
        return made.json()["id"]
    return {
        "session": world.session_id,
        "level": world.level,
        "job": world.level_job if "level-jobs" in door.name else world.overview_job,
    }[door.owned]


def _frames(world: World, session_id: str, n: int) -> list[pb.FrameUpdate]:
    world.frame += n
    return list(wc.walk(session_id, n, start_frame=world.frame))


def _rpc(world: World, door: Door, key: str, target: str) -> tuple[str, str]:
    requests = {
        "CreateSession": lambda: wc.two_target_request(),
        "Frame": lambda: _frames(world, target, 1)[0],
        "UpdateStyle": lambda: pb.UpdateStyleRequest(session_id=target, style=pb.Style()),
        "TakeShot": lambda: pb.TakeShotRequest(session_id=target, release=True),
        "CloseSession": lambda: pb.CloseSessionRequest(session_id=target),
    }
    if door.name == "grpc.health.v1.Health/Check":
        with grpc.insecure_channel(world.server.grpc) as channel:
            reply = health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(), timeout=10)
        return ("OK" if reply.status == health_pb2.HealthCheckResponse.SERVING else "NOT_SERVING"), ""
    if door.name == "grpc.reflection.v1alpha.ServerReflection":
        with grpc.insecure_channel(world.server.grpc) as channel:
            services = ProtoReflectionDescriptorDatabase(channel).get_services()
        return ("OK" if "camdirector.v1.Director" in services else "NO_DIRECTOR"), ""
    client = (
        wc.GrpcRaw(world.server.grpc, key=key or None)
        if door.transport == "gRPC"
        else wc.ZmqRaw(world.server.zmq, key=key or None, server_key=world.server.zmq_server_key)
    )
    try:
        if door.name == "StreamFrames":
            client.stream(_frames(world, target, 2))
        else:
            client.call(door.name, requests[door.name]())
        return "OK", ""
    except wc.RpcFailed as exc:
        return exc.code.name, exc.message
    finally:
        client.close()


def _http(world: World, door: Door, key: str, target: str) -> tuple[str, str]:
    method, path = door.name.split(" ", 1)
    url = world.http + re.sub(r"\{[a-z_]+\}", target, path)
    headers = _auth(key)
    kwargs: dict = {}
    if path.endswith("/style"):
        kwargs["json"] = {}
    elif path.endswith("/take"):
        kwargs["json"] = {"release": True}
    elif path == "/v1/keys" and method == "POST":
        kwargs["json"] = {"role": "viewer", "name": "door test"}
    elif path == "/v1/login":
        kwargs["json"] = {"key": world.keys["viewer"]}  # an open door: no Authorization needed
    elif method == "POST":
        kwargs["data"] = {"seed": "1"} if "overview" in path else {"name": "door-test"}  # no file: 422 once let in
    if path.endswith(".mjpeg"):
        with httpx.stream(method, url, headers=headers, params={"fps": 1}, timeout=30) as reply:
            return str(reply.status_code), "" if reply.status_code == 200 else reply.read().decode()
    reply = httpx.request(method, url, headers=headers, timeout=60, **kwargs)
    detail = reply.json().get("detail", "") if reply.headers.get("content-type", "").startswith("application/json") else ""
    return str(reply.status_code), str(detail)


def _call(world: World, door: Door, caller: str, owned: bool = True) -> tuple[str, str]:
    target = _target(world, door, owned) if door.owned else ""
    answer = (_http if door.transport == "HTTP" else _rpc)(world, door, world.keys[caller], target)
    return answer[0], _normal(answer[1], [target])


@pytest.mark.parametrize(
    "route, item",
    [
        ("/v1/sessions", "session_id"),
        ("/v1/levels", "name"),
        ("/v1/overview-jobs", "id"),
        ("/v1/level-jobs", "id"),
        ("/v1/keys", "id"),
    ],
)
def test_lists_show_only_the_callers_tenant(world, route, item):
    """(Before the doors' walk, which ends by deleting the level.)"""
    field = route.rsplit("/", 1)[1].replace("overview-", "").replace("level-", "")
    mine = httpx.get(world.http + route, headers=_auth(world.keys["admin"])).json()[field]
    theirs = httpx.get(world.http + route, headers=_auth(world.keys["other tenant"])).json()[field]
    assert mine, f"{route}: alpha has things here"
    assert not {x[item] for x in mine} & {x[item] for x in theirs}


# Deleting the level ends its door's walk, and comes after every door that reads it.
ORDER = sorted(doors(), key=lambda d: d.name == "DELETE /v1/levels/{name}")


@pytest.mark.parametrize("door", ORDER, ids=lambda d: f"{d.transport} {d.name}")
def test_each_caller_gets_the_answer_the_page_gives(world, door):
    answers = {}
    for caller in ("none", "revoked", "engine", "director", "viewer", "other tenant", "admin"):
        status, detail = answers[caller] = _call(world, door, caller)
        if door.verb == "open":
            assert status not in UNAUTHENTICATED | DENIED, (caller, detail)
        elif caller in ("none", "revoked"):
            assert status in UNAUTHENTICATED, (caller, status, detail)
        elif door.verb == "any key":
            assert status in ("200", "OK"), (caller, status, detail)
        elif not allows("admin" if caller == "other tenant" else caller, Verb(door.verb)):
            assert status in DENIED, (caller, status, detail)
            assert door.verb in detail  # says which verb the role lacks
        elif caller == "other tenant" and door.owned:
            assert (status, detail) == _call(world, door, caller, owned=False), "another tenant's thing shows"
        else:
            assert status not in UNAUTHENTICATED | DENIED, (caller, status, detail)
            if door.owned:
                assert (status, detail) != _call(world, door, caller, owned=False), (caller, "its own thing is missing")
