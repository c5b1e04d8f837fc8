"""BVH parsing, forward kinematics and unit inference (precompute/overview/bvh.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector.precompute.overview.bvh import (
    CM_PER_UNIT_M,
    CMU_UNIT_M,
    METRE_UNIT_M,
    forward_kinematics,
    infer_scale_m_per_unit,
    parse_bvh,
)

TWO_JOINT = """HIERARCHY
ROOT Base
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Tip
  {
    OFFSET 0 {length} 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 {length} 0
    }
  }
}
MOTION
Frames: {frames}
Frame Time: 0.5
{rows}
"""


def two_joint(rows: list[list[float]], length: float = 1.0) -> str:
    text = TWO_JOINT.replace("{length}", str(length)).replace("{frames}", str(len(rows)))
    return text.replace("{rows}", "\n".join(" ".join(str(v) for v in r) for r in rows))


def test_parses_hierarchy_and_motion():
    clip = parse_bvh(two_joint([[0, 0, 0, 0, 0, 0, 0, 0, 0], [1, 2, 3, 0, 0, 0, 0, 0, 0]]))
    sk = clip.skeleton
    assert sk.joint_names == ("Base", "Tip")
    assert sk.parents.tolist() == [-1, 0]
    assert sk.channel_count == 9
    assert sk.end_site_parents.tolist() == [1]
    assert clip.motion.shape == (2, 9)
    assert clip.frame_time_s == 0.5


def test_fk_two_joint_chain_rotations_and_translation():
    # Frame 0: rest. Frame 1: root moved to (1, 2, 3) and rotated 90 deg about Z, so the bone
    # along +Y points along -X. Frame 2: the child rotated 90 deg about X, so its tip along +Z.
    rows = [[0, 0, 0, 0, 0, 0, 0, 0, 0], [1, 2, 3, 90, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 0, 90, 0]]
    m = forward_kinematics(parse_bvh(two_joint(rows)), scale_m_per_unit=1.0)
    np.testing.assert_allclose(m.positions_m[0], [[0, 0, 0], [0, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(m.end_site_positions_m[0], [[0, 2, 0]], atol=1e-12)
    np.testing.assert_allclose(m.positions_m[1], [[1, 2, 3], [0, 2, 3]], atol=1e-12)
    np.testing.assert_allclose(m.end_site_positions_m[1], [[-1, 2, 3]], atol=1e-12)
    np.testing.assert_allclose(m.positions_m[2], [[0, 0, 0], [0, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(m.end_site_positions_m[2], [[0, 1, 1]], atol=1e-12)


def test_rotation_channels_apply_in_listed_order():
    # Root channels list Z then X: R = Rz(90) @ Rx(90). The bone (0, 1, 0) goes by Rx to (0, 0, 1),
    # which Rz leaves alone. The other order, Rx @ Rz, would give Rx (-1, 0, 0) = (-1, 0, 0).
    rows = [[0, 0, 0, 90, 90, 0, 0, 0, 0]]
    m = forward_kinematics(parse_bvh(two_joint(rows)), scale_m_per_unit=1.0)
    np.testing.assert_allclose(m.positions_m[0, 1], [0, 0, 1], atol=1e-12)


def test_skip_frames_and_scale():
    rows = [[0, 0, 0, 0, 0, 0, 0, 0, 0], [5, 0, 0, 0, 0, 0, 0, 0, 0]]
    m = forward_kinematics(parse_bvh(two_joint(rows)), scale_m_per_unit=0.01, skip_frames=1)
    assert m.frame_count == 1
    np.testing.assert_allclose(m.positions_m[0, 0], [0.05, 0, 0])
    with pytest.raises(ValueError, match="skip_frames"):
        forward_kinematics(parse_bvh(two_joint(rows)), skip_frames=2)


@pytest.mark.parametrize(
    "height_units, expected",
    [
        (170.0, CM_PER_UNIT_M),
        (150.0, CM_PER_UNIT_M),
        (30.0, CMU_UNIT_M),
        (27.0, CMU_UNIT_M),
        (1.7, METRE_UNIT_M),
        (1.5, METRE_UNIT_M),
    ],
)
def test_unit_inference(height_units, expected):
    assert infer_scale_m_per_unit(height_units) == expected


def test_unit_inference_from_a_centimetre_skeleton():
    rows = [[0, 0, 0, 0, 0, 0, 0, 0, 0]]
    m = forward_kinematics(parse_bvh(two_joint(rows, length=85.0)))
    assert m.scale_m_per_unit == CM_PER_UNIT_M
    assert math.isclose(m.character_height_m(), 1.7)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-180, 180), min_size=6, max_size=6), st.lists(st.floats(-10, 10), min_size=3, max_size=3))
def test_fk_preserves_bone_lengths(angles, translation):
    rows = [translation + angles[:3] + angles[3:]]
    m = forward_kinematics(parse_bvh(two_joint(rows, length=2.0)), scale_m_per_unit=1.0)
    pts = m.all_points_m[0]
    assert math.isclose(np.linalg.norm(pts[1] - pts[0]), 2.0, rel_tol=1e-9)
    assert math.isclose(np.linalg.norm(pts[2] - pts[1]), 2.0, rel_tol=1e-9)
    np.testing.assert_allclose(pts[0], translation, atol=1e-9)


GOOD = two_joint([[0] * 9, [0] * 9])


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "not a BVH file"),
        ("hello world", "not a BVH file"),
        ("HIERARCHY\nJOINT x {", "expected 'ROOT'"),
        (GOOD[: GOOD.index("End Site")], "truncated"),
        (GOOD[: GOOD.index("MOTION")], "no 'MOTION'"),
        (GOOD.replace("Frames: 2", "Frames: 3"), "truncated BVH: 'Frames: 3' but only 2"),
        (GOOD.replace("Frames: 2", "Frames: 1"), "inconsistent BVH: 'Frames: 1' but 2"),
        (GOOD.replace("Frames: 2", "Frames: 0").rsplit("\n", 3)[0] + "\n", "zero frames"),
        (GOOD.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"), "declares 4 channels but lists 3"),
        (GOOD.replace("\n0 0 0 0 0 0 0 0 0\n", "\n0 0 0 0 0 0 0 0\n", 1), "inconsistent BVH channel count"),
        (GOOD.replace("\n0 0 0 0 0 0 0 0 0\n", "\n0 0 0 0 x 0 0 0 0\n", 1), "non-numeric"),
        (GOOD.replace("Frame Time: 0.5", "Frame Time: 0"), "frame time"),
        (GOOD.replace("OFFSET 0 0 0", "OFFSET 0 zero 0", 1), "OFFSET expects 3 numbers"),
    ],
)
def test_bad_input_raises_clear_value_error(text, message):
    with pytest.raises(ValueError, match=message):
        parse_bvh(text)
