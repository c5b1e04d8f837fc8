"""The layout rules of docs/architecture.md, checked.

- Dependencies point one way: the processes (front, worker, render, jobs) -> pipeline ->
  precompute -> geometry, with infra/ below them all; the per-frame pipeline knows nothing of the
  wire or the web; precompute imports nothing per-frame.
- The service's Python lives under src/camdirector/ only; each process folder has the one module
  that is its main loop.
- Names say which one: no two modules share a name unless they sit in sibling folders (the same
  idea in each: `rig.py` of every rig) or are an area's `cli.py`.
- No code outside a rig's folder asks which rig it holds (`isinstance(..., ToricRig)`): it asks the
  rig contract (pipeline/camera_rig.py).
- No import cycle among the modules of src/camdirector/, and no process folder imports another
  process's but a parent its child's handle (front -> worker, front -> jobs, worker -> render);
  server_settings.py, which every process reads, imports nothing of camdirector but infra/.

The pipeline check imports every module under camdirector.pipeline in a fresh interpreter, so that
what the test suite has already imported cannot hide an import the pipeline makes (and the same for
what a job process loads); the other checks read import statements (lazy ones inside functions
included)."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "camdirector"

# What a module under camdirector.pipeline may not bring in, directly or through others.
WIRE_AND_WEB = ("google.protobuf", "grpc", "fastapi", "camdirector.v1")
# What a job process may not bring in: it runs a job body, never a transport.
WEB_AND_GRPC = ("fastapi", "starlette", "uvicorn", "grpc")
# Each process's folder and the module that is its main loop.
PROCESSES = ("front", "worker", "render", "jobs")
# The one way a process folder may import another's: the parent holds its child's handle.
PARENT_TO_CHILD = {("front", "worker"), ("front", "jobs"), ("worker", "render")}
# The top-level folders of the repository that may hold Python, and what they hold.
PYTHON_FOLDERS = {
    "src": "the service",
    "proto": "the generated wire code",
    "client_sdk": "the SDKs",
    "tests": "tests",
    "load_tests": "benchmarks",
    "scripts": "scripts",
    "docs": "docs",
}
# A name that may repeat outside sibling folders: every area's subcommands of `camdirector`.
AREA_ROLES = {"__init__.py", "cli.py"}
RIG_CLASSES = {"ToricRig": "toric", "TracksRig": "tracks", "MatchRig": "match"}

# argv: the packages whose modules to import (every module under each), "--", the forbidden names.
_IMPORT_IN_FRESH_INTERPRETER = """
import importlib, json, pkgutil, sys
split = sys.argv.index("--")
packages, forbidden = sys.argv[1:split], tuple(sys.argv[split + 1:])
names = []
for package in packages:
    module = importlib.import_module(package)
    names.append(package)
    names += [m.name for m in pkgutil.walk_packages(getattr(module, "__path__", []), package + ".")]
for name in names:
    importlib.import_module(name)
loaded = sorted(m for m in sys.modules if m in forbidden or m.startswith(tuple(f + "." for f in forbidden)))
print(json.dumps({"modules": names, "loaded": loaded}))
"""


def loaded_by(packages: tuple[str, ...], forbidden: tuple[str, ...]) -> dict:
    """Imports `packages` and every module under them in a fresh interpreter (what this test
    session has imported cannot hide anything); returns {"modules": [...], "loaded": [forbidden ones]}."""
    done = subprocess.run(
        [sys.executable, "-c", _IMPORT_IN_FRESH_INTERPRETER, *packages, "--", *forbidden],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def test_the_pipeline_imports_no_protobuf_grpc_or_fastapi():
    found = loaded_by(("camdirector.pipeline",), WIRE_AND_WEB)
    assert "camdirector.pipeline.stages" in found["modules"]  # the walk saw the package
    assert found["loaded"] == [], f"imported under camdirector.pipeline: {found['loaded']}"


def test_a_job_process_imports_no_web_framework_or_grpc():
    """What the job executor's forkserver preloads: the command's main module, the job process's
    entry, the job bodies of every kind the service offers."""
    found = loaded_by(
        ("camdirector.__main__", "camdirector.jobs", "camdirector.jobs.main", *_service_job_modules()), WEB_AND_GRPC
    )
    assert found["loaded"] == [], f"a job process would import: {found['loaded']}"


def _service_job_modules() -> tuple[str, ...]:
    from camdirector.jobs import service_kinds

    modules = service_kinds().modules
    assert modules, "the service offers no job kind"
    return modules


def test_the_check_sees_what_a_module_imports():
    """The fresh-interpreter check must report a forbidden import that does happen."""
    assert "camdirector.v1.director_pb2" in loaded_by(("camdirector.worker.codec",), WIRE_AND_WEB)["loaded"]


def imported_modules(path: Path) -> set[str]:
    """Absolute module names a file's import statements name (`from a.b import c` gives a.b and a.b.c)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _under(name: str, packages: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in packages)


