"""The SDK as another project gets it: `cmake --install` of the tests' build into an empty prefix;
then examples/consumer, copied out of the tree, built against that prefix alone with
find_package(camdirector CONFIG REQUIRED) and run against a real server for 600 frames; and a C
file built with nothing but what `pkg-config --static camdirector` says."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

from camdirector.version import VERSION
from tests.client_sdk.cpp.conftest import SDK_DIR, run_json

TIMEOUT_S = 300  # a configure and one small compile on two busy cores


def _run(cmd: list[str], env: dict | None = None, cwd: Path | None = None) -> str:
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S, env=env, cwd=cwd)
    assert done.returncode == 0, f"{' '.join(cmd)} failed:\n{done.stdout[-4000:]}\n{done.stderr[-4000:]}"
    return done.stdout


def _cache(build_dir: Path, name: str) -> str:
    """A variable of a CMake build's cache."""
    for line in (build_dir / "CMakeCache.txt").read_text().splitlines():
        if line.startswith(f"{name}:"):
            return line.split("=", 1)[1]
    raise AssertionError(f"{name} is not in {build_dir}/CMakeCache.txt")


def _isolated_env() -> dict:
    """This environment without what could point CMake or pkg-config at another camdirector than
    the prefix under test."""
    return {
        k: v
        for k, v in os.environ.items()
        if k not in ("CMAKE_PREFIX_PATH", "PKG_CONFIG_PATH", "PKG_CONFIG_LIBDIR", "camdirector_DIR")
    }


@pytest.fixture(scope="module")
def installed(sdk_bin, tmp_path_factory) -> tuple[Path, str]:
    """(prefix, libdir relative to it): the SDK installed from the tests' build."""
    prefix = tmp_path_factory.mktemp("prefix")
    _run(["cmake", "--install", str(sdk_bin), "--prefix", str(prefix)])
    return prefix, _cache(sdk_bin, "CMAKE_INSTALL_LIBDIR")


def test_the_install_holds_the_headers_the_libraries_and_both_package_files(installed):
    prefix, libdir = installed
    files = {p.relative_to(prefix).as_posix() for p in prefix.rglob("*") if p.is_file()}
    assert files == {
        "include/camdirector/camdirector.h",
        "include/camdirector/camdirector.hpp",
        f"{libdir}/libcamdirector.a",
        f"{libdir}/libcamdirector_wire.a",  # the generated wire code, linked by the library
        f"{libdir}/cmake/camdirector/camdirectorConfig.cmake",
        f"{libdir}/cmake/camdirector/camdirectorConfigVersion.cmake",
        f"{libdir}/cmake/camdirector/camdirectorTargets.cmake",
        f"{libdir}/cmake/camdirector/camdirectorTargets-release.cmake",
        f"{libdir}/pkgconfig/camdirector.pc",
    }, "the public headers need no generated protobuf header, so none is installed"


def test_a_separate_cmake_project_finds_the_installed_sdk_and_streams_600_frames(installed, sdk_bin, server, tmp_path):
    prefix, libdir = installed
    source, build = tmp_path / "consumer", tmp_path / "consumer-build"
    shutil.copytree(SDK_DIR / "examples" / "consumer", source)  # nothing relative reaches the SDK's tree
    _run(
        [
            "cmake",
            "-S",
            str(source),
            "-B",
            str(build),
            f"-DCMAKE_PREFIX_PATH={prefix}",
            "-DCMAKE_FIND_PACKAGE_NO_PACKAGE_REGISTRY=ON",
            "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON",
        ],
        env=_isolated_env(),
    )
    _run(["cmake", "--build", str(build)])
    assert Path(_cache(build, "camdirector_DIR")) == prefix / libdir / "cmake" / "camdirector"
    # The compile and link lines name the prefix and never the SDK's sources or build.
    lines = (build / "compile_commands.json").read_text() + (build / "CMakeFiles/stream_frames.dir/link.txt").read_text()
    assert str(prefix) in lines and str(SDK_DIR) not in lines, lines

    report = run_json(build / "stream_frames", server.grpc, "600", timeout_s=120)
    assert report["flush"] == "OK" and report["close"] == "OK", report
    assert report["frames_submitted"] == 600 and report["frames_dropped"] == 0, report
    assert report["frames_answered"] == report["server_frames"] == 600, report
    assert report["last_pose_frame"] == 600 and report["frames_lost"] == 0, report


def test_a_c_program_builds_with_pkg_config_alone(installed, tmp_path):
    prefix, libdir = installed
    env = {**_isolated_env(), "PKG_CONFIG_PATH": str(prefix / libdir / "pkgconfig")}
    # Both package files state the one version (the project's, from CMakeLists.txt).
    config_version = (prefix / libdir / "cmake/camdirector/camdirectorConfigVersion.cmake").read_text()
    version = re.search(r'set\(PACKAGE_VERSION "([^"]+)"\)', config_version).group(1)
    assert _run(["pkg-config", "--modversion", "camdirector"], env=env).strip() == version
    flags = shlex.split(_run(["pkg-config", "--static", "--cflags", "--libs", "camdirector"], env=env))
    (tmp_path / "check.c").write_text(r"""#include <stdio.h>
#include <camdirector/camdirector.h>

int main(void) {
  char why[128] = "";
  cd_status good = cd_check_address("127.0.0.1:50051", NULL, 0);
  cd_status bad = cd_check_address("127.0.0.1", why, sizeof why);
  printf("{\"good\": \"%s\", \"bad\": \"%s\", \"why\": \"%s\", \"version\": \"%s\"}\n", cd_status_name(good),
         cd_status_name(bad), why, cd_version());
  return 0;
}
""")
    _run(["cc", "-std=c99", "check.c", "-o", "check", *flags], cwd=tmp_path)
    assert json.loads(_run([str(tmp_path / "check")])) == {
        "good": "OK",
        "bad": "INVALID_ARGUMENT",
        "why": "address '127.0.0.1' has no port: expected HOST:PORT",
        "version": VERSION,
    }  # the project's one version (camdirector.version)
    assert version == VERSION
