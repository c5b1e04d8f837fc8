"""camdirector._native.aggregate_amap (native/src/amap.rs, style_mask.rs), the compiled twin of
pipeline/toric/anticipation_map.py's `AnticipationMap.aggregate`, CompiledAnticipationMap's: over
drawn A_s on windows on one lattice (whole-texel shifts, the maps' usual case), off it (other
texel sizes, partly or not at all overlapping, phi past +-pi), slots without a map, every style
mask and torus angle, and resolutions 8 to 64, the same bits as the numpy code; bad input
refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector import _native as native
from camdirector.geometry.toric_maps import MapWindow
from camdirector.pipeline.style import MaskKind
from camdirector.pipeline.toric.anticipation_map import AnticipationMap
from camdirector.pipeline.toric.compiled_maps import CompiledAnticipationMap
from camdirector.pipeline.toric.style_masks import StyleMaskSettings


@st.composite
def aggregate_cases(draw):
    """(windows, a_s, newest, mask, alpha_rad): 2 to 10 slots, some without a map."""
    n = draw(st.sampled_from([8, 9, 16, 37, 64]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    step_t = draw(st.floats(1e-3, math.tau / n))
    step_p = draw(st.floats(1e-3, math.tau / n))
    newest = MapWindow(draw(st.floats(-1.0, 3.0)), draw(st.floats(-4.0, 4.0)), step_t, step_p, n)
    slots = draw(st.integers(2, 10))
    windows: list[MapWindow | None] = []

    def moved(d_theta_rad: float, d_phi_rad: float) -> MapWindow:
        return MapWindow(newest.theta_min_rad + d_theta_rad, newest.phi_min_rad + d_phi_rad, step_t, step_p, n)

    for _ in range(slots):
        kind = draw(st.sampled_from(["none", "newest", "shifted", "near", "other"]))
        if kind == "none":
            windows.append(None)
        elif kind == "newest":
            windows.append(moved(0.0, 0.0))
        elif kind == "shifted":  # MapWindow.around on the lattice: whole texels, phi wrapped by a turn or not
            di, dj = draw(st.integers(-n - 2, n + 2)), draw(st.integers(-n - 2, n + 2))
            turn = draw(st.sampled_from([0.0, math.tau, -math.tau]))
            windows.append(moved(di * step_t, dj * step_p + turn))
        elif kind == "near":  # within rounding of a whole-texel shift: the taps snap
            di, dj = draw(st.integers(-3, 3)), draw(st.integers(-3, 3))
            eps = draw(st.sampled_from([1e-9, -1e-9, 3e-7, -3e-7]))
            windows.append(moved((di + eps) * step_t, (dj - eps) * step_p))
        else:
            windows.append(
                MapWindow(
                    newest.theta_min_rad + draw(st.floats(-1.0, 1.0)),
                    newest.phi_min_rad + draw(st.floats(-7.0, 7.0)),
                    step_t * draw(st.floats(0.5, 1.5)),
                    min(step_p * draw(st.floats(0.5, 1.5)), math.tau / n),
                    n,
                )
            )
    values = rng.random((slots, n, n), dtype=np.float32)
    values[rng.random((slots, n, n)) < 0.2] = 0.0
    values[rng.random((slots, n, n)) < 0.05] = 1.0
    values[rng.random((slots, n, n)) < 0.05] = -0.0  # where a sum's sign could show
    mask = StyleMaskSettings(
        kind=draw(st.sampled_from(list(MaskKind))),
        soft_width_rad=draw(st.floats(0.01, 3.0)),
        top_view_phi_deg=draw(st.floats(0.0, 90.0)),
        bottom_view_phi_deg=draw(st.floats(90.0, 180.0)),
        view_ramp_deg=draw(st.floats(0.5, 90.0)),
    )
    return windows, values, newest, mask, draw(st.floats(0.01, math.pi - 0.01))


@settings(max_examples=300, deadline=None)
@given(aggregate_cases())
def test_the_compiled_aggregate_is_the_numpy_one_bit_for_bit(case):
    windows, values, newest, mask, alpha_rad = case
    python = AnticipationMap.aggregate(list(values), windows, newest, mask, alpha_rad)
    compiled = CompiledAnticipationMap.aggregate(list(values), windows, newest, mask, alpha_rad)
    for mine, theirs in zip(compiled, python):
        assert mine.dtype == np.float32 and mine.shape == theirs.shape
        assert mine.tobytes() == theirs.tobytes()


def test_a_slot_on_another_window_is_resampled_and_one_off_the_window_covers_nothing():
    newest = MapWindow(1.0, 0.5, 0.02, 0.02, 4)
    shifted = MapWindow(1.02, 0.5, 0.02, 0.02, 4)  # one texel further in theta
    away = MapWindow(3.0, 0.5, 0.02, 0.02, 4)
    a_s = [np.full((4, 4), 0.5, np.float32), np.full((4, 4), 1.0, np.float32), np.full((4, 4), 0.25, np.float32)]
    a_map, coverage = native.aggregate_amap(a_s, [newest, shifted, away], newest, StyleMaskSettings(), 1.0)
    assert coverage[0].tolist() == pytest.approx([1 / 3] * 4) and coverage[1:].ravel().tolist() == pytest.approx([2 / 3] * 12)
    assert a_map[0].tolist() == [0.5] * 4 and a_map[1:].ravel().tolist() == [0.75] * 12


def test_bad_input_is_refused():
    window = MapWindow(1.0, 0.5, 0.02, 0.02, 4)
    good = np.zeros((4, 4), np.float32)
    with pytest.raises(ValueError, match="one A_s per window"):
        native.aggregate_amap([good], [window, window], window, StyleMaskSettings(), 1.0)
    with pytest.raises(ValueError, match=r"must be \(4, 4\)"):
        native.aggregate_amap([np.zeros((3, 4), np.float32)], [window], window, StyleMaskSettings(), 1.0)
    with pytest.raises(TypeError):
        native.aggregate_amap([good.astype(np.float64)], [window], window, StyleMaskSettings(), 1.0)
    # a slot without a map is not read, whatever its array
    a_map, coverage = native.aggregate_amap([None, good], [None, window], window, StyleMaskSettings(), 1.0)
    assert not a_map.any() and coverage.tolist() == [[0.5] * 4] * 4
