"""`make dist` (scripts/dist.sh): every release artifact named with the one version, checksummed,
and holding what its users take from it: the wheels' metadata, the sdists' sources, the C/C++
SDK's install tree with its CMake package and pkg-config file, a C library that says its
version, and the service image as a docker archive (where podman runs). The artifacts are
tests/conftest.py's release_dist, built once per run: the wheels that
tests/test_installed_package.py installs are these."""

from __future__ import annotations

import hashlib
import json
import os
import platform
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

from camdirector.version import VERSION
from tests.conftest import why_no_image

IMAGE = f"camdirector-image-{VERSION}-linux-{platform.machine()}.tar"
ROOT = Path(__file__).resolve().parents[1]


def image_or_skip() -> None:
    """The image archive is made only where podman runs (tests/conftest.py's release_dist)."""
    why = why_no_image()
    if why is not None:
        if os.environ.get("CAMDIRECTOR_REQUIRE_PODMAN") == "1":
            pytest.fail(f"{why} (CAMDIRECTOR_REQUIRE_PODMAN=1)")
        pytest.skip(f"make dist left the image out: {why}")


# The server's wheel carries camdirector._native compiled for the stable ABI (CPython 3.11 and
# later) on this platform; the other two are pure Python.
SERVER_WHEEL = f"camdirector-{VERSION}-cp311-abi3-linux_{platform.machine()}.whl"
PURE_WHEELS = {name: f"{name}-{VERSION}-py3-none-any.whl" for name in ("camdirector_proto", "camdirector_client")}


def test_every_artifact_is_named_with_the_version_and_checksummed(release_dist):
    sdk = f"camdirector-cpp-sdk-{VERSION}-linux-{platform.machine()}.tar.gz"
    sdists = {f"{name}-{VERSION}.tar.gz" for name in ("camdirector", "camdirector_proto", "camdirector_client")}
    expected = sdists | set(PURE_WHEELS.values()) | {SERVER_WHEEL, sdk, "SHA256SUMS"}
    if why_no_image() is None:
        expected.add(IMAGE)
    assert {p.name for p in release_dist.iterdir()} == expected
    sums = dict(reversed(line.split("  ", 1)) for line in (release_dist / "SHA256SUMS").read_text().splitlines())
    assert set(sums) == expected - {"SHA256SUMS"}
    for name, digest in sums.items():
        sha = hashlib.sha256()
        with open(release_dist / name, "rb") as artifact:  # the image is a gigabyte: read in pieces
            while chunk := artifact.read(1 << 22):
                sha.update(chunk)
        assert sha.hexdigest() == digest, name


def test_the_wheels_and_sdists_hold_their_sources_at_the_version(release_dist):
    for name, wheel_name in {"camdirector": SERVER_WHEEL, **PURE_WHEELS}.items():
        with zipfile.ZipFile(release_dist / wheel_name) as wheel:
            metadata = wheel.read(f"{name}-{VERSION}.dist-info/METADATA").decode()
        assert f"\nVersion: {VERSION}\n" in metadata
    with tarfile.open(release_dist / f"camdirector-{VERSION}.tar.gz") as sdist:
        names = sdist.getnames()
    assert f"camdirector-{VERSION}/src/camdirector/access/guard.py" in names
    assert not [n for n in names if "__pycache__" in n]  # staged sources, not the checkout's leftovers


def test_the_server_sdist_holds_the_crate_and_its_wheel_the_compiled_module(release_dist):
    """The wheel is built from the sdist, so the crate's sources must be in it (MANIFEST.in), and
    never cargo's output nor a module compiled in the checkout."""
    top = f"camdirector-{VERSION}/"
    with tarfile.open(release_dist / f"camdirector-{VERSION}.tar.gz") as sdist:
        names = sdist.getnames()
        crate = {m.name.removeprefix(top) for m in sdist.getmembers() if m.name.startswith(top + "native/") and m.isfile()}
    checkout = {p.relative_to(ROOT).as_posix() for p in (ROOT / "native").rglob("*") if p.is_file() and "target" not in p.parts}
    assert crate == checkout and {"native/Cargo.toml", "native/Cargo.lock", "native/src/lib.rs"} <= crate
    assert not [n for n in names if n.endswith(".so")]
    with zipfile.ZipFile(release_dist / SERVER_WHEEL) as wheel:
        modules = [n for n in wheel.namelist() if n.startswith("camdirector/_native")]
        wheel_file = wheel.read(f"camdirector-{VERSION}.dist-info/WHEEL").decode()
    tags = [line for line in wheel_file.splitlines() if line.startswith("Tag:")]
    assert modules == ["camdirector/_native.abi3.so"]
    assert tags == [f"Tag: cp311-abi3-linux_{platform.machine()}"]


def test_the_cpp_sdk_archive_is_an_install_tree_whose_library_says_its_version(release_dist, tmp_path):
    sdk = f"camdirector-cpp-sdk-{VERSION}-linux-{platform.machine()}"
    with tarfile.open(release_dist / f"{sdk}.tar.gz") as archive:
        archive.extractall(tmp_path, filter="data")
    prefix = tmp_path / sdk
    for part in (
        "include/camdirector/camdirector.h",
        "include/camdirector/camdirector.hpp",
        "lib/libcamdirector.a",
        "lib/cmake/camdirector/camdirectorConfig.cmake",
        "lib/pkgconfig/camdirector.pc",
    ):
        assert (prefix / part).is_file(), part
    assert f"Version: {VERSION}" in (prefix / "lib/pkgconfig/camdirector.pc").read_text()
    # Loaded in a fresh interpreter: the library carries the system's gRPC and protobuf, which must
    # not meet the copies this test process has loaded (that aborts the process).
    said = subprocess.run(
        [
            sys.executable,
            "-c",
            "import ctypes, sys; lib = ctypes.CDLL(sys.argv[1]); "
            "lib.cd_version.restype = ctypes.c_char_p; print(lib.cd_version().decode())",
            str(prefix / "lib/libcamdirector_c.so"),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert said.stdout.strip() == VERSION


def test_the_image_archive_holds_the_labelled_unprivileged_image(release_dist):
    """What `docker load -i` reads: one image tagged with the version, its config labelled with it
    and running as the service's user, every layer it lists present."""
    image_or_skip()
    with tarfile.open(release_dist / IMAGE) as archive:
        (manifest,) = json.load(archive.extractfile("manifest.json"))
        assert manifest["RepoTags"] == [f"localhost/camdirector:{VERSION}"]
        config = json.load(archive.extractfile(manifest["Config"]))
        names = set(archive.getnames())
    assert config["config"]["Labels"]["org.opencontainers.image.version"] == VERSION
    assert config["config"]["User"] == "camdirector"
    assert set(manifest["Layers"]) <= names and len(manifest["Layers"]) == len(config["rootfs"]["diff_ids"])
