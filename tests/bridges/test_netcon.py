"""bridges/netcon.py: spec_goto is the demo importer's conversion run backwards, and a TCP
listener standing in for CS2's console gets lines no faster than the rate, reconnecting."""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest

from camdirector.bridges.gsi_settings import NetconSettings
from camdirector.bridges.netcon import NetconSender, spec_goto_line, world_to_source
from camdirector.geometry.transforms import matrix_to_quat, quat_to_matrix
from camdirector.matches.cs2_demo import source_points_to_world, view_rotation


def test_world_to_source_inverts_the_importers_conversion():
    points = np.array([[218.35, -1529.35, -175.97], [-974.5, 127.35, -367.97]])
    np.testing.assert_allclose(world_to_source(source_points_to_world(points)), points, atol=1e-9)


@pytest.mark.parametrize("pitch_deg, yaw_deg", [(0.0, 0.0), (20.0, 135.0), (-35.0, -60.0)])
def test_spec_goto_carries_the_cameras_view_as_source_angles(pitch_deg, yaw_deg):
    # a camera looks down its -Z; the importer's view_rotation turns +Z onto the view
    view = view_rotation(np.array(pitch_deg), np.array(yaw_deg))
    flip = matrix_to_quat(np.diag([-1.0, 1.0, -1.0]))  # half a turn about +Y: -Z where +Z was
    camera = matrix_to_quat(quat_to_matrix(view) @ quat_to_matrix(flip))
    position = source_points_to_world(np.array([100.0, -200.0, 64.0]))
    words = spec_goto_line(position, camera).split()
    assert words[0] == "spec_goto"
    np.testing.assert_allclose([float(w) for w in words[1:]], [100.0, -200.0, 64.0, pitch_deg, yaw_deg], atol=0.06)


class Console:
    """A TCP listener standing in for CS2's -netconport: collects the lines it gets, with their
    arrival times; accepts again after a client went away."""

    def __init__(self):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.lines: list[tuple[float, str]] = []
        self.connections = 0
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.connections += 1
            with conn, conn.makefile("r") as f:
                for line in f:
                    self.lines.append((time.monotonic(), line.rstrip("\n")))

    def close(self):
        self.sock.close()


def test_lines_reach_the_console_at_most_at_the_rate():
    console = Console()
    try:
        sender = NetconSender(NetconSettings(port=console.port, rate_hz=20.0))
        start = time.monotonic()
        window_s = 1.5
        while time.monotonic() - start < window_s:  # a program at ~200 Hz, far above the rate
            sender.offer("spec_goto 1.0 2.0 3.0 0.00 90.00\n", time.monotonic())
            time.sleep(0.005)
        sender.close()
        deadline = time.monotonic() + 2.0
        while len(console.lines) < sender.sent and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(console.lines) == sender.sent
        assert 0 < sender.sent <= 20.0 * window_s + 1
        assert sender.sent >= 10  # and it does send, about at the rate
        assert all(line == "spec_goto 1.0 2.0 3.0 0.00 90.00" for _, line in console.lines)
    finally:
        console.close()


def test_a_missing_console_drops_lines_and_is_reached_once_it_listens():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    sender = NetconSender(NetconSettings(port=port, rate_hz=50.0, reconnect_s=0.05))
    assert not sender.offer("spec_goto 0 0 0 0 0\n", time.monotonic())
    console = socket.create_server(("127.0.0.1", port))
    try:
        deadline = time.monotonic() + 3.0
        while not sender.offer("spec_goto 0 0 0 0 0\n", time.monotonic()) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert sender.sent == 1 and sender.dropped >= 1
    finally:
        sender.close()
        console.close()
