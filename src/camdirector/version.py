"""Which camdirector this is: the release (one version for the server, the wire code and the
SDKs, written in each distribution's pyproject.toml and the C/C++ SDK's CMakeLists.txt, which
tests/test_versions.py holds equal) and the protocol (the wire contract's revision: a client newer
than its server is told so)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    VERSION = version("camdirector")
except PackageNotFoundError:  # run from a checkout that was never installed (python -m from src/)
    VERSION = "0+unknown"
PROTOCOL = 1  # raised when the wire contract gains what an older server cannot answer
