"""What a service that does not start reports (deploy/services.py): a CI run's HAProxy ran, logged
nothing and refused its port for 10 s; the report now says what the process was doing and
whether anything held the port."""

from __future__ import annotations

import socket
import subprocess
import sys

import pytest

from camdirector.deploy.services import ServiceError, _wait_port, free_port, process_state, tcp_state


def test_a_process_that_runs_without_listening_is_reported_with_its_state_and_the_ports(tmp_path):
    log = tmp_path / "log"
    log.write_text("started\n")
    port = free_port()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        with pytest.raises(ServiceError) as refused:
            _wait_port(port, sleeper, 0.3, "sleeper", log)
        message = str(refused.value)
        assert f"pid {sleeper.pid}: S (sleeping) in " in message and "the port: nothing" in message
        assert message.endswith("started\n")
    finally:
        sleeper.kill()
        sleeper.wait()
    assert process_state(sleeper.pid) == "gone"


def test_a_listening_port_is_told_from_a_closed_one():
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        assert tcp_state(f"127.0.0.1:{port}") == "LISTEN"
    assert tcp_state(f"127.0.0.1:{port}") == "nothing"
