#!/usr/bin/env bash
# The service image with Debian's podman, no image registry needed (docs/container.md):
#   scripts/podman-image.sh base     makes the local bookworm base once (debootstrap + podman import)
#   scripts/podman-image.sh build    builds docker/Dockerfile on it as localhost/camdirector:VERSION
#   scripts/podman-image.sh build --base python:3.11-slim-bookworm   on the public base instead
#   scripts/podman-image.sh save TAG FILE   the image as a docker archive (scripts/dist.sh does this)
# Needs the venv (`make test` or `make run` makes it), root, and podman, runc and debootstrap
# (scripts/system-deps.sh --tests). The code is src/camdirector/deploy/image.py, which the tests use.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ ! -x "$root/.venv/bin/python" ]; then
  echo "podman-image.sh: no virtual environment at $root/.venv (run make test or make run first)" >&2
  exit 1
fi
cmd=${1:-}
shift || true
if [ "$cmd" = "build" ]; then
  exec "$root/.venv/bin/python" -m camdirector.deploy.image build --root "$root" "$@"
fi
exec "$root/.venv/bin/python" -m camdirector.deploy.image "$cmd" "$@"
