#!/usr/bin/env bash
# System libraries the project needs beyond PyPI: Mesa's EGL (offscreen OpenGL, llvmpipe on
# machines without a GPU). Installs them with apt-get when missing and we are root.
# `system-deps.sh --browser` (make test) also wants Debian's Chromium, which the dashboard's
# browser tests drive; without root that one is only reported (those tests then skip, CI fails).
set -euo pipefail
need=()
ldconfig -p | grep -q 'libEGL.so.1' || need+=(libegl1)
ldconfig -p | grep -q 'libEGL_mesa.so.0' || need+=(libegl-mesa0 libgl1-mesa-dri libgbm1)
ldconfig -p | grep -q 'libGL.so.1' || need+=(libgl1)
if [ "${1:-}" = "--browser" ] && ! command -v chromium >/dev/null; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "no chromium: the dashboard's browser tests will skip (install Debian's chromium as root)" >&2
  else
    need+=(chromium)
  fi
fi
if [ ${#need[@]} -eq 0 ]; then exit 0; fi
if [ "$(id -u)" -ne 0 ]; then
  echo "missing system packages: ${need[*]} (install them with apt-get as root)" >&2
  exit 1
fi
echo "installing system packages: ${need[*]}"
apt-get update -q
DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${need[@]}"
