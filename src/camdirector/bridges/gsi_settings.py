"""The GSI bridge's settings (`camdirector cast gsi`): one typed object per component, each default
with its unit and limit, validated once."""

from __future__ import annotations

import math
from dataclasses import dataclass


def _check(checks: list[tuple[bool, str]]) -> None:
    bad = [message for ok, message in checks if not ok]
    if bad:
        raise ValueError("; ".join(bad))


@dataclass(frozen=True)
class GsiEndpointSettings:
    """The HTTP endpoint CS2 posts its payloads to (gsi_server.py)."""

    host: str = "127.0.0.1"              # the address to listen on; the game runs on the same machine or the LAN
    port: int = 3000                     # TCP port (0: any free one). [0, 65535]
    token: str = ""                      # the auth token every payload must carry (the cfg's auth.token); required, 1 to 256 printable characters
    max_body_bytes: int = 1 << 20        # largest payload accepted, bytes (413 above); a full spectator payload is ~15 KiB. [1 KiB, 64 MiB]

    def __post_init__(self):
        _check(
            [
                (0 <= self.port <= 65535, "port must be in [0, 65535]"),
                (1 <= len(self.token) <= 256 and self.token.isprintable() and '"' not in self.token,
                 "token must be 1 to 256 printable characters without a double quote"),
                (1024 <= self.max_body_bytes <= 64 << 20, "max_body_bytes must be in [1 KiB, 64 MiB]"),
            ]
        )


@dataclass(frozen=True)
class GsiDriverSettings:
    """The clock-driven loop that turns the newest payloads into the session's frames (gsi_cast.py)."""

    rate_hz: float = 30.0                # frames sent to the server a second. [1, 120]
    interp_delay_s: float = 0.1          # frames show the players this far in the past, so that two payloads bracket them (the game's throttle, default 0.1 s). [0, 2]
    hold_s: float = 2.0                  # without a payload, players are held where they were last seen this long, then frames pause (stale). [0.1, 60]
    delay_s: float = 10.0                # the broadcast delay of the session, s. [0, 300]

    def __post_init__(self):
        _check(
            [
                (math.isfinite(self.rate_hz) and 1.0 <= self.rate_hz <= 120.0, "rate_hz must be in [1, 120]"),
                (0.0 <= self.interp_delay_s <= 2.0, "interp_delay_s must be in [0, 2]"),
                (0.1 <= self.hold_s <= 60.0, "hold_s must be in [0.1, 60]"),
                (0.0 <= self.delay_s <= 300.0, "delay_s must be in [0, 300]"),
            ]
        )


@dataclass(frozen=True)
class NetconSettings:
    """The program camera sent to CS2's console (netcon.py; the game started with -netconport)."""

    host: str = "127.0.0.1"              # the console's address
    port: int = 2121                     # the game's -netconport. [1, 65535]
    rate_hz: float = 10.0                # most spec_goto lines a second; the program changes faster than an observer camera needs. [0.1, 64]
    reconnect_s: float = 1.0             # wait between two connection attempts after the console went away, s. [0.05, 60]

    def __post_init__(self):
        _check(
            [
                (1 <= self.port <= 65535, "port must be in [1, 65535]"),
                (math.isfinite(self.rate_hz) and 0.1 <= self.rate_hz <= 64.0, "rate_hz must be in [0.1, 64]"),
                (0.05 <= self.reconnect_s <= 60.0, "reconnect_s must be in [0.05, 60]"),
            ]
        )
