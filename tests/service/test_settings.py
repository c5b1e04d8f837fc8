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
    ({"CAMDIRECTOR_POSE_OUTPUT_ALLOW": "10.0.0.1/8"}, "pose_output_allow"),  # host bits set
    ({"CAMDIRECTOR_POSE_OUTPUT_ALLOW": "::1/128"}, "pose_output_allow"),
    ({"CAMDIRECTOR_POSE_OUTPUT_ALLOW": ""}, "pose_output_allow"),
    ({"CAMDIRECTOR_TENANT_MAX_LIVE_VIEWS": "65"}, "tenant_max_live_views"),
    ({"CAMDIRECTOR_MAP_THREADS": "65"}, "map_threads"),
    ({"CAMDIRECTOR_MAP_THREADS": "-1"}, "map_threads"),
])
def test_bad_settings_are_refused(env, message):
    with pytest.raises(ValueError, match=message):
        ServerSettings.from_env(env)


def test_map_threads_default_to_the_cores_only_where_the_front_holds_the_sessions(monkeypatch):
    monkeypatch.setattr("os.cpu_count", lambda: 6)
    assert ServerSettings(workers=0).map_threads_per_update == 6
    assert ServerSettings(workers=2).map_threads_per_update == 1  # the workers already share the cores
    assert ServerSettings(workers=2, map_threads=3).map_threads_per_update == 3


def test_serve_refuses_a_bad_flag_with_a_message():
    out = subprocess.run([sys.executable, "-m", "camdirector.__main__", "serve", "--max-sessions", "0"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "max_sessions must be in" in out.stderr


def test_pose_outputs_go_to_loopback_unless_the_operator_allows_more():
    assert ServerSettings().pose_output_allow == ("127.0.0.0/8",)
    env = {"CAMDIRECTOR_POSE_OUTPUT_ALLOW": "10.20.0.0/16, 192.0.2.7/32"}
    assert ServerSettings.from_env(env).pose_output_allow == ("10.20.0.0/16", "192.0.2.7/32")