def _camdirector(*folders: str) -> tuple[str, ...]:
    return tuple(f"camdirector.{f}" for f in folders)


# access/ (who may do what) sits beside the processes: the areas below them name tenants through
# infra/tenants.py, never through the roles.
@pytest.mark.parametrize(
    "folder, forbidden",
    [
        (
            "infra",
            _camdirector(*PROCESSES, "pipeline", "precompute", "geometry", "evaluation", "matches", "demo", "deploy", "access"),
        ),
        ("geometry", _camdirector(*PROCESSES, "pipeline", "precompute", "evaluation", "matches", "demo", "deploy", "access")),
        ("precompute", _camdirector(*PROCESSES, "pipeline", "evaluation", "matches", "demo", "deploy", "access")),
        ("pipeline", _camdirector(*PROCESSES, "evaluation", "matches", "demo", "deploy", "access")),
    ],
)
def test_dependencies_point_one_way(folder, forbidden):
    files = sorted((PACKAGE / folder).rglob("*.py"))
    assert files, f"no Python files under src/camdirector/{folder}/"
    bad = sorted(
        f"{path.relative_to(ROOT)}: {name}" for path in files for name in imported_modules(path) if _under(name, forbidden)
    )
    assert bad == []


def test_imported_modules_sees_lazy_and_from_imports(tmp_path):
    """The scan above must not miss an import inside a function (the CLIs import lazily)."""
    source = tmp_path / "m.py"
    source.write_text("import os\n\ndef f():\n    from camdirector.front import router\n")
    assert imported_modules(source) == {"os", "camdirector.front", "camdirector.front.router"}


