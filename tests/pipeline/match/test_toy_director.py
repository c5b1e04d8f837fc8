"""A director registered by a test alone (toy_director.py) runs as the built-ins do: in a session
in process, over gRPC on a real server that imports it as a plugin (`--plugin`, its spawned worker
too), listed by `GET /v1/match-directors`, and measured by `eval-match --plugin`. Adding a
director is one module and one registry entry: nothing of the service names "toy"."""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import subprocess
import sys
from types import ModuleType
from unittest import mock

import grpc
import httpx
import numpy as np
import pytest

import camdirector_client as cd
from camdirector.deploy.server_process import ServerProcess
from camdirector.pipeline.match import director_registry
from camdirector.pipeline.match.director_registry import DirectorEntry, director_entry, register, registered
from camdirector.pipeline.style import Rig, Style
from camdirector.server_settings import ServerSettings
from tests.evaluation.match.test_evaluate import eval_match, registry, registry_and_match  # noqa: F401 (fixtures)
from tests.pipeline.match.scenes import melee, run_session
from tests.service.test_match_sessions import frames, match_request
from tests.service.tracks_sessions import ROOT

PLUGIN = "tests.pipeline.match.toy_director"
WITH_PLUGIN = {"PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)}


@pytest.fixture
def toy_director():
    """The toy imported (so registered) in this process for the test that asks for it alone: the registry
    and the module cache are as before afterwards, so later tests (a benchmark that runs every
    registered director against a server without the plugin) never see it."""
    with mock.patch.dict(director_registry._ENTRIES):
        module: ModuleType = importlib.import_module(PLUGIN)
        yield module
        sys.modules.pop(PLUGIN)


def test_the_toy_is_registered_after_the_built_ins_and_a_name_is_never_taken_over(toy_director):
    names = [e.name for e in registered()]
    assert names[:3] == ["planned", "hltv", "autotrack"] and "toy" in names
    assert director_entry("toy").wire is None
    with pytest.raises(ValueError, match="already registered"):
        register(DirectorEntry("toy", "another", toy_director.ToyDirector))
    with pytest.raises(ValueError, match="lower case"):
        register(DirectorEntry("Toy", "another", toy_director.ToyDirector))
    with pytest.raises(KeyError, match="the registered ones are planned, hltv, autotrack"):
        director_entry("nobody")


def test_the_toy_directs_a_session_in_process(toy_director):
    match = dataclasses.replace(melee(seed=2, duration_s=6.0, delay_s=1.0), style=Style(rig=Rig.MATCH, match_director="toy"))
    first = match.scene().targets[0].id
    _, states = run_session(match, 6.0)
    shown = [s for s in states if s.pose is not None]
    assert shown and all(s.match.shot.subject_ids == (first,) for s in shown)
    assert sum(s.cut for s in shown) == 1 and shown[0].match.shot.reason.startswith("toy: ")
    assert all(s.match.planned_cut is None for s in shown)  # no planned cuts: DirectorBase's answer
    behind = [np.linalg.norm(s.pose.position_world - s.aim_points_world[0]) for s in shown]
    assert np.allclose(behind, np.linalg.norm(toy_director.OFFSET_M))


@pytest.fixture(scope="module")
def plugin_server():
    with ServerProcess("--workers", "1", "--plugin", PLUGIN, transports=("grpc", "http"), env=WITH_PLUGIN) as server:
        yield server


def test_the_toy_directs_a_session_over_grpc_on_a_server_that_imports_it(plugin_server):
    with cd.connect(plugin_server.url("grpc")) as client:
        with client.create_session(match_request(delay_s=0.5, match_director_name="toy")) as session:
            replies = list(session.stream(frames(session.id, 60)))
            detail = httpx.get(f"http://{plugin_server.http}/v1/sessions/{session.id}").json()
    shown = [r for r in replies if r.HasField("pose")]
    assert shown and {tuple(r.shot.subject_ids) for r in shown} == {("a0",)}
    assert all(r.shot.kind == cd.pb.SHOT_FOLLOW and r.shot.reason == "toy: always a0" for r in shown)
    assert detail["style"]["matchDirectorName"] == "toy"


def test_the_server_lists_the_toy_after_the_built_ins_and_refuses_an_unknown_name(plugin_server):
    listed = httpx.get(f"http://{plugin_server.http}/v1/match-directors").json()["directors"]
    assert [(d["name"], d["wire"]) for d in listed] == [
        ("planned", "MATCH_DIRECTOR_PLANNED"),
        ("hltv", "MATCH_DIRECTOR_HLTV"),
        ("autotrack", "MATCH_DIRECTOR_AUTOTRACK"),
        ("toy", None),
    ]
    assert all(d["label"] for d in listed)
    with cd.connect(plugin_server.url("grpc")) as client, pytest.raises(cd.DirectorError) as refused:
        client.create_session(match_request(delay_s=0.5, match_director_name="nobody"))
    assert refused.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert "the registered ones are planned, hltv, autotrack, toy" in refused.value.message


def test_a_server_without_the_plugin_refuses_the_toy():
    with ServerProcess("--workers", "0", transports=("grpc",)) as server, cd.connect(server.url("grpc")) as client:
        with pytest.raises(cd.DirectorError) as refused:
            client.create_session(match_request(delay_s=0.5, match_director_name="toy"))
    assert refused.value.code == grpc.StatusCode.INVALID_ARGUMENT and "'toy'" in refused.value.message


def test_eval_match_measures_the_toy_beside_ours(registry_and_match, monkeypatch):  # noqa: F811 (a fixture)
    folder, _ = registry_and_match
    monkeypatch.setenv("PYTHONPATH", WITH_PLUGIN["PYTHONPATH"])
    done = eval_match(
        folder,
        "--delay",
        "2",
        "--minutes",
        "0.1",
        "--plugin",
        PLUGIN,
        "--director",
        "toy",
        "--director",
        "planned",
        "--json",
        str(folder / "toy.json"),
    )
    assert done.returncode == 0, done.stderr
    result = json.loads((folder / "toy.json").read_text())
    assert list(result["directors"]) == ["toy", "planned"] and "coverage_gain_over_hltv" not in result
    assert result["directors"]["toy"]["program_moments"] > 0
    unknown = eval_match(folder, "--delay", "2", "--director", "toy", "--json", str(folder / "x.json"))
    assert unknown.returncode == 2 and "'toy' is not a registered match director" in unknown.stderr


def test_the_toy_is_registered_for_its_tests_alone():
    assert "toy" not in [e.name for e in registered()] and PLUGIN not in sys.modules


def test_plugins_come_from_the_environment_and_one_that_cannot_be_imported_stops_serve(tmp_path):
    assert ServerSettings.from_env({"CAMDIRECTOR_PLUGINS": "studio.director, other"}).plugins == ("studio.director", "other")
    with pytest.raises(ValueError, match="plugins must be Python module names"):
        ServerSettings(plugins=("not a module",))
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "camdirector",
            "serve",
            "--plugin",
            "no_such_plugin_module",
            "--workers",
            "0",
            "--grpc",
            "127.0.0.1:0",
            "--zmq",
            "",
            "--http",
            "",
            "--data-dir",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert out.returncode == 2 and "plugin 'no_such_plugin_module' could not be imported" in out.stderr
