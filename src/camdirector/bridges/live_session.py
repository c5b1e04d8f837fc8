"""A RIG_MATCH session driven by a clock from a live feed's players, shared by the bridges
(gsi_cast.py, qtv.py).

Once the feed knows its roster, the session opens on `level` with the players as capsule targets
(evaluation/match/measure.py's body and aim point) and one StreamFrames stream carries a frame
every 1 / rate_hz s of the monotonic clock: every player as the feed samples it at that tick
(interpolated or held, the feed's rule), its scoreboard values when they changed and the events
since the last frame. Game time is the tick's time since the session opened: each tick is sampled
at its own time on the 1 / rate_hz grid however late its thread woke (a busy machine), so the
frames lie whole periods apart in game time as in the feed's time; a thread that woke late sends
its tick, then the latest tick since at once, skipping any between. While the feed is stale no
frame is sent (the program holds) and the tick is counted; frames go on when it comes back, game
time going on from the clock, in the same session. Nor is one sent before the feed's first sample
is due (the sample says not started), nor counted: the first frame's game time is then the delay
that took. When `end` is set (a feed whose roster changed) the stream ends and the session closes,
and the feed (not stopped) can drive the next one: drive_sessions opens the next at once with the
feed's new roster (a session's players are fixed when it opens), as long as the feed's roster
changes.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

import camdirector_client as cd
from camdirector.bridges.gsi_tracks import DerivedEvent, Sample
from camdirector.evaluation.match.match_file import MatchPlayer
from camdirector.evaluation.match.measure import aim_offset, player_mesh
from camdirector.matches.cs2_demo import view_rotation

EVENT_LABELS = {"kill": "kill", "death": "died", "kill_unknown": "kill, victim unknown"}
# a death whose other side the feed leaves unsaid (a QuakeWorld teamkill's obituary names one side; a GSI payload's
# dead player with no killer in it) goes as a CUSTOM event rated as a kill is (MatchSettings.priorities, HLTV's 7): news
# the director gives a beat and keeps replays off, as eval-match counts the kill the demo resolved (a cast's replay
# covered a teamkill at 147.6 s, rated 4 as a CUSTOM event: a live kill missed for a replay)
ONE_SIDED_PRIORITY = 7

log = logging.getLogger(__name__)


class LiveTracks(Protocol):
    """A live feed's players as the driver reads them (gsi_tracks.GsiTracks, qtv.QtvTracks)."""

    @property
    def roster(self) -> list[MatchPlayer]: ...

    def wait_roster(self, timeout_s: float) -> bool: ...

    def sample(self, now_s: float) -> Sample: ...


class GrowingTracks(LiveTracks, Protocol):
    """A live feed whose roster can change while a session runs: roster_changed is set when it
    did, and reopen() takes the changes into the roster (the players who joined or changed) and
    clears it; until then nothing of those players is sampled."""

    @property
    def roster_changed(self) -> threading.Event: ...

    def reopen(self) -> list[MatchPlayer]: ...


@dataclass
class CastCounts:
    """sessions opened, frames sent, answered, program (answers with a pose), cuts, kills (events sent), stale
    (clock ticks without a frame: no payload for hold_s), last_shot (the program's shot: kind and
    subjects' names)."""

    sessions: int = 0
    frames: int = 0
    answered: int = 0
    program: int = 0
    cuts: int = 0
    kills: int = 0
    stale: int = 0
    last_shot: str = ""


def event_msg(event: DerivedEvent) -> cd.pb.GameEvent:
    kind = cd.pb.EVENT_KILL if event.kind == "kill" else cd.pb.EVENT_CUSTOM
    return cd.pb.GameEvent(
        kind=kind,
        actor_id=event.actor_id,
        other_actor_id=event.other_id,
        priority=0 if event.kind == "kill" else ONE_SIDED_PRIORITY,  # 0: the kind's own (a kill's)
        label=EVENT_LABELS[event.kind],
        position=cd.vec3(event.position_world),
    )


def frame_update(session: cd.Session, frame: int, time_s: float, sample: Sample) -> cd.pb.FrameUpdate:
    """The FrameUpdate of a sample: bodies turned by their yaw alone, as the demo importer's."""
    rotations = view_rotation(np.zeros_like(sample.yaw_deg), sample.yaw_deg)
    update = session.frame_update(frame, time_s, packed=cd.pack_states(sample.ids, sample.positions_world, rotations))
    update.player_stats.extend(cd.pb.PlayerStats(id=i, health=h, armor=a, items=it, frags=f) for i, h, a, it, f in sample.stats)
    update.events.extend(event_msg(e) for e in sample.events)
    return update


