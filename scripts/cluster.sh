#!/usr/bin/env bash
# The multi-node topology on this machine, on loopback ports (docs/scaling.md):
#   scripts/cluster.sh up --nodes N [--dir DIR]   starts Redis, PostgreSQL, N nodes, queue workers
#                                                  and HAProxy; prints one JSON object; returns
#   scripts/cluster.sh down [--dir DIR]           stops all of it
#   scripts/cluster.sh add-node [--dir DIR]       one more node, added to the running balancer
#   scripts/cluster.sh status [--dir DIR]
# Needs the venv (`make test` or `make run` makes it) and Debian's redis-server, haproxy and
# postgresql (scripts/system-deps.sh --cluster).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ ! -x "$root/.venv/bin/python" ]; then
  echo "cluster.sh: no virtual environment at $root/.venv (run make test or make run first)" >&2
  exit 1
fi
exec "$root/.venv/bin/python" -m camdirector.deploy.cluster "$@"
