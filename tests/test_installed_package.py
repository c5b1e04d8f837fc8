"""What users install, tested. The wheels of the main project, proto/ and client_sdk/python/, each
built from its sdist by `make dist` (tests/conftest.py's release_dist: built once per run, the same
files tests/test_dist.py checks), are installed, not editable, into a fresh venv by
scripts/install-dist.sh --prebuilt: the install step of docker/Dockerfile's script, which there
builds the same way first (tests/deploy/test_image.py builds that image). That venv's
`camdirector`, imported from its own site-packages and run outside this checkout with PYTHONPATH
cleared, then serves every rig over gRPC and ZeroMQ, adds a level over REST, runs an overview job,
serves the dashboard with its assets and a monitor's picture, and finds its shipped scenarios. A
module, a dependency or a data file that the distributions leave out fails here, never skips.

The venv is made by the interpreter running the tests (the project's Python 3.11, requires-python),
so no other interpreter need be on PATH; pip's cache is reused. Installing takes about half a minute
with a warm cache (several the first time: every dependency is downloaded), after the build."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.version import VERSION
from tests import served_checks as checks
from tests.front.fronts import edge_frames
from tests.precompute.tracks.tiny_levels import corridor, l_room
from tests.service.tracks_sessions import obj_text

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = "scripts/install-dist.sh"
DOCKERFILE = ROOT / "docker" / "Dockerfile"

pytestmark = pytest.mark.timeout(900)  # the first build downloads every dependency into pip's cache


def outside_env() -> dict[str, str]:
    """This environment without what would let a child import from elsewhere than its own venv."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "VIRTUAL_ENV")}


@dataclass
class Installed:
    venv: Path
    site_packages: Path
    cwd: Path  # a folder outside the checkout, where every child runs
    dist: Path  # the wheels it was installed from

    @property
    def python(self) -> Path:
        return self.venv / "bin" / "python"

    def run(self, *args, timeout: float = 120) -> subprocess.CompletedProcess:
        done = subprocess.run(
            [str(a) for a in args], cwd=self.cwd, env=outside_env(), capture_output=True, text=True, timeout=timeout
        )
        assert done.returncode == 0, f"{args} exited {done.returncode}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        return done

    def python_json(self, code: str):
        """Runs `code` in the venv's interpreter; what it printed last, as JSON."""
        return json.loads(self.run(self.python, "-c", code).stdout.splitlines()[-1])


