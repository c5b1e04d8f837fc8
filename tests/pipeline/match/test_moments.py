"""MomentBuffer: who is alive, and which moment the program shows under a delay."""

from __future__ import annotations

import pickle
from dataclasses import dataclass

import numpy as np
import pytest

from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.match.moments import COMPACT_AFTER, Moment, MomentBuffer, _moment_of_bytes, _unpacked_moment
from camdirector.pipeline.match.settings import MatchSettings
from tests.pipeline.match.scenes import kill

RATE_HZ = 60.0


def feed(buffer: MomentBuffer, path_b, kill_at_frame: int = 10, frames: int = 120) -> list[bool]:
    """Player "a" stands still at the origin and kills "b" at kill_at_frame; b's feet follow
    path_b(frame) -> (x, y, z). Returns b's alive flag per frame."""
    flags = []
    for f in range(frames):
        t = f / RATE_HZ
        poses = [
            RigidTransform(np.zeros(3), np.array([0, 0, 0, 1.0])),
            RigidTransform(np.asarray(path_b(f), dtype=np.float64), np.array([0, 0, 0, 1.0])),
        ]
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
    flags = feed(MomentBuffer(["a", "b"], settings), lambda f: (5.0 + max(f - 60, 0) / RATE_HZ * walk_m_s, 0, 0), frames=180)
    first_alive = flags.index(True, 10)
    walked_m = (first_alive - 60) / RATE_HZ * walk_m_s
    assert walked_m == pytest.approx(settings.respawn_walk_m, abs=walk_m_s / RATE_HZ)


@pytest.mark.parametrize("attacker, killer", [("a", 0), ("b", -1), ("world", -1)])
def test_a_dead_players_killer_is_known_until_it_respawns(attacker, killer):
    """Moment.killers: the attacker of a dead player's last KILL (-1 for a suicide or the world's),
    from the kill's moment until the respawn; -1 for the living."""
    buffer = MomentBuffer(["a", "b"], MatchSettings())
    killers = []
    for f in range(120):
        poses = [
            RigidTransform(np.zeros(3), np.array([0, 0, 0, 1.0])),
            RigidTransform(np.array([5.0 if f < 60 else 30.0, 0.0, 0.0]), np.array([0, 0, 0, 1.0])),  # respawned at 60
        ]
        buffer.push(
            f, f / RATE_HZ, poses, [p.position_world for p in poses], [kill(attacker, "b", f / RATE_HZ)] if f == 10 else []
        )
        killers.append(buffer.newest.killers.tolist())
    assert killers[:10] == [[-1, -1]] * 10 and killers[10:60] == [[-1, killer]] * 50 and killers[60:] == [[-1, -1]] * 60


def test_jumps_are_the_moments_a_player_teleports_or_respawns_not_those_it_runs_or_falls():
    # b runs at 10 m/s, teleports 20 m at frame 40, falls (up to 20 m/s) from frame 70; a stands still
    def path(f):
        run = min(f, 40) / RATE_HZ * 10.0
        drop = 0.5 * 9.81 * (max(f - 70, 0) / RATE_HZ) ** 2
        return (run + (20.0 if f >= 40 else 0.0), -min(drop, 20.0), 0.0)

    buffer = MomentBuffer(["a", "b"], MatchSettings())
    feed(buffer, path, kill_at_frame=1000)
    assert buffer.jumps_s([1], 0.0, 2.0) == [40 / RATE_HZ]
    assert buffer.jumps_s([0, 1], 0.0, 2.0) == [40 / RATE_HZ]
    assert buffer.jumps_s([0], 0.0, 2.0) == []
    assert buffer.jumps_s([1], 40 / RATE_HZ, 2.0) == []  # (start, end]: the jump's own moment is at start
    assert buffer.jumps_s([1], 0.0, 39.5 / RATE_HZ) == []
    # with the level: only a jump with a wall between its two aim points (a jump pad's has none)
    assert buffer.jumps_s([1], 0.0, 2.0, crosses=lambda a, b: np.ones(len(a), dtype=bool)) == [40 / RATE_HZ]
    assert buffer.jumps_s([1], 0.0, 2.0, crosses=lambda a, b: np.zeros(len(a), dtype=bool)) == []


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


