"""Limb visibility by rendering ellipsoids offscreen (limb_visibility.py, moderngl EGL)."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.precompute.overview.body_parts import BodyPart, map_body_parts
from camdirector.precompute.overview.bvh import forward_kinematics, parse_bvh
from camdirector.precompute.overview.character_track import track_character
from camdirector.precompute.overview.limb_visibility import LimbVisibilityRenderer, render_limb_visibility
from camdirector.precompute.overview.overview_settings import OverviewSettings

# A T-posed stick figure facing +Z, in metres: left arm along +X, right arm along -X.
FIGURE = (
    """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest { OFFSET 0 0.3 0 CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head { OFFSET 0 0.3 0 CHANNELS 3 Zrotation Xrotation Yrotation
      End Site { OFFSET 0 0.2 0 } }
    JOINT LeftArm { OFFSET 0.15 0.2 0 CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT LeftHand { OFFSET 0.55 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
        End Site { OFFSET 0.1 0 0 } } }
    JOINT RightArm { OFFSET -0.15 0.2 0 CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT RightHand { OFFSET -0.55 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
        End Site { OFFSET -0.1 0 0 } } } }
  JOINT LeftUpLeg { OFFSET 0.1 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT LeftFoot { OFFSET 0 -0.85 0 CHANNELS 3 Zrotation Xrotation Yrotation
      End Site { OFFSET 0 -0.05 0.15 } } }
  JOINT RightUpLeg { OFFSET -0.1 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT RightFoot { OFFSET 0 -0.85 0 CHANNELS 3 Zrotation Xrotation Yrotation
      End Site { OFFSET 0 -0.05 0.15 } } }
}
MOTION
Frames: 2
Frame Time: 0.1
"""
    + "\n".join(["0 0.95 0 " + " ".join(["0"] * 33)] * 2)
    + "\n"
)


@pytest.fixture(scope="module")
def figure_visibility():
    clip = forward_kinematics(parse_bvh(FIGURE), scale_m_per_unit=1.0)
    settings = OverviewSettings(limb_view_azimuths=4, limb_view_elevations_deg=(0.0, 30.0), limb_min_saliency=0.0)
    parts = map_body_parts(clip)
    track = track_character(clip, parts, settings, np.arange(clip.frame_count))
    with LimbVisibilityRenderer(settings.limb_tile_px) as renderer:
        return render_limb_visibility(clip, parts, track, np.ones(clip.frame_count), settings, renderer)


def test_arm_hidden_behind_the_body_from_the_other_side(figure_visibility):
    # azimuths 0, 90, 180, 270 deg: from +Z (front), +X (left side), -Z (back), -X (right side)
    px = figure_visibility.pixels[0, :, 0, :]  # elevation 0
    left_arm, right_arm = px[BodyPart.LEFT_ARM], px[BodyPart.RIGHT_ARM]
    assert left_arm[0] > 0 and right_arm[0] > 0  # both arms seen from the front
    assert left_arm[3] < 0.5 * left_arm[0]  # left arm end-on behind the body
    assert right_arm[1] < 0.5 * right_arm[0]
    assert left_arm[0] == pytest.approx(right_arm[0], rel=0.15)  # symmetric figure


def test_normalised_visibility_is_in_unit_range(figure_visibility):
    n = figure_visibility.normalised
    assert n.min() >= 0.0 and n.max() == pytest.approx(1.0)
    assert figure_visibility.row_of_frame.tolist() == [0, 1]