def drive_session(
    client: cd.Client,
    tracks: LiveTracks,
    *,
    rate_hz: float,
    delay_s: float,
    level: str,
    director: str,
    stop: threading.Event,
    on_pose: Callable[[cd.pb.Pose, float], None] | None = None,
    on_frame: Callable[[int, float, Sample], None] | None = None,
    on_reply: Callable[[cd.pb.CameraUpdate], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
    on_session: Callable[[str], None] = lambda session_id: None,
    on_progress: Callable[[CastCounts], None] = lambda counts: None,
    progress_s: float = 1.0,
    end: threading.Event | None = None,
    counts: CastCounts | None = None,
) -> CastCounts:
    """Runs the session (module docstring) until `stop` is set; returns the counts. Waits for the
    roster first (returns with no frames if stopped before). on_pose: each program pose and the
    clock's time; on_frame: each frame sent (its number, game time and the sample it carries), and
    on_progress: the counts every progress_s, stale or not, both on the stream's sending thread;
    on_reply: each reply; end: ends this session only (module docstring); counts: go on counting
    into these (a feed's sessions one after another). DirectorError: the server refused the
    session or the stream failed."""
    counts = CastCounts() if counts is None else counts
    while not tracks.wait_roster(0.1):
        if stop.is_set():
            return counts
    targets = [
        cd.pb.Target(
            id=p.id,
            team=p.team,
            display_name=p.name,
            team_name=p.team_name,
            mesh=cd.mesh_from_arrays(player_mesh(p).vertices, player_mesh(p).faces),
            aim_offset=cd.vec3(aim_offset(p)),
        )
        for p in tracks.roster
    ]
    names = {p.id: p.name for p in tracks.roster}
    style = cd.pb.Style(rig=cd.pb.RIG_MATCH, match_director_name=director)
    with client.create_session(targets=targets, level_id=level, delay_s=delay_s, style=style) as session:
        counts.sessions += 1
        on_session(session.id)
        start_s = clock()

        def updates() -> Iterator[cd.pb.FrameUpdate]:
            period_s = 1.0 / rate_hz
            due_s = next_progress_s = start_s
            while not stop.wait(max(0.0, due_s - clock())) and not (end is not None and end.is_set()):
                now_s = due_s  # the tick's own time (module docstring), however late this runs
                due_s += period_s * max(1, math.floor((clock() - now_s) / period_s))  # the latest missed tick, no other
                if now_s >= next_progress_s:  # on the tick, not a reply: none comes while stale
                    next_progress_s = now_s + progress_s
                    on_progress(counts)
                sample = tracks.sample(now_s)
                if sample.stale:
                    counts.stale += 1
                    continue
                if not sample.started:  # the feed's first sample not yet due: nothing moves to show
                    continue
                counts.frames += 1
                counts.kills += sum(e.kind == "kill" for e in sample.events)
                if on_frame is not None:
                    on_frame(counts.frames, now_s - start_s, sample)
                yield frame_update(session, counts.frames, now_s - start_s, sample)

        replies = session.stream(updates())
        try:
            for reply in replies:
                counts.answered += 1
                if on_reply is not None:
                    on_reply(reply)
                if not (reply.buffering or reply.stale) and reply.HasField("pose"):
                    counts.program += 1
                    counts.cuts += reply.cut
                    shot = reply.shot
                    who = ", ".join(names.get(i, i) for i in shot.subject_ids)
                    counts.last_shot = f"{cd.pb.ShotKind.Name(shot.kind).removeprefix('SHOT_')} {who}".strip()
                    if on_pose is not None:
                        on_pose(reply.pose, clock())
        finally:
            if end is None or not end.is_set():  # the feed goes on only for the next session
                stop.set()
            if isinstance(replies, Generator):  # ends the stream now, not when collected
                replies.close()
    return counts


def drive_sessions(
    client: cd.Client,
    tracks: GrowingTracks,
    *,
    stop: threading.Event,
    on_reopen: Callable[[list[MatchPlayer]], None] = lambda changed: None,
    **drive: Any,
) -> CastCounts:
    """drive_session (its keywords in `drive`, but end and counts) until `stop` is set, a session
    after another each time the feed's roster changes (module docstring): one warning line names
    the players who joined or changed, then on_reopen hears them before the next session opens.
    Returns the counts of all the sessions together."""
    counts = CastCounts()
    while True:
        drive_session(client, tracks, stop=stop, end=tracks.roster_changed, counts=counts, **drive)
        if stop.is_set() or not tracks.roster_changed.is_set():
            return counts
        changed = tracks.reopen()
        log.warning(
            "the roster changed (%s): a new session with %d players",
            ", ".join(f"{p.id} {p.name}" for p in changed) or "back as it was",
            len(tracks.roster),
        )
        on_reopen(changed)
