"""The stream clock: a live feed's own clock (a QTV stream's demo time, the sum of its MVD blocks'
time deltas) mapped onto the local monotonic clock by a jitter buffer, so that the players move
at the pace the source recorded them, not at the pace their bytes arrived.

Each arrival says that the feed's time source_s reached this machine at local_s. Its delay,
local_s - source_s, is the path's latency plus a constant (the two clocks' origins): a segment
that comes late, or several that come bunched after a stall, have a larger one. The offset
follows the least delay over the last window_s (the arrival that waited least): down at once (a
source time is never shown later than its earliest arrival allows, so a source that runs faster
than real time, catching up, plays at its pace), up at most `slew` seconds per second of the
local clock. So late and bunched arrivals change nothing, and a lasting rise of the latency
moves the mapping slowly (the players play at most `slew` slower meanwhile). Source time source_s
is due at local time source_s + offset, the earliest its data arrives; the feed's reader shows it
a playout delay later (qtv.py's interp_delay_s), the time a late segment has before its players
would be held. An arrival more than reanchor_s off the offset either way (the source paused, or
skipped ahead) re-anchors the mapping on it, as does reanchor() (a new connection, whose time
starts anew).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class StreamClockSettings:
    """The jitter buffer of a live feed's clock (module docstring)."""

    window_s: float = 3.0  # the least delay is taken over this much of the latest arrivals, s. [0.1, 60]
    slew: float = 0.05  # the offset rises at most this many s per s toward the least delay (playback pace 1 - slew). [0, 0.5]
    reanchor_s: float = 1.0  # an arrival this far off the offset either way re-anchors it on itself, s. [0.1, 60]

    def __post_init__(self):
        checks = [
            (0.1 <= self.window_s <= 60.0, "window_s must be in [0.1, 60]"),
            (0.0 <= self.slew <= 0.5, "slew must be in [0, 0.5]"),
            (0.1 <= self.reanchor_s <= 60.0, "reanchor_s must be in [0.1, 60]"),
        ]
        bad = [message for ok, message in checks if not ok]
        if bad:
            raise ValueError("; ".join(bad))


class StreamClock:
    """The mapping (module docstring): arrive() each time the feed's clock is seen, local_of() the
    local time a source time is due. Not thread-safe: the caller holds its own lock."""

    def __init__(self, settings: StreamClockSettings):
        self.settings = settings
        self._delays: deque[tuple[float, float]] = deque()  # (local_s, delay_s): the window's least first, then later leasts
        self._offset_s = math.nan  # nan: not anchored
        self._last_local_s = 0.0
        self.anchors = 0  # times the mapping was (re-)anchored

    def reanchor(self) -> None:
        """The next arrival anchors the mapping (a new stream whose clock starts anew)."""
        self._offset_s = math.nan

    def arrive(self, source_s: float, local_s: float) -> None:
        """The feed's clock read source_s when its bytes reached this machine at local_s."""
        delay_s = local_s - source_s
        anchored = not math.isnan(self._offset_s) and abs(delay_s - self._offset_s) <= self.settings.reanchor_s
        if not anchored:
            self._delays.clear()
            self._offset_s = delay_s
            self.anchors += 1
        while self._delays and self._delays[-1][1] >= delay_s:
            self._delays.pop()  # never the least again: this one is less and leaves the window later
        self._delays.append((local_s, delay_s))
        while self._delays[0][0] < local_s - self.settings.window_s:
            self._delays.popleft()
        if anchored:
            step_s = self.settings.slew * max(0.0, local_s - self._last_local_s)
            self._offset_s = min(self._delays[0][1], self._offset_s + step_s)
        self._last_local_s = local_s

    def local_of(self, source_s: float) -> float:
        """The local time at which source time source_s is due; nan before the first arrival."""
        return source_s + self._offset_s
