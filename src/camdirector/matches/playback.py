"""A recorded match played live into a RIG_MATCH session, for a casting crew rehearsing with the
dashboard (`camdirector play-match`, issue 29 item 2).

The session and its frames are eval-match's (evaluation/match/session_feed.py: the players as
capsule targets on the match's level, the rows subsampled to a rate with the events of skipped rows
riding on the next sent one, and the players' scoreboard values where the match has them, each lap
beginning with all of them). They go out over one StreamFrames stream, each frame held until it is
due: the first at once, then each when the wall clock since the first, times `speed`, reaches its
game time since the first. Once played, the last row is held for the delay so that the program
reaches the match's end; with `loop` the match starts again instead, one step after its last row,
frame numbers and game times going on increasing, until stopped.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

import camdirector_client as cd
from camdirector.evaluation.match.match_file import MatchRecording
from camdirector.evaluation.match.session_feed import Feed, frame_updates, match_session_fields


@dataclass
class PlaybackCounts:
    """A playback's counts so far: frames sent, replies (answered), replies carrying a program
    camera (neither buffering nor stale), cuts among them, late frames (sent more than one frame
    period, 1 / (rate_hz * speed) s of wall time, after they were due) and laps begun.

    sent, late and laps are written by the thread that feeds the stream, the others by the one
    that reads its replies."""

    sent: int = 0
    answered: int = 0
    program: int = 0
    cuts: int = 0
    late: int = 0
    laps: int = 0


@dataclass
class PlaybackResult:
    """How a playback ended: its counts, wall_s (s, from opening the session to closing it),
    whether Ctrl-C stopped it, and the server's compute_ms of each program frame (whether the
    director kept up with the game: a frame it answers late is late on air) and of each buffering
    reply (the MATCH rig works its edit window out while the delay fills: its first plan is there)."""

    counts: PlaybackCounts = field(default_factory=PlaybackCounts)
    wall_s: float = 0.0
    interrupted: bool = False
    compute_ms: list[float] = field(default_factory=list)
    buffering_compute_ms: list[float] = field(default_factory=list)

    def summary(self) -> dict:
        c = self.counts
        compute = np.array(self.compute_ms) if self.compute_ms else np.zeros(1)
        return {
            "frames_sent": c.sent,
            "answered": c.answered,
            "program_frames": c.program,
            "cuts": c.cuts,
            "late_frames": c.late,
            "laps": c.laps,
            "wall_s": round(self.wall_s, 2),
            "compute_ms": {
                "median": round(float(np.median(compute)), 3),
                "p99": round(float(np.percentile(compute, 99)), 3),
                "max": round(float(compute.max()), 3),
            },
            "interrupted": self.interrupted,
        }


def lap_feeds(match: MatchRecording, rate_hz: float, delay_s: float, loop: bool) -> Iterator[Feed]:
    """The feeds of the laps: the match once with the delay's tail; with `loop` the match without
    the tail, over and over, each lap's frames and times after the last's (module docstring)."""
    if not loop:
        yield Feed.of(match, rate_hz, delay_s)
        return
    once = Feed.of(match, rate_hz, 0.0)  # the rows, then one step more: where the next lap begins
    span_frames = int(once.frames[-1] - once.frames[0])
    span_s = float(once.times_s[-1] - once.times_s[0])
    for lap in itertools.count():
        yield Feed(once.rows[:-1], once.frames[:-1] + lap * span_frames, once.times_s[:-1] + lap * span_s)


def paced_updates(
    session: cd.Session,
    match: MatchRecording,
    feeds: Iterable[Feed],
    speed: float,
    clock: Callable[[], float],
    stop: threading.Event,
    counts: PlaybackCounts,
) -> Iterator[cd.pb.FrameUpdate]:
    """The laps' FrameUpdates (every player, with the events), each yielded once due on `clock`
    (monotonic wall seconds): at the first one's wall time plus its game time since the first's,
    divided by `speed`. Ends early once `stop` is set."""
    columns = list(range(len(match.players)))
    first = None  # (wall s, game s) of the first frame
    for feed in feeds:
        counts.laps += 1
        period_s = 1.0 / (feed.rate_hz * speed)
        for update in frame_updates(session, match, feed, columns, events=True):
            if first is None:
                first = (clock(), update.time_s)
            due_s = first[0] + (update.time_s - first[1]) / speed
            if stop.wait(max(0.0, due_s - clock())):
                return
            if clock() - due_s > period_s:
                counts.late += 1
            counts.sent += 1
            yield update


def cut_line(reply: cd.pb.CameraUpdate, names: dict[str, str]) -> dict:
    """A cut as one JSON-ready object: the program moment (frame, time_s, s) and its new shot, its
    subjects by id and by name (names: id -> the player's name; the id where it has none)."""
    shot = reply.shot
    return {
        "frame": reply.frame,
        "time_s": round(reply.time_s, 3),
        "shot_id": reply.shot_id,
        "subjects": list(shot.subject_ids),
        "subject_names": [names.get(pid) or pid for pid in shot.subject_ids],
        "kind": cd.pb.ShotKind.Name(shot.kind).removeprefix("SHOT_"),
        "reason": shot.reason,
        "held": shot.held,
    }


def play_match(
    client: cd.Client,
    match: MatchRecording,
    *,
    director: str,
    delay_s: float,
    rate_hz: float = 30.0,
    speed: float = 1.0,
    loop: bool = False,
    seed: int = 0,
    clock: Callable[[], float] = time.monotonic,
    on_session: Callable[[str], None] = lambda session_id: None,
    on_cut: Callable[[dict], None] = lambda line: None,
    stop: threading.Event | None = None,
) -> PlaybackResult:
    """Plays the match into a new RIG_MATCH session of `director` (a registered name) with the
    broadcast delay delay_s, s (module docstring), then closes the session. `on_session` hears the
    session id as soon as it is open, `on_cut` each cut (cut_line). `stop`, once set (by another
    thread or a signal handler, as play-match's Ctrl-C), ends the updates: the server answers
    those sent, the stream ends and the session is closed; the result says it was interrupted. A
    KeyboardInterrupt while streaming does the same, less cleanly (raised inside grpc's calls, it
    can leave its channel unable to close: grpc/grpc#19973). DirectorError: the server refused
    the session or the stream failed."""
    result = PlaybackResult()
    names = {p.id: p.name for p in match.players}
    stop = threading.Event() if stop is None else stop
    start_s = clock()
    with client.create_session(**match_session_fields(match, director, delay_s, seed)) as session:
        on_session(session.id)
        updates = paced_updates(session, match, lap_feeds(match, rate_hz, delay_s, loop), speed, clock, stop, result.counts)
        replies = session.stream(updates)
        try:
            for reply in replies:
                result.counts.answered += 1
                if reply.buffering and not reply.stale:
                    result.buffering_compute_ms.append(reply.compute_ms)
                if reply.buffering or reply.stale:
                    continue
                result.counts.program += 1
                result.compute_ms.append(reply.compute_ms)
                if reply.cut:
                    result.counts.cuts += 1
                    on_cut(cut_line(reply, names))
            result.interrupted = stop.is_set()
        except KeyboardInterrupt:
            result.interrupted = True
        finally:
            stop.set()  # the feeding thread may be waiting for a frame's due time
            replies.close()
    result.wall_s = clock() - start_s
    return result