def test_the_service_is_one_package_under_src():
    """No Python of the service outside src/camdirector/: a folder the wheel would not contain."""
    tracked = subprocess.run(["git", "ls-files", "*.py"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    assert tracked, "git ls-files found no Python"
    outside = sorted(f for f in tracked if f.split("/")[0] not in PYTHON_FOLDERS)
    assert outside == []
    assert not (PACKAGE / "__init__.py").exists(), "camdirector is a namespace shared with camdirector.v1 (proto/)"


@pytest.mark.parametrize("process", PROCESSES)
def test_each_process_has_its_main_loop_in_its_folder(process):
    main = PACKAGE / process / "main.py"
    assert main.is_file(), f"src/camdirector/{process}/main.py: the process's main loop"
    assert main.read_text().startswith('"""'), "the main loop says what it runs in its docstring"


def duplicate_names(paths: list[Path]) -> dict[str, list[str]]:
    """Module names that repeat outside sibling folders (and outside AREA_ROLES): name -> folders."""
    folders = defaultdict(list)
    for path in paths:
        folders[path.name].append(path.parent)
    return {
        name: sorted(str(f) for f in where)
        for name, where in folders.items()
        if len(where) > 1 and name not in AREA_ROLES and len({f.parent for f in where}) > 1
    }


def test_no_two_modules_share_a_name_unless_siblings():
    paths = [p.relative_to(PACKAGE) for p in PACKAGE.rglob("*.py")]
    assert duplicate_names(paths) == {}


def test_the_name_check_tells_siblings_from_strangers():
    paths = [
        Path("pipeline/toric/rig.py"),
        Path("pipeline/tracks/rig.py"),
        Path("a/cli.py"),
        Path("b/c/cli.py"),
        Path("worker/views.py"),
        Path("front/http/views.py"),
    ]
    assert duplicate_names(paths) == {"views.py": ["front/http", "worker"]}


def rig_sniffing(path: Path, folder_of_rig: dict[str, str]) -> list[str]:
    """isinstance(..., <a rig class>) calls in `path` that are outside that rig's own folder."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id == "isinstance"
            and len(node.args) == 2
        ):
            classes = node.args[1].elts if isinstance(node.args[1], ast.Tuple) else [node.args[1]]
            for cls in classes:
                name = cls.id if isinstance(cls, ast.Name) else cls.attr if isinstance(cls, ast.Attribute) else None
                if name in folder_of_rig and path.parent.name != folder_of_rig[name]:
                    found.append(f"{path}:{node.lineno} isinstance(..., {name})")
    return found


def test_no_code_outside_a_rig_asks_which_rig_it_holds():
    found = [hit for path in sorted(PACKAGE.rglob("*.py")) for hit in rig_sniffing(path, RIG_CLASSES)]
    assert found == []


def test_the_rig_check_sees_isinstance(tmp_path):
    (tmp_path / "toric").mkdir()
    outside, inside = tmp_path / "session.py", tmp_path / "toric" / "rig.py"
    outside.write_text("def f(rig):\n    return isinstance(rig, (int, ToricRig))\n")
    inside.write_text("def f(rig):\n    return isinstance(rig, ToricRig)\n")
    assert rig_sniffing(outside, RIG_CLASSES) == [f"{outside}:2 isinstance(..., ToricRig)"]
    assert rig_sniffing(inside, RIG_CLASSES) == []


def module_graph(root: Path, package: str) -> dict[str, set[str]]:
    """Each module of `package` (the folder root/package) -> the modules of `package` its import
    statements name: lazy ones inside functions included, relative ones resolved, and `from p
    import n` naming p.n where that is a module (else p, whose __init__ defines n)."""
    paths = {}
    for path in (root / package).rglob("*.py"):
        parts = path.relative_to(root).with_suffix("").parts
        paths[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path

    def nearest(name: str) -> str | None:
        while name and name not in paths:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for module, path in paths.items():
        here = module if path.name == "__init__.py" else module.rpartition(".")[0]
        named = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                named.update(nearest(alias.name) for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    above = here.split(".")[: len(here.split(".")) - (node.level - 1)]
                    base = ".".join(above + ([node.module] if node.module else []))
                named.update(f"{base}.{alias.name}" if f"{base}.{alias.name}" in paths else nearest(base) for alias in node.names)
        graph[module] = {name for name in named if name is not None and name != module}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The modules that import one another round a circle: each strongly connected component of
    more than one module (Tarjan's algorithm), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        for other in sorted(graph.get(module, ())):
            if other not in index:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in stack:
                low[module] = min(low[module], index[other])
        if low[module] == index[module]:
            component = []
            while not component or component[-1] != module:
                component.append(stack.pop())
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return sorted(cycles)


def process_crossings(graph: dict[str, set[str]]) -> list[str]:
    """Imports from one process folder into another's other than PARENT_TO_CHILD."""

    def process(module: str) -> str | None:
        parts = module.split(".")
        return parts[1] if len(parts) > 1 and parts[1] in PROCESSES else None

    return sorted(
        f"{module} -> {other}"
        for module, others in graph.items()
        for other in others
        if process(module)
        and process(other)
        and process(module) != process(other)
        and (process(module), process(other)) not in PARENT_TO_CHILD
    )


def test_no_import_cycle():
    graph = module_graph(ROOT / "src", "camdirector")
    assert "camdirector.infra.channels" in graph["camdirector.worker.main"]  # the scan saw the tree
    assert import_cycles(graph) == []


def test_the_server_settings_are_a_leaf():
    """Every process reads ServerSettings: it imports nothing of camdirector but infra/."""
    imports = module_graph(ROOT / "src", "camdirector")["camdirector.server_settings"]
    assert sorted(name for name in imports if not _under(name, ("camdirector.infra",))) == []


def test_no_process_imports_another_but_its_child():
    assert process_crossings(module_graph(ROOT / "src", "camdirector")) == []


def _tree(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return root


def test_the_cycle_check_sees_a_lazy_relative_circle(tmp_path):
    tree = _tree(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/a.py": "from pkg import b\n",
            "pkg/b.py": "import os\n\ndef f():\n    from . import c\n",
            "pkg/c.py": "from .sub.d import VALUE\n",
            "pkg/sub/__init__.py": "",
            "pkg/sub/d.py": "from ..a import NAME\n",
        },
    )
    graph = module_graph(tree, "pkg")
    assert graph["pkg.a"] == {"pkg.b"} and graph["pkg.b"] == {"pkg.c"} and graph["pkg.sub.d"] == {"pkg.a"}
    assert import_cycles(graph) == [["pkg.a", "pkg.b", "pkg.c", "pkg.sub.d"]]


def test_the_cycle_check_passes_a_package_that_gathers_its_modules(tmp_path):
    """`from pkg import b` names the module b, not pkg's __init__ (which imports a): no circle."""
    tree = _tree(
        tmp_path,
        {
            "pkg/__init__.py": "from pkg.a import A\nfrom pkg.b import B\n",
            "pkg/a.py": "from pkg import b\nA = 1\n",
            "pkg/b.py": "import pkg.c\nB = 2\n",
            "pkg/c.py": "import json\n",
        },
    )
    graph = module_graph(tree, "pkg")
    assert graph["pkg"] == {"pkg.a", "pkg.b"} and graph["pkg.a"] == {"pkg.b"}
    assert import_cycles(graph) == []


def test_the_process_check_allows_only_parent_to_child(tmp_path):
    tree = _tree(
        tmp_path,
        {
            "pkg/front/main.py": "from pkg.worker import main\nfrom pkg.jobs import queue\n",
            "pkg/worker/main.py": "from pkg.render import monitor\nfrom pkg.infra import channels\n",
            "pkg/render/monitor.py": "def f():\n    from pkg.worker import main\n",
            "pkg/jobs/queue.py": "",
            "pkg/infra/channels.py": "",
        },
    )
    graph = module_graph(tree, "pkg")
    assert process_crossings(graph) == ["pkg.render.monitor -> pkg.worker.main"]
    (tree / "pkg/render/monitor.py").write_text("")
    assert process_crossings(module_graph(tree, "pkg")) == []