@pytest.fixture(scope="module")
def installed(tmp_path_factory, release_dist) -> Installed:
    root = tmp_path_factory.mktemp("installed")
    assert not root.resolve().is_relative_to(ROOT), "the venv must live outside the checkout"
    venv, cwd = root / "venv", root / "cwd"
    cwd.mkdir()
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120, cwd=cwd)
    # Nothing is built here: release_dist built the wheels with the `build` of the interpreter running
    # the tests (the dev extra), so the venv under test gets only what pip installs.
    done = subprocess.run(
        ["bash", str(ROOT / SCRIPT), "--prebuilt", str(venv / "bin" / "python"), str(release_dist)],
        cwd=cwd,
        env=outside_env(),
        capture_output=True,
        text=True,
        timeout=840,
    )
    assert done.returncode == 0, f"{SCRIPT} failed:\n{done.stdout[-5000:]}\n{done.stderr[-5000:]}"
    site_packages = subprocess.run(
        [str(venv / "bin" / "python"), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        cwd=cwd,
        env=outside_env(),
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    return Installed(venv, Path(site_packages), cwd, release_dist)


# -- the installed distributions --------------------------------------------------------------


def test_the_dockerfile_installs_with_the_same_script_and_copies_what_exists():
    text = DOCKERFILE.read_text()
    assert SCRIPT in text, f"docker/Dockerfile must install with {SCRIPT}, as this test does"
    for line in re.findall(r"^COPY\s+(.+)$", text, re.MULTILINE):
        words = [w for w in line.split() if not w.startswith("--")]
        if "--from=" in line:
            continue
        for source in words[:-1]:
            assert (ROOT / source).exists(), f"docker/Dockerfile copies {source}, which the checkout has not"


def test_camdirector_is_imported_from_the_venv_not_the_checkout(installed):
    found = installed.python_json("""
import importlib.metadata as md, json
import camdirector, camdirector.__main__, camdirector.pipeline, camdirector.v1.director_pb2, camdirector_client
files = [m.__file__ for m in (camdirector.__main__, camdirector.pipeline, camdirector.v1.director_pb2, camdirector_client)]
print(json.dumps({"files": files, "path": list(camdirector.__path__),
                  "direct_url": {n: json.loads(md.distribution(n).read_text("direct_url.json") or "{}")
                                 for n in ("camdirector", "camdirector-proto", "camdirector-client")}}))
""")
    for where in found["files"] + found["path"]:
        assert Path(where).is_relative_to(installed.site_packages), f"{where} is not in the venv's site-packages"
        assert not Path(where).resolve().is_relative_to(ROOT), where
    for name, direct_url in found["direct_url"].items():
        (wheel,) = installed.dist.glob(f"{name.replace('-', '_')}-{VERSION}-*.whl")  # built from its sdist
        assert "archive_info" in direct_url and direct_url["url"] == wheel.as_uri(), f"{name}: {direct_url}"
        assert not direct_url.get("dir_info", {}).get("editable"), f"{name} is an editable install"
    assert (installed.venv / "bin" / "camdirector").is_file()


def test_the_compiled_module_is_imported_from_the_venv(installed):
    """camdirector._native, compiled into the wheel (abi3), loads from the venv's site-packages:
    not the module an editable install built into the checkout's src/."""
    found = installed.python_json("""
import json
import camdirector._native as native
print(json.dumps({"file": native.__file__, "version": native.__version__}))
""")
    assert Path(found["file"]) == installed.site_packages / "camdirector" / "_native.abi3.so", found
    assert found["version"] == VERSION


def test_every_module_imports_with_the_declared_dependencies_only(installed):
    """Every module under camdirector in the venv, imported: a module the wheel lacks, or a
    dependency the code imports that pyproject.toml does not declare, fails here."""
    found = installed.python_json("""
import importlib, json, pkgutil
import camdirector
names, failed = [], {}
def walk_error(name):
    failed[name] = "cannot be walked"
for m in pkgutil.walk_packages(camdirector.__path__, "camdirector.", onerror=walk_error):
    names.append(m.name)
    try:
        importlib.import_module(m.name)
    except BaseException as exc:
        failed[m.name] = repr(exc)
print(json.dumps({"names": names, "failed": failed}))
""")
    assert found["failed"] == {}
    checkout = {
        ".".join(p.relative_to(ROOT / "src").with_suffix("").parts).removesuffix(".__init__")
        for p in (ROOT / "src" / "camdirector").rglob("*.py")
    }
    missing = sorted(checkout - set(found["names"]) - {"camdirector"})
    assert missing == [], f"modules of the checkout that the installed package lacks: {missing}"
    assert "camdirector.v1.director_pb2_grpc" in found["names"]  # camdirector-proto shares the namespace


def test_the_shipped_scenarios_are_package_data(installed):
    found = installed.python_json("""
import json
from camdirector.evaluation.scenario_file import load_scenario, shipped_scenarios
from camdirector.evaluation.toric.suite import suite_scenarios
print(json.dumps({"shipped": sorted(shipped_scenarios()), "paper": [load_scenario(p).name for p in suite_scenarios("paper")]}))
""")
    assert len(found["shipped"]) > 0 and found["paper"], found
    assert set(found["paper"]) <= set(found["shipped"])
    checkout = sorted(p.stem for p in (ROOT / "src" / "camdirector" / "evaluation" / "scenarios").glob("*.json"))
    assert found["shipped"] == checkout
    installed.run(installed.venv / "bin" / "camdirector", "eval", "--help")


# -- the installed server ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def server(installed, tmp_path_factory):
    """The installed server, on a data directory where the installed CLI added the corridor level."""
    data_dir = tmp_path_factory.mktemp("installed-server") / "data"
    level_file = data_dir.parent / "corridor.obj"
    level_file.write_text(obj_text(corridor()))
    added = installed.run(installed.venv / "bin" / "camdirector", "level", "add", "corridor", level_file, "--data-dir", data_dir)
    assert json.loads(added.stdout)["counts"]["nodes"] > 0
    # through the console script, in a folder outside the checkout, with nothing pointing back into it
    srv = ServerProcess(
        "--workers",
        "1",
        "--data-dir",
        str(data_dir),
        command=[str(installed.venv / "bin" / "camdirector"), "serve"],
        base_env=outside_env(),
        cwd=installed.cwd,
    )
    srv.client = httpx.Client(base_url=f"http://{srv.http}", timeout=30.0)
    yield srv
    srv.client.close()
    log = srv.log_tail()
    assert srv.stop() == 0, f"the installed server did not exit cleanly:\n{log}"


def served(srv: ServerProcess) -> checks.Served:
    return checks.Served(srv.grpc, srv.zmq, srv.client, srv.log_tail)


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
@pytest.mark.parametrize("rig", ["toric", "match", "tracks"])
def test_a_session_of_each_rig_over_each_transport(server, rig, transport):
    checks.session_of_rig(served(server), rig, transport)


def test_a_level_added_over_rest_is_listed(server):
    checks.add_level_over_rest(served(server), "room", l_room())
    assert [level["name"] for level in server.client.get("/v1/levels").json()["levels"]] == ["corridor", "room"]
    checks.tracks_session_on(served(server), "room")


@pytest.mark.shared_data
def test_an_overview_job_completes(server, run_bvh):
    checks.assert_overview_done(served(server), checks.post_overview_job(served(server), run_bvh))


def test_the_dashboard_and_its_assets_are_served(server):
    page = server.client.get("/", follow_redirects=True)
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html"), page.text[:500]
    assets = re.findall(r'(?:src|href)="([^":#]+\.(?:js|css))"', page.text)
    assert {"dashboard.js", "dashboard.css"} <= set(assets), assets
    for asset in assets:
        reply = server.client.get(str(page.url.join(asset)))
        assert reply.status_code == 200 and len(reply.content) > 100, (asset, reply.status_code)


def test_a_monitor_picture_of_a_live_session(server):
    checks.monitor_picture(served(server))


def test_the_front_holding_its_sessions_answers_their_frames_on_the_edges_thread(installed):
    """`--workers 0` in the installed package: the compiled module calls back into the installed
    Python's session table from the edge's own thread (WorkerPool.answer_inline)."""
    srv = ServerProcess(
        "--workers",
        "0",
        "--data-dir",
        str(installed.cwd / "inline-data"),
        command=[str(installed.venv / "bin" / "camdirector"), "serve"],
        base_env=outside_env(),
        cwd=installed.cwd,
    )
    srv.client = httpx.Client(base_url=f"http://{srv.http}", timeout=30.0)
    try:
        for transport in ("grpc", "zmq"):
            checks.session_of_rig(served(srv), "toric", transport)
        # each session's first frame goes through the front's loop, which routes it to the edge
        assert edge_frames(srv) == 2 * (checks.FRAMES - 1)
    finally:
        srv.client.close()
        log = srv.log_tail()
        assert srv.stop() == 0, f"the installed server did not exit cleanly:\n{log}"
