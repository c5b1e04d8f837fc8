"""The match program's measures (evaluation/match/measure.py) on tiny hand-built matches: a camera
that sees both duelists covers the kill, a wall between does not; jump cuts either side of 30 deg."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from camdirector.evaluation.match.match_file import MatchEvent, MatchPlayer, MatchRecording
from camdirector.evaluation.match.measure import (
    EYE_HEIGHT_FRACTION,
    BodySampler,
    Program,
    cuts_per_minute,
    framed_visibility,
    in_eyes_of,
    jump_cuts,
    kill_coverage,
    measure_shown,
    program_visibility,
    shot_lengths_s,
    shown_heights,
    shown_heights_per_moment,
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


def program_of(
    match: MatchRecording, cameras_world: np.ndarray, look_world: np.ndarray, cut_rows=(0,), subjects=("a", "b")
) -> Program:
    """Every match frame a program moment; cameras (n, 3) looking at look (n, 3); cuts on cut_rows."""
    n = len(match.time_s)
    lens = Lens()
    rotation = np.array([level_look_rotation(c, p, (0.0, 0.0), lens) for c, p in zip(cameras_world, look_world)])
    cut = np.zeros(n, dtype=bool)
    cut[list(cut_rows)] = True
    return Program(
        index=np.arange(n),
        time_s=match.time_s.copy(),
        position=np.asarray(cameras_world, dtype=float),
        rotation=rotation,
        vertical_fov_deg=np.full(n, lens.vertical_fov_deg),
        cut=cut,
        shot_id=np.cumsum(cut),
        subjects=[tuple(subjects)] * n,
        overview=np.zeros(n, dtype=bool),
        shown_index=np.arange(n),
        replay=np.zeros(n, dtype=bool),
    )


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
    assert framed_visibility(program, shown, match.player_index(), in_eyes_of(match, program)) >= 0.5


def test_a_casts_moment_stands_its_bodies_on_the_feet_it_carried(match):
    """Program.feet_world: b carried 30 m aside (out of the frame) on the first moment, b's own
    (NaN) on the others; b's shown share and on-screen height follow."""
    program = side_view(match)
    bodies = BodySampler(match, np.random.default_rng(0))
    before = measure_shown(program, bodies, Lens(), floor())
    feet = np.full((FRAMES, 2, 3), np.nan)
    feet[0, 1] = match.positions_world[0, 1] + [30.0, 0.0, 0.0]
    program.feet_world = feet
    after = measure_shown(program, bodies, Lens(), floor())
    assert before[0, 1] >= 0.5 and after[0, 1] == 0.0
    np.testing.assert_array_equal(after[1:], before[1:])
    np.testing.assert_array_equal(after[:, 0], before[:, 0])
    heights = shown_heights_per_moment(program, bodies, Lens(), after, in_eyes_of(match, program))
    assert len(heights[0]) == 1 and len(heights[1]) == 2  # only a on the first moment


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


def first_person_of_a(match: MatchRecording) -> Program:
    """In a's eyes (feet + EYE_HEIGHT_FRACTION of its height) looking at b, naming a as the subject."""
    n = len(match.time_s)
    eye = match.positions_world[0, 0] + [0.0, EYE_HEIGHT_FRACTION * 1.8, 0.0]
    return program_of(match, np.tile(eye, (n, 1)), np.tile(match.positions_world[0, 1] + CHEST, (n, 1)), subjects=("a",))


def test_the_attackers_eyes_seeing_the_victim_cover_the_kill_first_person_only(match):
    program = first_person_of_a(match)
    bodies = BodySampler(match, np.random.default_rng(0))
    shown = measure_shown(program, bodies, Lens(), floor())
    eyes = in_eyes_of(match, program)
    assert eyes.tolist() == [0] * FRAMES and shown[:, 1].min() >= 0.5
    assert kill_coverage(match, program, shown).covered.tolist() == [False]  # a's body is not in the picture
    assert kill_coverage(match, program, shown, eyes).covered.tolist() == [True]
    assert framed_visibility(program, shown, match.player_index(), eyes) == 1.0  # it names a: a's view, not a's body
    # In the victim's eyes instead, the attacker's eyes rule does not apply.
    swapped = duel()
    swapped.events[0] = dataclasses.replace(swapped.events[0], actor_id="b", other_actor_id="a")
    assert kill_coverage(swapped, program, shown, eyes).covered.tolist() == [False]


def test_a_camera_half_a_metre_off_the_eye_is_in_nobodys_eyes(match):
    program = first_person_of_a(match)
    program.position = program.position + [0.0, 0.0, 0.51]
    assert in_eyes_of(match, program).tolist() == [-1] * FRAMES


