"""Style masks (pipeline/toric/style_masks.py, the paper's section 5.2 and Figure 10): where "behind"
begins, and what each mask excludes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from camdirector.geometry.camera import Lens
from camdirector.geometry.toric import composition_angle, make_torus, torus_position
from camdirector.geometry.toric_maps import MapWindow
from camdirector.pipeline.style import MaskKind
from camdirector.pipeline.toric.style_masks import StyleMaskSettings, apply_style_mask, behind_theta_rad, style_mask

ALPHA = composition_angle((-1.0 / 3.0, 0.0), (1.0 / 3.0, 0.0), Lens())
TORUS = make_torus((0.0, 1.0, 0.0), (2.5, 1.0, 0.0), ALPHA)

MASK_WINDOW = MapWindow(0.2, -math.pi, (2.0 * math.pi - 2.0 * ALPHA - 0.4) / 64, 2.0 * math.pi / 64, 64)


def test_behind_boundary_is_where_the_camera_is_level_with_a():
    theta = behind_theta_rad(ALPHA)
    for phi in (0.3, 1.5, -2.0):
        along = (torus_position(TORUS, theta, phi) - TORUS.a_world) @ TORUS.axis_world
        assert abs(along) < 1e-9
        assert (torus_position(TORUS, theta - 0.1, phi) - TORUS.a_world) @ TORUS.axis_world < 0.0


def test_masks():
    theta, phi = MASK_WINDOW.grid()
    behind = theta < behind_theta_rad(ALPHA)
    a = np.random.default_rng(0).random((64, 64)).astype(np.float32)
    empty = style_mask(StyleMaskSettings(), MASK_WINDOW, ALPHA)
    np.testing.assert_array_equal(apply_style_mask(a, empty), a)
    hard = apply_style_mask(a, style_mask(StyleMaskSettings(kind=MaskKind.HARD_BEHIND), MASK_WINDOW, ALPHA))
    assert np.all(hard[behind] == 1.0)
    np.testing.assert_array_equal(hard[~behind], a[~behind])
    soft = style_mask(StyleMaskSettings(kind=MaskKind.SOFT_BEHIND), MASK_WINDOW, ALPHA)
    assert np.all(np.diff(soft, axis=0) >= 0.0)  # a gradient toward the back
    assert np.all(soft[~behind] == 1.0) and np.all(soft[theta < behind_theta_rad(ALPHA) - 0.6] == 0.0)
    assert 0 < np.count_nonzero((soft > 0) & (soft < 1))
    combined = style_mask(StyleMaskSettings(kind=MaskKind.AVOID_BEHIND_TOP_BOTTOM), MASK_WINDOW, ALPHA)
    front = ~behind
    abs_phi = np.abs(np.degrees(phi))
    assert np.all(combined[front & (abs_phi < 15)] == 0.0)  # top views
    assert np.all(combined[front & (abs_phi > 150)] == 0.0)  # bottom views
    assert np.all(combined[front & (abs_phi > 45) & (abs_phi < 120)] == 1.0)
    assert np.all((combined >= 0.0) & (combined <= 1.0))
    with pytest.raises(ValueError):
        StyleMaskSettings(top_view_phi_deg=120.0)
