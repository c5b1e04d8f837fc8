"""shots.py's pair window of a planned DUEL: when it frames the pair, and the swing of its second
framed point between the victim and the killer's gaze-room point."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from camdirector.pipeline.match.shots import PairWindow, Place, swung_point

WINDOW = PairWindow(keep_index=0, times_s=(10.0, 14.0), before_s=0.5, after_s=0.25, ramp_s=0.5)


def test_the_pair_is_framed_around_each_event_and_eased_in_and_out():
    assert WINDOW.weight(10.0) == 1.0 and WINDOW.weight(9.5) == 1.0 and WINDOW.weight(10.25) == 1.0
    assert math.isclose(WINDOW.weight(9.25), 0.5) and math.isclose(WINDOW.weight(10.5), 0.5)
    assert WINDOW.weight(9.0) == 0.0 and WINDOW.weight(10.75) == 0.0 and WINDOW.weight(12.0) == 0.0
    assert WINDOW.weight(13.5) == 1.0  # the second event's window


@given(st.floats(0.0, 30.0))
def test_the_weight_is_in_0_1_and_1_only_within_a_window(time_s):
    weight = WINDOW.weight(time_s)
    assert 0.0 <= weight <= 1.0
    inside = any(t - WINDOW.before_s <= time_s <= t + WINDOW.after_s for t in WINDOW.times_s)
    assert (weight == 1.0) == inside


vectors = st.tuples(*[st.floats(-30.0, 30.0)] * 3).map(np.array).filter(lambda v: np.linalg.norm(v) > 0.1)


@given(vectors, vectors, st.floats(0.0, 1.0))
def test_the_swung_point_keeps_away_from_the_kept_player(from_offset, to_offset, weight):
    """It never comes nearer the origin than the nearer end (a straight blend would cross it,
    and the torus of the framing would collapse), nor farther than the farther."""
    origin = np.array([1.0, 2.0, 3.0])
    distance = np.linalg.norm(swung_point(origin, from_offset, to_offset, weight) - origin)
    lengths = sorted([np.linalg.norm(from_offset), np.linalg.norm(to_offset)])
    assert lengths[0] * (1 - 1e-9) <= distance <= lengths[1] * (1 + 1e-9)


@given(vectors, vectors)
def test_the_swung_point_starts_and_ends_at_its_ends(from_offset, to_offset):
    origin = np.zeros(3)
    # asin near the vertical loses ~1e-8 m: well under a millimetre
    assert np.allclose(swung_point(origin, from_offset, to_offset, 0.0), from_offset, atol=1e-6)
    assert np.allclose(swung_point(origin, from_offset, to_offset, 1.0), to_offset, atol=1e-6)


def test_a_split_camera_takes_the_pair_place_within_the_window_and_its_own_outside():
    from camdirector.geometry.camera import Lens
    from camdirector.pipeline.match.frame import ShotKind
    from camdirector.pipeline.match.shots import ToricCamera
    from camdirector.pipeline.style import Style

    own, pair = Place(0.1, 0.5, 1.0), Place(0.9, -0.5, 2.6)
    camera = ToricCamera(ShotKind.DUEL, 0, 1, Style(), Lens(), own)
    camera.pair = PairWindow(0, (10.0,), 0.5, 0.25, 0.5, place=pair)
    assert camera.place_at(10.0) == pair and camera.place_at(8.0) == own and camera.place_at(11.0) == own
    halfway = camera.place_at(9.25)
    assert math.isclose(halfway.theta_ratio, 0.5) and math.isclose(halfway.phi_rad, 0.0, abs_tol=1e-12)
    assert math.isclose(halfway.width, 1.8)
    assert camera.framed(8.0) == (0,) and camera.framed(10.0) is None
