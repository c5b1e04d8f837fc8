"""bridges/stream_clock.py: the stream's clock onto the local one. A late or bunched arrival
leaves the mapping where the earliest arrivals put it; a lasting rise of the latency moves it no
faster than the slew; a source faster than real time is followed at its pace; a pause, a skip
ahead or a new stream re-anchors it."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.bridges.stream_clock import StreamClock, StreamClockSettings

STEP_S = 0.013  # a server frame (mvdsv's 77 Hz)


def _steady(clock: StreamClock, source_s: np.ndarray, delay_s: float) -> None:
    for s in source_s:
        clock.arrive(float(s), float(s) + delay_s)


def test_late_and_bunched_arrivals_leave_the_mapping_on_the_earliest():
    clock = StreamClock(StreamClockSettings())
    _steady(clock, np.arange(0.0, 2.0, STEP_S), delay_s=5.0)
    due = [clock.local_of(0.0)]
    for s in np.arange(2.0, 2.1, STEP_S):  # a stall, then 0.1 s of frames at once
        clock.arrive(float(s), 2.1 + 5.0 + 0.02)
    due.append(clock.local_of(0.0))
    for s in np.arange(2.1, 3.0, STEP_S):  # late by up to 0.4 s, no two alike
        clock.arrive(float(s), float(s) + 5.0 + 0.4 * abs(np.sin(50 * s)))
    due.append(clock.local_of(0.0))
    assert due == pytest.approx([5.0, 5.0, 5.0], abs=1e-9)
    assert clock.anchors == 1


def test_a_lasting_latency_moves_the_mapping_no_faster_than_the_slew():
    settings = StreamClockSettings(window_s=1.0, slew=0.05)
    clock = StreamClock(settings)
    _steady(clock, np.arange(0.0, 3.0, STEP_S), delay_s=1.0)
    offsets = []
    for s in np.arange(3.0, 15.0, STEP_S):
        clock.arrive(float(s), float(s) + 1.3)
        offsets.append(clock.local_of(0.0))
    rates = np.diff(offsets) / STEP_S
    assert rates.min() >= -1e-9 and rates.max() <= settings.slew + 1e-9
    # the earlier arrivals leave the window 0.7 s in (it is 1 s of the local clock, 0.3 s more delay)
    assert offsets[int(0.65 / STEP_S)] == pytest.approx(1.0)
    assert offsets[int(0.75 / STEP_S)] > 1.0
    assert offsets[-1] == pytest.approx(1.3)
    assert clock.anchors == 1


def test_a_source_faster_than_real_time_is_followed_at_its_pace():
    clock = StreamClock(StreamClockSettings())
    for s in np.arange(0.0, 8.0, STEP_S):  # four times real time, as a source catching up sends
        clock.arrive(float(s), 10.0 + float(s) / 4.0)
        assert clock.local_of(float(s)) == pytest.approx(10.0 + float(s) / 4.0)
    assert clock.anchors == 1


def test_a_pause_a_skip_and_a_new_stream_re_anchor():
    clock = StreamClock(StreamClockSettings(reanchor_s=1.0))
    _steady(clock, np.arange(0.0, 2.0, STEP_S), delay_s=1.0)
    clock.arrive(2.0, 6.0)  # the source paused 3 s: its time went on from where it stopped
    assert clock.local_of(2.0) == pytest.approx(6.0) and clock.anchors == 2
    clock.arrive(20.0, 6.1)  # a catch-up burst brought the present
    assert clock.local_of(20.0) == pytest.approx(6.1) and clock.anchors == 3
    clock.reanchor()  # a new connection: its time starts anew, here near enough the old mapping's
    clock.arrive(20.2, 6.4)
    assert clock.local_of(20.2) == pytest.approx(6.4) and clock.anchors == 4


def test_settings_are_checked():
    with pytest.raises(ValueError, match="slew must be in"):
        StreamClockSettings(slew=2.0)
