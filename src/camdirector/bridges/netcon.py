"""The program camera sent to Counter-Strike 2's console as `spec_goto X Y Z PITCH YAW` lines.

CS2 started with `-netconport PORT` takes console commands, one a line, over a plain TCP
connection. `spec_goto` puts a free-roaming observer's camera at a point (Source units, Z up)
with a pitch (degrees, positive looking down) and a yaw (degrees about +Z from +X). The program's
pose comes back from our world (metres, Y up, the camera looking down its local -Z; docs/protocol.md)
by the inverse of the demo importer's map (matches/cs2_demo.py: Source (x, y, z) units -> world
(x, z, -y) * 0.0254 m).

No `spec_player`: it would hand the view to a player's own eyes, and no shot of the wire contract
is a first-person view (ShotKind: DUEL, FOLLOW, GROUP, OVERVIEW), so every program pose is a
spec_goto. Lines are sent at most rate_hz a second (the others dropped: the next pose supersedes
them); when the console is not there or goes away, the sender drops lines and tries again every
reconnect_s, never blocking the caller for more than a short socket timeout.
"""

from __future__ import annotations

import logging
import socket

import numpy as np
import numpy.typing as npt

from camdirector.bridges.gsi_settings import NetconSettings
from camdirector.geometry.transforms import quat_rotate
from camdirector.matches.cs2_demo import source_points_to_world

SEND_TIMEOUT_S = 0.2  # longest a connect or a send may hold the reply loop
log = logging.getLogger("camdirector.bridges.netcon")
_M_PER_UNIT = float(source_points_to_world(np.array([1.0, 0.0, 0.0]))[0])  # the importer's scale


def world_to_source(points_world: npt.ArrayLike) -> np.ndarray:
    """World points (..., 3) m, Y up -> Source points (..., 3) units, Z up: the inverse of
    cs2_demo.source_points_to_world."""
    p = np.asarray(points_world, dtype=np.float64)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1) / _M_PER_UNIT


def spec_goto_line(position_world: npt.ArrayLike, rotation_xyzw: npt.ArrayLike) -> str:
    """The console line putting the observer camera at a camera pose: position (3,) m, rotation
    (4,) xyzw camera-to-world (the camera looking down its local -Z)."""
    x, y, z = world_to_source(position_world)
    fx, fy, fz = world_to_source(quat_rotate(rotation_xyzw, np.array([0.0, 0.0, -1.0]))) * _M_PER_UNIT
    pitch_deg = -np.degrees(np.arcsin(np.clip(fz, -1.0, 1.0)))
    yaw_deg = np.degrees(np.arctan2(fy, fx))
    return f"spec_goto {x:.1f} {y:.1f} {z:.1f} {pitch_deg:.2f} {yaw_deg:.2f}\n"


class NetconSender:
    """Sends lines to the console, rate-limited and reconnecting (module docstring). Not
    thread-safe: one caller (the reply loop)."""

    def __init__(self, settings: NetconSettings):
        self.settings = settings
        self.sent = 0
        self.dropped = 0
        self._sock: socket.socket | None = None
        self._next_send_s = float("-inf")
        self._next_connect_s = float("-inf")

    def offer(self, line: str, now_s: float) -> bool:
        """Sends `line` if a line is due at now_s (monotonic s) and the console is there; whether
        it went out."""
        if now_s < self._next_send_s:
            self.dropped += 1
            return False
        sock = self._connected(now_s)
        if sock is None:
            self.dropped += 1
            return False
        try:
            sock.sendall(line.encode("ascii"))
        except OSError as exc:
            log.warning("netcon %s:%d: send failed (%s); reconnecting", self.settings.host, self.settings.port, exc)
            self.close()
            self._next_connect_s = now_s + self.settings.reconnect_s
            self.dropped += 1
            return False
        self._next_send_s = max(self._next_send_s + 1.0 / self.settings.rate_hz, now_s)
        self.sent += 1
        return True

    def _connected(self, now_s: float) -> socket.socket | None:
        if self._sock is not None or now_s < self._next_connect_s:
            return self._sock
        try:
            self._sock = socket.create_connection((self.settings.host, self.settings.port), timeout=SEND_TIMEOUT_S)
        except OSError as exc:
            self._next_connect_s = now_s + self.settings.reconnect_s
            log.info("netcon %s:%d: not connected (%s)", self.settings.host, self.settings.port, exc)
            return None
        self._sock.settimeout(SEND_TIMEOUT_S)
        return self._sock

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
