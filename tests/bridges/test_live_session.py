"""bridges/live_session.py: the driver's progress goes on while the feed is stale (no frame is
sent then, so no reply comes to carry it), counting the stale ticks; frames lie on the tick grid;
none goes before the feed's first sample is due, and those ticks are not counted stale."""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager

import numpy as np
import pytest

import camdirector_client as cd
from camdirector.bridges.gsi_tracks import DerivedEvent, Sample
from camdirector.bridges.live_session import ONE_SIDED_PRIORITY, drive_session, event_msg
from camdirector.matches.quakeworld_mvd import quake_player
from camdirector.pipeline.inputs import EventKind
from camdirector.pipeline.match.settings import MatchSettings

FRESH_SAMPLES = 3  # the feed goes stale after this many samples


class _Tracks:
    """One player, not started for `waiting` samples, then fresh for `fresh` samples, then stale
    for good."""

    roster = [quake_player("p00", "runner", 0, "")]

    def __init__(self, waiting: int = 0, fresh: int = FRESH_SAMPLES):
        self.samples, self.fresh = -waiting, fresh

    def wait_roster(self, timeout_s: float) -> bool:
        return True

    def sample(self, now_s: float) -> Sample:
        self.samples += 1
        if self.samples <= 0:
            return Sample.not_started(False)
        stale = self.samples > self.fresh
        return Sample(["p00"], np.zeros((1, 3)), np.zeros(1), [], [], stale)


class _Session:
    """A session that answers each frame with an empty reply."""

    id = "s1"

    def frame_update(self, frame: int, time_s: float, *, packed) -> cd.pb.FrameUpdate:
        return cd.wire.frame_update(self.id, frame, time_s, packed=packed)

    def stream(self, updates):
        for update in updates:
            yield cd.pb.CameraUpdate(frame=update.frame)


class _Client:
    @contextmanager
    def create_session(self, **kwargs):
        yield _Session()


def _drive(tracks: _Tracks, stop: threading.Event, rate_hz: float, **kwargs):
    """drive_session of the tracks into the answering client until `stop` (or 20 s: a driver
    that never reports would hang the test); its counts."""
    guard = threading.Timer(20.0, stop.set)
    guard.start()
    try:
        return drive_session(
            _Client(), tracks, rate_hz=rate_hz, delay_s=1.0, level="any", director="planned", stop=stop, **kwargs
        )
    finally:
        guard.cancel()


def test_progress_goes_on_while_the_feed_is_stale():
    stop = threading.Event()
    seen: list[tuple[int, int]] = []  # (frames, stale ticks) at each progress

    def on_progress(counts) -> None:
        seen.append((counts.frames, counts.stale))
        if counts.stale >= 5:
            stop.set()

    counts = _drive(_Tracks(), stop, 100.0, on_progress=on_progress, progress_s=0.0)
    assert counts.frames == FRESH_SAMPLES
    assert seen[-1] == (FRESH_SAMPLES, 5)


def test_frames_lie_on_the_tick_grid_in_game_time_however_late_the_driver_wakes():
    stop = threading.Event()
    stalled_s = [0.0]  # added to the clock: the driver's thread "slept" that much more
    sent: list[float] = []

    def clock() -> float:
        return time.monotonic() + stalled_s[0]

    def on_frame(frame: int, game_s: float, sample) -> None:
        sent.append(game_s)
        if frame in (5, 9):
            stalled_s[0] += 0.123  # woke 3.69 periods late
        if frame == 20:
            stop.set()

    _drive(_Tracks(fresh=1000), stop, 30.0, clock=clock, on_frame=on_frame)
    ticks = np.array(sent) * 30.0
    assert ticks == pytest.approx(np.round(ticks), abs=1e-6)  # every frame on the 1/30 s grid
    assert np.all(np.diff(np.round(ticks)) >= 1)
    assert np.round(ticks).max() > len(sent)  # the ticks missed while stalled were skipped


def test_no_frame_goes_before_the_feeds_first_sample_is_due():
    stop = threading.Event()
    sent: list[float] = []

    def on_frame(frame: int, game_s: float, sample) -> None:
        sent.append(game_s)
        assert sample.started and sample.ids == ["p00"]

    def on_progress(counts) -> None:
        if counts.stale >= 2:
            stop.set()

    counts = _drive(_Tracks(waiting=4), stop, 30.0, on_frame=on_frame, on_progress=on_progress, progress_s=0.0)
    assert counts.frames == len(sent) == FRESH_SAMPLES
    assert counts.stale >= 2  # the stale ticks after the fresh ones, and only those
    assert sent[0] * 30.0 >= 4 - 1e-6  # the four ticks before it sent nothing


def test_a_kill_goes_at_its_kinds_priority_and_a_one_sided_death_rated_as_a_kill():
    """A kill of one player by another is a KILL at the kind's own priority (0); a death whose
    other side the feed left unsaid is a CUSTOM event rated as the director rates a kill, so that
    it gets a beat and no replay covers it."""
    at = np.zeros(3)
    kill = event_msg(DerivedEvent("kill", "p00", "p01", at))
    assert (kill.kind, kill.priority, kill.actor_id, kill.other_actor_id) == (cd.pb.EVENT_KILL, 0, "p00", "p01")
    for kind, label in (("death", "died"), ("kill_unknown", "kill, victim unknown")):
        event = event_msg(DerivedEvent(kind, "p02", "", at))
        assert (event.kind, event.priority, event.label) == (cd.pb.EVENT_CUSTOM, ONE_SIDED_PRIORITY, label)
    assert ONE_SIDED_PRIORITY == MatchSettings().priorities[EventKind.KILL] >= MatchSettings().beat_min_priority
