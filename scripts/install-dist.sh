#!/usr/bin/env bash
# scripts/install-dist.sh PYTHON DIST_DIR: builds what users install from this checkout and installs
# it (not editable) into PYTHON's environment with its pip. DIST_DIR (made if missing; must be empty)
# gets wheels of proto/ (camdirector-proto) and client_sdk/python/ (camdirector-client), and the main
# project's sdist plus its wheel built FROM that sdist (so a file the sdist leaves out fails here).
# docker/Dockerfile runs it, and tests/test_installed_package.py runs it and tests what it installed.
#
# `python -m build` runs under BUILD_PYTHON (default: PYTHON), which must have the `build` package:
# the dev venv has it (the dev extra) and the image's build stage pip-installs it, so each passes its
# own interpreter and the environment being installed into gets nothing it would not get from pip.
# The sources are staged in a temporary folder first: the checkout's egg-info, build/ and
# __pycache__ leftovers cannot leak into the distributions, and nothing is written into the
# checkout (two runs at once, or a run beside an editable install, do not collide).
set -euo pipefail
[ $# -eq 2 ] || { echo "usage: $0 PYTHON DIST_DIR" >&2; exit 2; }
PYTHON=$1
BUILD_PYTHON=${BUILD_PYTHON:-$PYTHON}
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
mkdir -p "$2"
DIST=$(cd "$2" && pwd)
[ -z "$(ls -A "$DIST")" ] || { echo "$0: $DIST is not empty" >&2; exit 2; }
"$BUILD_PYTHON" -c "import build" 2>/dev/null \
  || { echo "$0: $BUILD_PYTHON has no 'build' package (pip install 'build>=1.2', or set BUILD_PYTHON)" >&2; exit 2; }

STAGE=$(mktemp -d)
trap 'rm -rf "$STAGE"' EXIT
tar -C "$ROOT" --exclude='*.egg-info' --exclude=__pycache__ --exclude=build \
    -cf - pyproject.toml README.md src proto client_sdk/python | tar -C "$STAGE" -xf -

"$BUILD_PYTHON" -m build --wheel --outdir "$DIST" "$STAGE/proto"
"$BUILD_PYTHON" -m build --wheel --outdir "$DIST" "$STAGE/client_sdk/python"
"$BUILD_PYTHON" -m build --outdir "$DIST" "$STAGE"   # the sdist, then the wheel from the sdist
"$PYTHON" -m pip install "$DIST"/camdirector_proto-*.whl "$DIST"/camdirector_client-*.whl "$DIST"/camdirector-*.whl
