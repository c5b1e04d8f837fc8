"""MomentBuffer: who is alive, and which moment the program shows under a delay."""
from __future__ import annotations

import numpy as np
import pytest

from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.match.moments import MomentBuffer
from camdirector.pipeline.match.settings import MatchSettings
from tests.pipeline.match.scenes import kill

RATE_HZ = 60.0


def feed(buffer: MomentBuffer, path_b, kill_at_frame: int = 10, frames: int = 120) -> list[bool]:
    """Player "a" stands still at the origin and kills "b" at kill_at_frame; b's feet follow
    path_b(frame) -> (x, y, z). Returns b's alive flag per frame."""
    flags = []
    for f in range(frames):
        t = f / RATE_HZ
        poses = [RigidTransform(np.zeros(3), np.array([0, 0, 0, 1.0])),
                 RigidTransform(np.asarray(path_b(f), dtype=np.float64), np.array([0, 0, 0, 1.0]))]
        events = [kill("a", "b", t)] if f == kill_at_frame else []
        assert buffer.push(f, t, poses, [p.position_world for p in poses], events)
        flags.append(bool(buffer.newest.alive[1]))
    return flags


def test_a_respawn_two_metres_from_where_the_player_fell_is_seen():
    # the eval's arena had spawns 1.9 m and 2.3 m from a death: a 3 m jump threshold kept them dead
    flags = feed(MomentBuffer(["a", "b"], MatchSettings()), lambda f: (5.0, 0, 0) if f < 60 else (6.9, 0, 0))
    assert flags[:10] == [True] * 10 and not any(flags[10:60]) and all(flags[60:])


def test_a_body_that_falls_or_slides_stays_dead():
    # falling 20 m under gravity after the kill (up to 20 m/s), then sliding 3 m at 2 m/s
    def path(f):
        t = max(f - 10, 0) / RATE_HZ
        drop = min(0.5 * 9.81 * t * t, 20.0)
        slide = min(max(f - 80, 0) / RATE_HZ * 2.0, 3.0)
        return (5.0 + slide, -drop, 0.0)
    flags = feed(MomentBuffer(["a", "b"], MatchSettings()), path, frames=240)
    assert not any(flags[10:])


def test_a_player_respawned_where_it_fell_is_alive_once_it_walks_away():
    settings = MatchSettings()
    walk_m_s = 5.0
    flags = feed(MomentBuffer(["a", "b"], settings),
                 lambda f: (5.0 + max(f - 60, 0) / RATE_HZ * walk_m_s, 0, 0), frames=180)
    first_alive = flags.index(True, 10)
    walked_m = (first_alive - 60) / RATE_HZ * walk_m_s
    assert walked_m == pytest.approx(settings.respawn_walk_m, abs=walk_m_s / RATE_HZ)


def test_respawn_settings_are_validated():
    for name in ("respawn_speed_m_s", "respawn_min_jump_m", "respawn_walk_m"):
        with pytest.raises(ValueError, match=name):
            MatchSettings(**{name: 0.0})


@pytest.mark.parametrize("rate_hz, delay_s", [(60.0, 10.0), (30.0, 30.0), (64.0, 2.5)])
def test_the_program_shows_each_moment_once_delay_seconds_late(rate_hz, delay_s):
    # t - D in floating point lands a hair before the frame it names about half the time
    buffer = MomentBuffer(["a"], MatchSettings())
    lag = round(delay_s * rate_hz)
    shown = []
    for f in range(lag + 2000):
        pose = RigidTransform(np.zeros(3), np.array([0, 0, 0, 1.0]))
        buffer.push(f, f / rate_hz, [pose], [pose.position_world], [])
        moment = buffer.program_moment(f / rate_hz - delay_s)
        shown.append(None if moment is None else moment.frame)
    assert shown[:lag] == [None] * lag
    assert shown[lag:] == list(range(2000))
