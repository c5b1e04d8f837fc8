"""The GSI bridge's session: a RIG_MATCH session driven by a clock from the newest GSI payloads.

Once the first payload with players came (gsi_tracks.py fixes the roster), the session opens on
`level` with the players as capsule targets (evaluation/match/measure.py's body and aim point) and
one StreamFrames stream carries a frame every 1 / rate_hz s of the monotonic clock: every player
interpolated (gsi_tracks.Sample), its scoreboard values when they changed (health, armor, items:
1 helmet, 2 defuse kit; frags: match_stats.kills) and the derived events. Game time is the clock's
time since the session opened. When payloads stop, players are held for hold_s, then no frame is
sent (the program holds; a progress line says stale) until a payload comes again, game time then
going on from the clock. Each program pose goes to the console when one is given (netcon.py).
A player who joins later (gsi_tracks.py) ends the session and the next opens with him at once.
The session loop is live_session.py's, shared with the QTV bridge.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import camdirector_client as cd
from camdirector.bridges.gsi_settings import GsiDriverSettings
from camdirector.bridges.gsi_tracks import GsiTracks
from camdirector.bridges.live_session import CastCounts, drive_sessions
from camdirector.bridges.netcon import NetconSender, spec_goto_line


def cast_gsi(
    client: cd.Client,
    tracks: GsiTracks,
    settings: GsiDriverSettings,
    *,
    level: str,
    director: str,
    stop: threading.Event,
    netcon: NetconSender | None = None,
    clock: Callable[[], float] = time.monotonic,
    on_session: Callable[[str], None] = lambda session_id: None,
    on_progress: Callable[[CastCounts], None] = lambda counts: None,
    progress_s: float = 1.0,
) -> CastCounts:
    """Runs the sessions (module docstring, live_session.py) until `stop` is set; returns the
    counts. DirectorError: the server refused a session or its stream failed."""

    def to_console(pose: cd.pb.Pose, now_s: float) -> None:
        if netcon is not None:
            position = [pose.position.x, pose.position.y, pose.position.z]
            rotation = [pose.rotation.x, pose.rotation.y, pose.rotation.z, pose.rotation.w]
            netcon.offer(spec_goto_line(position, rotation), now_s)

    return drive_sessions(
        client,
        tracks,
        stop=stop,
        rate_hz=settings.rate_hz,
        delay_s=settings.delay_s,
        level=level,
        director=director,
        on_pose=to_console,
        clock=clock,
        on_session=on_session,
        on_progress=on_progress,
        progress_s=progress_s,
    )
