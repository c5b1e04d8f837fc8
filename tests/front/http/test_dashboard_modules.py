"""The dashboard's ES modules as files and as served (no browser): the page loads one entry module,
whose static imports reach every module of the folder, each import naming something its module
exports, with no cycle among them; the server serves each with a JavaScript content type (a
browser refuses a module served otherwise); and the wheel's package data takes every file of the
folder. The browser tests (test_dashboard.py) run them."""

from __future__ import annotations

import re
import tomllib
from fnmatch import fnmatch
from graphlib import CycleError, TopologicalSorter
from pathlib import Path

import httpx
import pytest

import camdirector.front.http

ROOT = Path(__file__).resolve().parents[3]
DASHBOARD_DIR = Path(camdirector.front.http.__file__).with_name("dashboard")  # as front/http/app.py serves it
IMPORT = re.compile(r'^import \{([^}]*)\} from "\./([^"]+)";$', re.MULTILINE)
JAVASCRIPT_TYPES = ("text/javascript", "application/javascript")


def entry_module() -> str:
    scripts = re.findall(r"<script ([^>]*)></script>", (DASHBOARD_DIR / "index.html").read_text())
    assert scripts == ['type="module" src="dashboard.js"'], scripts
    return "dashboard.js"


def imports(module: str) -> dict[str, list[str]]:
    """module -> the names the given module imports from it."""
    found = IMPORT.findall((DASHBOARD_DIR / module).read_text())
    return {target: [name.strip() for name in names.split(",")] for names, target in found}


def reached() -> dict[str, dict[str, list[str]]]:
    """Every module the entry reaches by static imports -> its imports."""
    graph: dict[str, dict[str, list[str]]] = {}
    todo = [entry_module()]
    while todo:
        module = todo.pop()
        if module not in graph:
            graph[module] = imports(module)
            todo.extend(graph[module])
    return graph


def test_the_entry_reaches_every_module_and_each_import_is_exported():
    graph = reached()
    assert set(graph) == {p.name for p in DASHBOARD_DIR.glob("*.js")}  # none left unreached
    for module, targets in graph.items():
        for target, names in targets.items():
            text = (DASHBOARD_DIR / target).read_text()
            for name in names:
                assert re.search(rf"^export (?:async )?(?:function|const|class) {name}\b", text, re.MULTILINE), (
                    f"{module} imports {name} from {target}, which does not export it"
                )


def test_the_modules_import_each_other_without_a_cycle():
    graph = reached()
    try:
        tuple(TopologicalSorter({module: set(targets) for module, targets in graph.items()}).static_order())
    except CycleError as error:
        pytest.fail(f"an import cycle among the dashboard's modules: {error.args[1]}")


def test_the_wheel_takes_every_file_of_the_dashboard():
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    patterns = package_data["camdirector.front.http"]
    for path in DASHBOARD_DIR.iterdir():
        assert any(fnmatch(f"dashboard/{path.name}", pattern) for pattern in patterns), path.name


def test_every_module_is_served_as_javascript(server):
    with httpx.Client(base_url=f"http://{server.http}", timeout=30.0) as http:
        for module in reached():
            reply = http.get(f"/dashboard/{module}")
            assert reply.status_code == 200, (module, reply.status_code)
            assert reply.headers["content-type"].split(";")[0] in JAVASCRIPT_TYPES, (module, reply.headers["content-type"])
