"""The dependency rule of docs/architecture.md, checked: server -> precompute -> geometry, and the
per-frame pipeline (camdirector.pipeline) knows nothing of the wire or the web.

The pipeline check imports every module under camdirector.pipeline in a fresh interpreter,
so that what the test suite has already imported cannot hide an import the pipeline makes (and the
same for what a job process loads); the precompute and geometry checks read import statements
(lazy ones inside functions included)."""
from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# What a module under camdirector.pipeline may not bring in, directly or through others.
WIRE_AND_WEB = ("google.protobuf", "grpc", "fastapi", "camdirector.v1")
# What a job process may not bring in: it runs a job body, never a transport.
WEB_AND_GRPC = ("fastapi", "starlette", "uvicorn", "grpc")

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
    done = subprocess.run([sys.executable, "-c", _IMPORT_IN_FRESH_INTERPRETER, *packages, "--", *forbidden],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def test_the_pipeline_imports_no_protobuf_grpc_or_fastapi():
    found = loaded_by(("camdirector.pipeline",), WIRE_AND_WEB)
    assert "camdirector.pipeline.stages" in found["modules"]  # the walk saw the package
    assert found["loaded"] == [], f"imported under camdirector.pipeline: {found['loaded']}"


def test_a_job_process_imports_no_web_framework_or_grpc():
    """What the job runner's forkserver preloads: the command's main module, the runner, the job bodies."""
    found = loaded_by(("camdirector.__main__", "camdirector.jobs", "camdirector.precompute.overview.job",
                       "camdirector.precompute.tracks.job"), WEB_AND_GRPC)
    assert found["loaded"] == [], f"a job process would import: {found['loaded']}"


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


@pytest.mark.parametrize("folder, forbidden", [
    ("precompute", ("camdirector",)),
    ("geometry", ("camdirector", "camdirector.precompute")),
])
def test_dependencies_point_one_way(folder, forbidden):
    files = sorted((ROOT / folder).rglob("*.py"))
    assert files, f"no Python files under {folder}/"
    bad = sorted(f"{path.relative_to(ROOT)}: {name}" for path in files for name in imported_modules(path)
                 if name in forbidden or name.startswith(tuple(f + "." for f in forbidden)))
    assert bad == []


def test_imported_modules_sees_lazy_and_from_imports(tmp_path):
    """The scan above must not miss an import inside a function (the CLIs import lazily)."""
    source = tmp_path / "m.py"
    source.write_text("import os\n\ndef f():\n    from camdirector.front import router\n")
    assert imported_modules(source) == {"os", "camdirector.front", "camdirector.front.router"}
