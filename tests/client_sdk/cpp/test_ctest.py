"""The C/C++ SDK's own unit tests (client_sdk/cpp/tests, registered with CTest), run by ctest in
the build the fixture made: conversions against docs/protocol.md's tables, fields of view,
address parsing, and the game thread's refusals without a session."""

from __future__ import annotations

import subprocess


def test_ctest_runs_the_sdks_unit_tests(sdk_bin):
    done = subprocess.run(
        ["ctest", "--test-dir", str(sdk_bin), "--output-on-failure"], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "100% tests passed, 0 tests failed out of 2" in done.stdout, done.stdout
