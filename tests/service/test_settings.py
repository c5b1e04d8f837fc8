"""Settings: defaults, environment variables, flags over both, and validation."""
from __future__ import annotations

import subprocess
import sys

import pytest

from camdirector.server_settings import ServerSettings


def test_environment_then_flags():
    env = {"CAMDIRECTOR_MAX_SESSIONS": "7", "CAMDIRECTOR_SESSION_RESUME_S": "2.5",
           "CAMDIRECTOR_RECORD_ALL": "yes", "CAMDIRECTOR_GRPC_ADDR": ""}
    settings = ServerSettings.from_env(env)
    assert (settings.max_sessions, settings.session_resume_s, settings.record_all, settings.grpc_addr) == (7, 2.5, True, "")
    assert ServerSettings.from_env(env, max_sessions=9, workers=None).max_sessions == 9


@pytest.mark.parametrize("env, message", [
    ({"CAMDIRECTOR_MAX_SESSIONS": "many"}, "cannot read 'many' as int"),
    ({"CAMDIRECTOR_MAX_SESSIONS": "0"}, "max_sessions"),
    ({"CAMDIRECTOR_ZMQ_ADDR": "udp://x"}, "zmq_addr"),
    ({"CAMDIRECTOR_RECORD_ALL": "maybe"}, "RECORD_ALL"),
])
def test_bad_settings_are_refused(env, message):
    with pytest.raises(ValueError, match=message):
        ServerSettings.from_env(env)


def test_serve_refuses_a_bad_flag_with_a_message():
    out = subprocess.run([sys.executable, "-m", "camdirector.__main__", "serve", "--max-sessions", "0"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "max_sessions must be in" in out.stderr
