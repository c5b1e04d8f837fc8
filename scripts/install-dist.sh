#!/usr/bin/env bash
# scripts/install-dist.sh [--prebuilt] PYTHON DIST_DIR: builds what users install from this checkout
# and installs it (not editable) into PYTHON's environment with its pip. DIST_DIR (made if missing;
# must be empty) gets wheels of proto/ (camdirector-proto) and client_sdk/python/ (camdirector-client),
# and the main project's sdist plus its wheel built FROM that sdist (so a file the sdist leaves out
# fails here; that wheel compiles camdirector._native from native/, so cargo must be on PATH).
# docker/Dockerfile runs it (tests/deploy/test_image.py builds that image).
#
# --prebuilt: nothing is built; DIST_DIR already holds the three wheels (scripts/dist.sh's output,
# where every wheel is built from its sdist; other files there are ignored) and only the install step
# runs, the same one. tests/test_installed_package.py installs this way the wheels that the suite's
# one `make dist` build made (tests/conftest.py's release_dist, which tests/test_dist.py checks).
#
# `python -m build` runs under BUILD_PYTHON (default: PYTHON), which must have the `build` package:
# the dev venv has it (the dev extra) and the image's build stage pip-installs it, so each passes its
# own interpreter and the environment being installed into gets nothing it would not get from pip.
# The sources are staged in a temporary folder first: the checkout's egg-info, build/ and
# __pycache__ leftovers cannot leak into the distributions, and nothing is written into the
# checkout (two runs at once, or a run beside an editable install, do not collide).
set -euo pipefail
PREBUILT=0
[ "${1:-}" = --prebuilt ] && { PREBUILT=1; shift; }
[ $# -eq 2 ] || { echo "usage: $0 [--prebuilt] PYTHON DIST_DIR" >&2; exit 2; }
PYTHON=$1
BUILD_PYTHON=${BUILD_PYTHON:-$PYTHON}
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

if [ "$PREBUILT" = 0 ]; then
  mkdir -p "$2"
  DIST=$(cd "$2" && pwd)
  [ -z "$(ls -A "$DIST")" ] || { echo "$0: $DIST is not empty" >&2; exit 2; }
  "$BUILD_PYTHON" -c "import build" 2>/dev/null \
    || { echo "$0: $BUILD_PYTHON has no 'build' package (pip install 'build>=1.2', or set BUILD_PYTHON)" >&2; exit 2; }

  STAGE=$(mktemp -d)
  trap 'rm -rf "$STAGE"' EXIT
  # native/: the crate the main wheel compiles (a Rust toolchain: cargo); not its cargo output, nor
  # the module an editable install built into src/
  tar -C "$ROOT" --exclude='*.egg-info' --exclude=__pycache__ --exclude=build \
      --exclude=native/target --exclude='src/camdirector/_native*.so' \
      -cf - pyproject.toml MANIFEST.in README.md src native proto client_sdk/python | tar -C "$STAGE" -xf -

  "$BUILD_PYTHON" -m build --wheel --outdir "$DIST" "$STAGE/proto"
  "$BUILD_PYTHON" -m build --wheel --outdir "$DIST" "$STAGE/client_sdk/python"
  "$BUILD_PYTHON" -m build --outdir "$DIST" "$STAGE"   # the sdist, then the wheel from the sdist
else
  [ -d "$2" ] || { echo "$0: --prebuilt: $2 is not a folder" >&2; exit 2; }
  DIST=$(cd "$2" && pwd)
fi

# The install step: exactly one wheel of each distribution (a second version beside it would make
# pip's choice, not ours).
WHEELS=()
for name in camdirector_proto camdirector_client camdirector; do
  found=("$DIST/$name"-[0-9]*.whl)
  [ ${#found[@]} -eq 1 ] && [ -f "${found[0]}" ] \
    || { echo "$0: $DIST must hold exactly one $name wheel; it holds: [$(ls -A "$DIST" | paste -sd " ")]" >&2; exit 2; }
  WHEELS+=("${found[0]}")
done
"$PYTHON" -m pip install "${WHEELS[@]}"
