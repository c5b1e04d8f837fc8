"""The match program's measures (evaluation/match/measure.py) on tiny hand-built matches: a camera
that sees both duelists covers the kill, a wall between does not; jump cuts either side of 30 deg."""
from __future__ import annotations

import numpy as np
import pytest

from camdirector.evaluation.match.match_file import MatchEvent, MatchPlayer, MatchRecording
from camdirector.evaluation.match.measure import (
    BodySampler,
    Program,
    cuts_per_minute,
    framed_visibility,
    jump_cuts,
    kill_coverage,
    measure_shown,
    shot_lengths_s,
)
from camdirector.geometry.camera import Lens, level_look_rotation
from camdirector.geometry.raycast import RayScene
from tests.precompute.tracks.tiny_levels import boxes

RATE_HZ = 10.0
FRAMES = 40
CHEST = np.array([0.0, 1.08, 0.0])  # 0.6 of 1.8 m


def duel(kill_s: float = 2.0) -> MatchRecording:
    """Two players 4 m apart on x facing each other for 4 s; a kills b at kill_s."""
    players = [MatchPlayer("a", 0, 1.8, 0.3), MatchPlayer("b", 1, 1.8, 0.3)]
    time_s = np.arange(FRAMES) / RATE_HZ
    positions = np.broadcast_to(np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]]), (FRAMES, 2, 3)).copy()
    half = np.sqrt(0.5)
    rotations = np.broadcast_to(np.array([[0.0, half, 0.0, half], [0.0, -half, 0.0, half]]), (FRAMES, 2, 4)).copy()
    alive = np.ones((FRAMES, 2), dtype=bool)
    alive[time_s >= kill_s, 1] = False
    kill = MatchEvent("kill", "a", "b", 0, kill_s, "", positions[0, 1])
    return MatchRecording("tiny", 0, RATE_HZ, players, time_s, positions, rotations, alive, [kill])


def program_of(match: MatchRecording, cameras_world: np.ndarray, look_world: np.ndarray, cut_rows=(0,),
               subjects=("a", "b")) -> Program:
    """Every match frame a program moment; cameras (n, 3) looking at look (n, 3); cuts on cut_rows."""
    n = len(match.time_s)
    lens = Lens()
    rotation = np.array([level_look_rotation(c, p, (0.0, 0.0), lens) for c, p in zip(cameras_world, look_world)])
    cut = np.zeros(n, dtype=bool)
    cut[list(cut_rows)] = True
    return Program(index=np.arange(n), time_s=match.time_s.copy(), position=np.asarray(cameras_world, dtype=float),
                   rotation=rotation, vertical_fov_deg=np.full(n, lens.vertical_fov_deg), cut=cut,
                   shot_id=np.cumsum(cut), subjects=[tuple(subjects)] * n)


def floor(*walls) -> RayScene:
    return RayScene([boxes(((-20, -0.2, -20), (20, 0, 20)), *walls)])


@pytest.fixture
def match() -> MatchRecording:
    return duel()


def side_view(match: MatchRecording, distance_m: float = 8.0) -> Program:
    """From the side of the duel (on -z), looking at its middle, one shot."""
    n = len(match.time_s)
    return program_of(match, np.tile([2.0, 1.5, -distance_m], (n, 1)), np.tile([2.0, 1.0, 0.0], (n, 1)))


def test_a_camera_seeing_both_covers_the_kill_and_leads_by_the_whole_shot(match):
    program = side_view(match)
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor())
    assert shown.shape == (FRAMES, 2) and shown.min() >= 0.5
    result = kill_coverage(match, program, shown)
    assert result.kills == 1 and result.covered.tolist() == [True] and result.coverage == 1.0
    np.testing.assert_allclose(result.lead_s, [2.0])  # the shot began at 0 s, the kill is at 2 s
    assert framed_visibility(program, shown, match.player_index()) >= 0.5


def test_a_wall_between_camera_and_victim_uncovers_the_kill(match):
    program = side_view(match)
    wall = ((3.0, 0.0, -3.0), (5.0, 3.0, -2.8))  # between the camera and b only
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor(wall))
    assert shown[:, 0].min() >= 0.5 and shown[:, 1].max() < 0.5
    result = kill_coverage(match, program, shown)
    assert result.covered.tolist() == [False] and len(result.lead_s) == 0


def test_a_camera_looking_away_or_a_cut_just_before_shortens_the_lead(match):
    n = len(match.time_s)
    look = np.tile([2.0, 1.0, 0.0], (n, 1))
    look[:5] = [2.0, 1.0, -20.0]  # the first 0.5 s away from the duel
    program = program_of(match, np.tile([2.0, 1.5, -8.0], (n, 1)), look, cut_rows=(0, 15))
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor())
    assert shown[:5].max() == 0.0
    np.testing.assert_allclose(kill_coverage(match, program, shown).lead_s, [0.5])  # cut at 1.5 s, kill at 2 s


def _two_views(match: MatchRecording, apart_deg: float) -> Program:
    """One shot then a cut at 1 s to a view of the same duel apart_deg around its middle, same distance."""
    n = len(match.time_s)
    middle = np.array([2.0, 0.0, 0.0]) + CHEST
    angle = np.radians([-90.0, -90.0 + apart_deg])
    views = middle + 8.0 * np.stack([np.cos(angle), np.zeros(2), np.sin(angle)], axis=1)
    cameras = np.where((np.arange(n) < 10)[:, None], views[0], views[1])
    return program_of(match, cameras, np.tile(middle, (n, 1)), cut_rows=(0, 10))


@pytest.mark.parametrize("apart_deg, jump", [(10.0, 1), (28.0, 1), (32.0, 0), (90.0, 0)])
def test_a_cut_to_the_same_subjects_under_30_deg_is_a_jump_cut(match, apart_deg, jump):
    bodies = BodySampler(match, np.random.default_rng(0))
    assert jump_cuts(_two_views(match, apart_deg), bodies) == jump


def test_a_cut_to_other_subjects_is_no_jump_cut_however_close(match):
    program = _two_views(match, 5.0)
    program.subjects = [("a", "b")] * 10 + [("a",)] * (len(program) - 10)
    assert jump_cuts(program, BodySampler(match, np.random.default_rng(0))) == 0


def test_shot_lengths_leave_out_the_last_shot_and_cuts_are_counted_per_minute(match):
    program = _two_views(match, 90.0)
    program.cut[25] = True
    np.testing.assert_allclose(shot_lengths_s(program), [1.0, 1.5])
    assert cuts_per_minute(program) == pytest.approx(60.0 * 2 / 3.9)


def test_samples_are_on_each_body_and_move_with_it(match):
    bodies = BodySampler(match, np.random.default_rng(0))
    points = bodies.points_world(0)
    assert points.shape == (2, 32, 3)
    horizontal = np.linalg.norm(points[:, :, [0, 2]] - match.positions_world[0][:, None, [0, 2]], axis=2)
    assert horizontal.max() <= 0.3 + 1e-6 and points[..., 1].min() >= -1e-6 and points[..., 1].max() <= 1.8 + 1e-6
    np.testing.assert_allclose(bodies.aims_world(0, [1]), [match.positions_world[0, 1] + CHEST])