def test_the_buffer_holds_the_delay_and_little_more_and_a_moment_pickles_back_exactly():
    """Moments more than kept_past_s before the program's are dropped within COMPACT_AFTER frames
    (a session's snapshot pickles the buffer: kept up to 4096 of them, a snapshot of the 4on4 grew
    to 9 MB), those within it are kept for replays; a moment pickled (its floats as bytes,
    packed once: Moment.__reduce__) comes back bit for bit, float64, also from a snapshot of the
    format before."""
    rng = np.random.default_rng(5)
    settings = MatchSettings()
    buffer = MomentBuffer(["a", "b"], settings)
    rate_hz, delay_s = 30.0, 2.0
    held = []
    for f in range(3000):
        poses = [RigidTransform(rng.normal(size=3), rng.normal(size=4), rng.uniform(0.5, 2.0, 3)) for _ in range(2)]
        events = [kill("a", "b", f / rate_hz)] if f == 2990 else []
        buffer.push(f, f / rate_hz, poses, [p.position_world + 1.0 for p in poses], events)
        buffer.program_moment(f / rate_hz - delay_s)
        held.append(len(buffer.moments))
    assert COMPACT_AFTER <= 64 and max(held) <= (delay_s + settings.kept_past_s) * rate_hz + 1 + COMPACT_AFTER + 1
    program_s = buffer.program_moment((2999 / rate_hz) - delay_s).time_s
    assert buffer.oldest_s <= program_s - settings.kept_past_s  # the past a replay shows is kept
    assert buffer.at(program_s - settings.kept_past_s).time_s <= program_s - settings.kept_past_s + 1e-9
    for moment in (buffer.newest, buffer.at(2990 / rate_hz)):
        data = pickle.dumps(moment)
        back = pickle.loads(data)
        _same_moment(back, moment)
        # packed once: pickled again, and its copy pickled, the same bytes; the copy's arrays its own
        assert pickle.dumps(moment) == data and pickle.dumps(back) == data
        back.feet_world[0, 0] += 1.0
        back.transforms[0].position_world[0] += 1.0
        assert not np.array_equal(back.feet_world, moment.feet_world)
        assert not np.array_equal(back.transforms[0].position_world, moment.transforms[0].position_world)
        # a snapshot written before 2026-12-02 (each moment as three arrays) restores the same moment, and one
        # written before 2026-12-06 (no killers) too: with no killer known
        _same_moment(pickle.loads(pickle.dumps(_ThreeArrays(moment))), moment, killers=False)
        _same_moment(_moment_of_bytes(*moment.__reduce__()[1][:6]), moment, killers=False)
    assert buffer.at(2990 / rate_hz).events  # the kill's moment, with its event, came back above


@dataclass
class _ThreeArrays:
    """A moment as snapshots pickled it before 2026-12-02: transforms (n, 10), points (3, n, 3), alive."""

    moment: Moment

    def __reduce__(self):
        m = self.moment
        rows = np.array([np.concatenate([t.position_world, t.rotation_xyzw, t.scale]) for t in m.transforms])
        points = np.stack([m.aims_world, m.feet_world, m.forward_world])
        return _unpacked_moment, (m.frame, m.time_s, rows, points, m.alive, m.events)


def _same_moment(back: Moment, moment: Moment, killers: bool = True) -> None:
    """Bit for bit, float64 (and the alive flags, and the killers: none known where not `killers`)."""
    assert (back.frame, back.time_s, back.events) == (moment.frame, moment.time_s, moment.events)
    if killers:
        assert moment.killers is not None and back.killers is not None
        assert back.killers.dtype == np.int64 and np.array_equal(back.killers, moment.killers)
    else:
        assert back.killers is None
    for name in ("aims_world", "feet_world", "forward_world", "alive"):
        a, b = getattr(moment, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b)
    for t, u in zip(moment.transforms, back.transforms, strict=True):
        for name in ("position_world", "rotation_xyzw", "scale"):
            assert getattr(u, name).dtype == np.float64 and np.array_equal(getattr(t, name), getattr(u, name))


def test_the_moment_at_or_after_a_time_is_the_first_buffered_there_clamped_to_the_buffer():
    """`at_or_after` is the program moment eval-match judges an event at (its first at or after
    it); `at`, the one at or before it."""
    buffer = MomentBuffer(["a", "b"], MatchSettings())
    feed(buffer, lambda f: (0.0, 0.0, 5.0), frames=4)
    times = buffer.times
    assert buffer.at_or_after(0.01).time_s == times[1] and buffer.at(0.01).time_s == times[0]
    assert buffer.at_or_after(times[2]).time_s == times[2] == buffer.at(times[2]).time_s
    assert buffer.at_or_after(times[2] - 1e-12).time_s == times[2]  # within TIME_EPSILON_S: that moment
    assert buffer.at_or_after(-1.0).time_s == times[0] and buffer.at_or_after(5.0).time_s == times[-1]
