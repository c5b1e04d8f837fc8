#!/usr/bin/env bash
# System libraries the project needs beyond PyPI: Mesa's EGL (offscreen OpenGL, llvmpipe on
# machines without a GPU). Installs them with apt-get when missing and we are root. A Rust
# toolchain (cargo) must be there already: without it this fails at once, naming rustup.
# `system-deps.sh --tests` (make test) also wants what the tests drive: Debian's Chromium for the
# dashboard's browser tests, and the C/C++ SDK's toolchain (client_sdk/cpp: CMake, g++, gRPC and
# protobuf for C++; `--cpp` asks for that one alone); without root those are only reported
# (their tests then skip, CI fails). `--cluster` (also part of `--tests`) wants the engines a
# cluster runs on (scripts/cluster.sh): redis-server, haproxy and postgresql. `--tests` also wants
# what builds and runs the service image (tests/deploy/test_image.py, deploy/image.py): podman,
# runc and debootstrap, and podman-compose for the cluster in containers (deploy/compose.py), and
# Node with npm for the TypeScript SDK.
set -euo pipefail
# camdirector._native (native/) compiles on every install from source (make's editable install,
# scripts/install-dist.sh): cargo must be on PATH, at least pyo3 0.30's rust-version (1.85; the
# locked crates ask no more). Debian's Rust is too old (bookworm has 1.63), so it is not installed
# here: the user installs it with rustup. `--cpp` and `--cluster` alone build nothing of it.
RUST_MIN=1.85
if [ $# -eq 0 ] || [ "$1" = "--tests" ]; then
  if ! command -v cargo >/dev/null; then
    echo "cargo is missing: camdirector's compiled module (native/) needs a Rust toolchain, $RUST_MIN or later;" \
         "install it with rustup (https://rustup.rs) and put ~/.cargo/bin on PATH" >&2
    exit 1
  fi
  cargo_version=$(cargo --version | cut -d' ' -f2)
  if [ "$(printf '%s\n' "$RUST_MIN" "$cargo_version" | sort -V | head -1)" != "$RUST_MIN" ]; then
    echo "cargo $cargo_version is older than $RUST_MIN, which camdirector's compiled module (native/) needs;" \
         "update it with rustup (rustup update stable; https://rustup.rs)" >&2
    exit 1
  fi
fi
need=()
ldconfig -p | grep -q 'libEGL.so.1' || need+=(libegl1)
ldconfig -p | grep -q 'libEGL_mesa.so.0' || need+=(libegl-mesa0 libgl1-mesa-dri libgbm1)
ldconfig -p | grep -q 'libGL.so.1' || need+=(libgl1)
optional=()
if [ "${1:-}" = "--tests" ] && ! command -v chromium >/dev/null; then
  optional+=(chromium)
fi
if [ "${1:-}" = "--tests" ] || [ "${1:-}" = "--cpp" ]; then
  command -v cmake >/dev/null || optional+=(cmake)
  command -v g++ >/dev/null || optional+=(g++)
  command -v pkg-config >/dev/null || optional+=(pkg-config)
  command -v protoc >/dev/null || optional+=(protobuf-compiler)
  command -v grpc_cpp_plugin >/dev/null || optional+=(protobuf-compiler-grpc)
  { command -v pkg-config >/dev/null && pkg-config --exists protobuf; } || optional+=(libprotobuf-dev)
  { command -v pkg-config >/dev/null && pkg-config --exists grpc++; } || optional+=(libgrpc++-dev)
fi
if [ "${1:-}" = "--tests" ] || [ "${1:-}" = "--cluster" ]; then
  command -v redis-server >/dev/null || optional+=(redis-server)
  command -v haproxy >/dev/null || [ -x /usr/sbin/haproxy ] || optional+=(haproxy)
  [ -x /usr/lib/postgresql/15/bin/initdb ] || optional+=(postgresql)
fi
if [ "${1:-}" = "--tests" ]; then
  # The TypeScript SDK's tests want Node 20+: these machines carry it (NodeSource's nodejs); where
  # none is installed, Debian's nodejs and npm are tried (bookworm's is 18: its test says so and fails).
  command -v node >/dev/null || optional+=(nodejs npm)
  command -v podman >/dev/null || optional+=(podman)
  [ -x /usr/sbin/runc ] || optional+=(runc)
  command -v debootstrap >/dev/null || [ -x /usr/sbin/debootstrap ] || optional+=(debootstrap)
  command -v podman-compose >/dev/null || optional+=(podman-compose)
fi
if [ ${#optional[@]} -gt 0 ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "missing for some tests: ${optional[*]} (the dashboard's browser tests, the C++ SDK's or the image's tests will skip; install them as root)" >&2
  else
    need+=("${optional[@]}")
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
