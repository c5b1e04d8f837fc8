#!/usr/bin/env bash
# scripts/dist.sh OUT_DIR (make dist): the release artifacts of this checkout, each named with the
# project's one version (CHANGELOG.md):
#   camdirector-V.tar.gz, camdirector-V-cp311-abi3-linux_ARCH.whl        the server, camdirector._native
#                                                                        compiled (native/: cargo on PATH)
#   camdirector_proto-V.tar.gz, camdirector_proto-V-py3-none-any.whl     the wire code
#   camdirector_client-V.tar.gz, camdirector_client-V-py3-none-any.whl   the Python SDK
#   camdirector-cpp-sdk-V-linux-ARCH.tar.gz                              the C/C++ SDK's install tree
#   camdirector-image-V-linux-ARCH.tar                                   the service image (docker load -i)
#   SHA256SUMS
# Each wheel is built from its sdist (python -m build), so a file an sdist leaves out fails here.
# Sources are staged in a temporary folder first, as scripts/install-dist.sh does, so nothing of the
# checkout's editable install leaks in. PYTHON (default .venv/bin/python) must have `build`.
set -euo pipefail
[ $# -eq 1 ] || { echo "usage: $0 OUT_DIR" >&2; exit 2; }
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PYTHON=${PYTHON:-$ROOT/.venv/bin/python}
mkdir -p "$1"
OUT=$(cd "$1" && pwd)
[ -z "$(ls -A "$OUT")" ] || { echo "$0: $OUT is not empty" >&2; exit 2; }
VERSION=$("$PYTHON" -c "import tomllib; print(tomllib.load(open('$ROOT/pyproject.toml', 'rb'))['project']['version'])")

STAGE=$(mktemp -d)
trap 'rm -rf "$STAGE"' EXIT
tar -C "$ROOT" --exclude='*.egg-info' --exclude=__pycache__ --exclude=build \
    --exclude=native/target --exclude='src/camdirector/_native*.so' \
    -cf - pyproject.toml MANIFEST.in README.md CHANGELOG.md src native proto client_sdk | tar -C "$STAGE" -xf -
for project in "$STAGE/proto" "$STAGE/client_sdk/python" "$STAGE"; do
  "$PYTHON" -m build --outdir "$OUT" "$project"
done

# The C/C++ SDK: configured, built and installed into a prefix that becomes the archive's root.
cmake -S "$STAGE/client_sdk/cpp" -B "$STAGE/cpp-build" -DCAMDIRECTOR_PROTO_DIR="$STAGE/proto" \
      -DCAMDIRECTOR_BUILD_TOOLS=OFF -DCAMDIRECTOR_BUILD_SHARED=ON -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$STAGE/cpp-build" -j "$(nproc)" >/dev/null
SDK="camdirector-cpp-sdk-$VERSION-linux-$(uname -m)"
cmake --install "$STAGE/cpp-build" --prefix "$STAGE/$SDK" >/dev/null
tar -C "$STAGE" -czf "$OUT/$SDK.tar.gz" "$SDK"

# The service image (docker/Dockerfile) built with podman as root (deploy/image.py: on the local
# debootstrap bookworm, or on IMAGE_BASE, e.g. python:3.11-slim-bookworm where a registry is
# reachable) and saved as a docker archive. NO_IMAGE=1 leaves it out (a machine without podman).
if [ "${NO_IMAGE:-}" != 1 ]; then
  TAG=$("$PYTHON" -m camdirector.deploy.image build --root "$ROOT" ${IMAGE_BASE:+--base "$IMAGE_BASE"} \
        | "$PYTHON" -c "import json, sys; print(json.load(sys.stdin)['image'])")
  "$PYTHON" -m camdirector.deploy.image save "$TAG" "$OUT/camdirector-image-$VERSION-linux-$(uname -m).tar" >/dev/null
fi

(cd "$OUT" && sha256sum -- * > SHA256SUMS)
ls -1 "$OUT"
