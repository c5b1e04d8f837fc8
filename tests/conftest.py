"""Fixtures shared by the whole suite: a real `camdirector serve` process, the shared data, and
the release artifacts (`make dist`)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from camdirector.deploy.server_process import ServerProcess

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data; skipped with a reason where absent, a failure under CI (.ci/run)."""
    if not SHARED_DATA.is_dir():
        if os.environ.get("CAMDIRECTOR_REQUIRE_SHARED_DATA") == "1":
            pytest.fail(f"{SHARED_DATA} is required (CAMDIRECTOR_REQUIRE_SHARED_DATA=1)")
        pytest.skip(f"{SHARED_DATA} is absent: third-party levels and clips are not in this clone")
    return SHARED_DATA


@pytest.fixture(scope="session")
def run_bvh(shared_data) -> bytes:
    """The motion-capture clip of a run (../shared/data/mocap), as a client uploads it."""
    from tests.precompute.overview.overview_mocap import CLIPS

    return (shared_data / "mocap" / CLIPS["run"][0]).read_bytes()


@pytest.fixture(scope="session")
def server(tmp_path_factory):
    """One shared server with two worker processes for the integration tests."""
    data_dir = tmp_path_factory.mktemp("server-data")
    srv = ServerProcess(
        "--workers",
        "2",
        "--data-dir",
        str(data_dir),
        "--max-sessions",
        "32",
        "--max-message-bytes",
        str(4 * 1024 * 1024),
        "--max-triangles",
        "200000",
    )
    yield srv
    assert srv.stop() == 0, "server did not exit cleanly"


@pytest.fixture
def server_factory():
    """Starts servers with custom flags; stops them after the test."""
    started = []

    def start(*args: str, env: dict | None = None) -> ServerProcess:
        srv = ServerProcess(*args, env=env)
        started.append(srv)
        return srv

    yield start
    for srv in started:
        srv.stop()


def service_or_skip(start):
    """A Debian service started for the tests, or a skip with the reason where its package is
    missing; a failure under CI (.ci/run sets CAMDIRECTOR_REQUIRE_CLUSTER=1)."""
    from camdirector.deploy.services import ServiceError

    try:
        return start()
    except ServiceError as exc:
        if os.environ.get("CAMDIRECTOR_REQUIRE_CLUSTER") == "1":
            pytest.fail(f"{exc} (CAMDIRECTOR_REQUIRE_CLUSTER=1)")
        pytest.skip(str(exc))


@pytest.fixture(scope="session")
def redis_server(tmp_path_factory):
    """One redis-server on a free loopback port for the whole run (deploy/services.py)."""
    from camdirector.deploy.services import RedisServer

    server = service_or_skip(lambda: RedisServer(tmp_path_factory.mktemp("redis")).start())
    yield server
    server.stop()


@pytest.fixture
def redis_url(redis_server) -> str:
    """The shared Redis, emptied for each test."""
    import redis

    client = redis.from_url(redis_server.url)
    client.flushall()
    client.close()
    return redis_server.url


@pytest.fixture(scope="session")
def postgres_server(tmp_path_factory):
    """One PostgreSQL cluster on a free loopback port for the whole run (deploy/services.py)."""
    from camdirector.deploy.services import PostgresServer

    server = service_or_skip(lambda: PostgresServer(tmp_path_factory.mktemp("postgres")).start())
    yield server
    server.stop()


@pytest.fixture(params=["sqlite", "postgres"])
def records_url(request) -> str:
    """Where records go, each test run on both: "" (the embedded SQLite default) or a fresh
    PostgreSQL database's URL (postgres_url)."""
    return "" if request.param == "sqlite" else request.getfixturevalue("postgres_url")


@pytest.fixture
def postgres_url(postgres_server) -> str:
    """A new empty database on the shared PostgreSQL cluster, dropped after the test."""
    import uuid

    import psycopg

    name = f"test_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres_server.url, autocommit=True) as admin:
        admin.execute(f"CREATE DATABASE {name}")
    yield postgres_server.url.rsplit("/", 1)[0] + "/" + name
    with psycopg.connect(postgres_server.url, autocommit=True) as admin:
        admin.execute(f"DROP DATABASE {name} WITH (FORCE)")


@pytest.fixture(scope="session")
def tls_files(tmp_path_factory):
    """A CA and a server certificate for 127.0.0.1 and localhost (camdirector.deploy.tls)."""
    from camdirector.deploy.tls import make_tls_files

    return make_tls_files(tmp_path_factory.mktemp("tls"))


def why_no_image() -> str | None:
    """Why the service image cannot be built and saved here (podman, runc, debootstrap, root), or
    None when it can."""
    from camdirector.deploy.image import require_podman
    from camdirector.deploy.services import ServiceError

    try:
        require_podman()
    except ServiceError as exc:
        return str(exc)
    if shutil.which("debootstrap") is None and not Path("/usr/sbin/debootstrap").exists():
        return "debootstrap is not installed (Debian package debootstrap; scripts/system-deps.sh --tests)"
    if os.geteuid() != 0:
        return "podman and debootstrap run as root here; these tests do not run as root"
    return None


@pytest.fixture(scope="session")
def release_dist(tmp_path_factory) -> Path:
    """`make dist`'s artifacts of this checkout (scripts/dist.sh: every wheel built from its sdist),
    built once per run into a folder outside the checkout: tests/test_dist.py checks them and
    tests/test_installed_package.py installs these same wheels. `python -m build` runs under this
    interpreter (the dev extra's `build`) with a bare PATH, so nothing of the caller's environment
    and nothing but the wheels reaches an environment they are installed into."""
    out = tmp_path_factory.mktemp("dist")
    assert not out.resolve().is_relative_to(ROOT), "the distributions must be built outside the checkout"
    # the image only where podman runs (root); tests/test_dist.py says so where it is left out
    no_image = {"NO_IMAGE": "1"} if why_no_image() else {}
    # cargo's folder too (rustup puts it in ~/.cargo/bin): the server's wheel compiles camdirector._native
    cargo = shutil.which("cargo")
    path = "/usr/bin:/bin:/usr/sbin:/sbin" + (f":{Path(cargo).parent}" if cargo else "")
    done = subprocess.run(
        ["bash", str(ROOT / "scripts" / "dist.sh"), str(out)],
        capture_output=True,
        text=True,
        env={"PATH": path, "PYTHON": sys.executable, **no_image},
    )
    assert done.returncode == 0, f"scripts/dist.sh failed:\n{done.stdout[-5000:]}\n{done.stderr[-5000:]}"
    return out
