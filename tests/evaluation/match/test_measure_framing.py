"""Issue 41's framing measures (evaluation/match/measure.py): frames showing nobody inside and
outside overviews, the tallest shown player, and candidates showing half of their subjects, on
the tiny duel of test_measure.py."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.evaluation.match.measure import (
    TALL_HEIGHT,
    BodySampler,
    Offered,
    candidates_showing_subjects,
    in_eyes_of,
    measure_shown,
    nobody_shown,
    shown_heights_per_moment,
    tallest_shown,
    third_person_heights,
)
from camdirector.geometry.camera import Lens, level_look_rotation
from tests.evaluation.match.test_measure import duel, first_person_of_a, floor, program_of, side_view

B_ONLY_WALL = ((3.0, 0.0, -3.0), (5.0, 3.0, -2.8))  # between the side view's camera and b only


@pytest.fixture
def match():
    return duel()


def test_nobody_shown_is_split_by_overview(match):
    n = len(match.time_s)
    look = np.tile([2.0, 1.0, 0.0], (n, 1))
    look[:10] = [2.0, 1.0, -20.0]  # the first 10 moments look away from both players
    program = program_of(match, np.tile([2.0, 1.5, -8.0], (n, 1)), look)
    program.overview[:4] = True  # 4 of them in an overview, 6 in another shot
    program.overview[30:] = True  # an overview that shows players does not count
    shown = measure_shown(program, BodySampler(match, np.random.default_rng(0)), Lens(), floor())
    result = nobody_shown(program, shown, np.full(n, -1))
    assert result == {"overview": pytest.approx(4 / n), "other": pytest.approx(6 / n)}
    # in a player's eyes, the camera shows that player's view: not nobody
    assert nobody_shown(program, shown, np.zeros(n, dtype=np.int64)) == {"overview": 0.0, "other": 0.0}


def test_a_camera_close_to_a_player_is_over_the_tall_limit_and_one_far_is_not(match):
    bodies = BodySampler(match, np.random.default_rng(0))
    n = len(match.time_s)
    no_eyes = np.full(n, -1)
    far = side_view(match, 8.0)
    far_heights = shown_heights_per_moment(far, bodies, Lens(), measure_shown(far, bodies, Lens(), floor()), no_eyes)
    far_result = tallest_shown(far_heights, no_eyes)
    assert far_result["over_60pc"] == 0.0 and 0.15 < far_result["max"] < TALL_HEIGHT
    # 1.5 m from a's side, looking at its chest, for the second half of the program
    cameras = np.tile([2.0, 1.5, -8.0], (n, 1))
    look = np.tile([2.0, 1.0, 0.0], (n, 1))
    cameras[n // 2 :], look[n // 2 :] = [0.0, 1.0, -1.5], [0.0, 1.0, 0.0]
    near = program_of(match, cameras, look)
    heights = shown_heights_per_moment(near, bodies, Lens(), measure_shown(near, bodies, Lens(), floor()), no_eyes)
    result = tallest_shown(heights, no_eyes)
    assert result["over_60pc"] == pytest.approx(0.5) and result["max"] > TALL_HEIGHT


def test_first_person_moments_are_left_out_of_the_tallest(match):
    bodies = BodySampler(match, np.random.default_rng(0))
    program = first_person_of_a(match)
    eyes = in_eyes_of(match, program)
    heights = shown_heights_per_moment(program, bodies, Lens(), measure_shown(program, bodies, Lens(), floor()), eyes)
    assert all(len(h) == 1 for h in heights)  # b is shown at every moment
    assert tallest_shown(heights, eyes) == {"max": None, "over_60pc": None}
    # and out of the director's own framing's heights: half the moments in a's eyes, half not
    half = eyes.copy()
    half[::2] = -1
    kept = third_person_heights(heights, half)
    assert len(kept) == len(heights[::2]) and np.array_equal(kept, np.concatenate(heights[::2]))
    assert len(third_person_heights(heights, eyes)) == 0


def offered(match, views: list[tuple[list[float], list[float], tuple[str, ...]]]) -> Offered:
    """One candidate per view (camera, look point, subjects), all offered beside match frame 5."""
    lens = Lens()
    return Offered(
        index=np.full(len(views), 5, dtype=np.int64),
        position=np.array([c for c, _, _ in views], dtype=np.float64),
        rotation=np.array([level_look_rotation(np.array(c), np.array(p), (0.0, 0.0), lens) for c, p, _ in views]),
        vertical_fov_deg=np.full(len(views), lens.vertical_fov_deg),
        subjects=[s for _, _, s in views],
    )


def test_candidates_show_half_of_their_subjects_or_not(match):
    bodies = BodySampler(match, np.random.default_rng(0))
    side, middle, away = [2.0, 1.5, -8.0], [2.0, 1.0, 0.0], [2.0, 1.0, -20.0]
    views = [
        (side, middle, ("a", "b")),  # both shown
        (side, middle, ("b",)),  # b behind the wall: not shown
        (side, middle, ("a", "b")),  # a shown, b hidden: half of them
        (side, away, ("a",)),  # looking away
        (side, middle, ()),  # no subjects: not counted
    ]
    result = candidates_showing_subjects(offered(match, views), bodies, Lens(), floor(B_ONLY_WALL))
    assert result == {"offered": 4, "showing_half": 2}
    no_wall = candidates_showing_subjects(offered(match, views), bodies, Lens(), floor())
    assert no_wall == {"offered": 4, "showing_half": 3}