def test_the_feet_the_program_carries_tell_whose_eyes_the_camera_is_in(match):
    """A cast's moment through a's eyes where a stood a metre from the match file's row (a teleport
    sampled half a row apart): in a's eyes by the feet its director saw, and the match file's where
    it carried none (NaN)."""
    program = first_person_of_a(match)
    program.position = program.position + [1.0, 0.0, 0.0]
    assert in_eyes_of(match, program).tolist() == [-1] * FRAMES
    feet = np.broadcast_to(match.positions_world[0], (FRAMES, 2, 3)).copy()
    feet[:, 0, 0] += 1.0
    program.feet_world = feet
    assert in_eyes_of(match, program).tolist() == [0] * FRAMES
    program.feet_world[1:, 0] = np.nan  # carried for the first moment only
    assert in_eyes_of(match, program).tolist() == [0] + [-1] * (FRAMES - 1)


def test_a_body_that_holds_the_camera_shows_none_of_itself(match):
    """A camera low in a's body (a corpse's eye) looking at b: a's surface about it faces away
    (a renderer culls it; no game draws the body whose eyes it shows), so a is not shown there;
    a little behind a's body, a's back is."""
    n = len(match.time_s)
    bodies = BodySampler(match, np.random.default_rng(0))
    shares = []
    for behind_m in (0.0, 0.45):  # a's radius is 0.3 m
        camera = match.positions_world[0, 0] + [-behind_m, 0.3, 0.0]
        program = program_of(match, np.tile(camera, (n, 1)), np.tile(match.positions_world[0, 1] + CHEST, (n, 1)))
        assert bodies.holding(0, camera).tolist() == [behind_m == 0.0, False]
        shares.append(measure_shown(program, bodies, Lens(), floor()))
    inside, behind = shares
    assert inside[:, 0].max() == 0.0 and behind[:, 0].min() > 0.0
    assert inside[:, 1].min() >= 0.5  # b is


def test_program_visibility_counts_every_moment_and_the_eyes_as_seen(match):
    program = side_view(match)
    program.subjects = [("a", "b")] * 20 + [()] * (FRAMES - 20)
    wall = ((3.0, 0.0, -3.0), (5.0, 3.0, -2.8))  # hides b only
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor(wall))
    no_eyes = np.full(FRAMES, -1)
    expected = np.concatenate([shown[:20].mean(axis=1), shown[20:].max(axis=1)]).mean()
    assert program_visibility(program, shown, match.player_index(), no_eyes) == pytest.approx(expected)
    eyes = np.full(FRAMES, 1)  # were the camera in b's eyes, b would count as seen
    assert program_visibility(program, shown, match.player_index(), eyes) > expected


def test_shown_height_is_the_bodys_share_of_the_frame_and_halves_at_twice_the_distance(match):
    bodies = BodySampler(match, np.random.default_rng(0))
    heights = []
    for distance_m in (8.0, 16.0):
        program = side_view(match, distance_m)
        shown = measure_shown(program, bodies, Lens(), floor())
        h = shown_heights(program, bodies, Lens(), shown, np.full(FRAMES, -1))
        assert len(h) == 2 * FRAMES
        heights.append(float(np.median(h)))
    # 1.8 m at about 8 m with a 50 deg vertical field: 1.8 / (2 * 8 * tan 25 deg) = 0.24 of the frame
    assert heights[0] == pytest.approx(1.8 / (2 * np.hypot(8.0, 2.0) * np.tan(np.radians(25.0))), rel=0.15)
    assert heights[1] == pytest.approx(heights[0] / 2.0, rel=0.15)
    # the player in whose eyes the camera is does not count
    program = first_person_of_a(match)
    shown = measure_shown(program, bodies, Lens(), floor())
    assert len(shown_heights(program, bodies, Lens(), shown, in_eyes_of(match, program))) == FRAMES  # b only


def test_the_program_digest_changes_with_one_pose(match):
    program = side_view(match)
    same = side_view(match)
    assert program.digest() == same.digest()
    same.position[7, 0] += 1e-9
    assert program.digest() != same.digest()


def test_the_subjects_height_counts_only_the_players_the_shot_names(match):
    bodies = BodySampler(match, np.random.default_rng(0))
    program = side_view(match)
    program.subjects = [("a",)] * FRAMES
    shown = measure_shown(program, bodies, Lens(), floor())
    every = shown_heights(program, bodies, Lens(), shown, np.full(FRAMES, -1))
    named = shown_heights(program, bodies, Lens(), shown, np.full(FRAMES, -1), subjects_only=True)
    assert len(every) == 2 * FRAMES and len(named) == FRAMES
    assert np.allclose(named, every[0::2])  # per moment a's height, then b's
