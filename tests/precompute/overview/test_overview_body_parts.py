"""Body-part mapping on every shared clip, by names and by topology (body_parts.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from camdirector.precompute.overview.body_parts import BodyPart, map_body_parts

from .overview_mocap import CLIPS, load_clip

EXPECTED = {  # one joint name per part per skeleton family
    "walk": {
        "Head": BodyPart.HEAD,
        "Chest": BodyPart.TORSO,
        "Hand_L": BodyPart.LEFT_ARM,
        "Hand_R": BodyPart.RIGHT_ARM,
        "Foot_L": BodyPart.LEFT_LEG,
        "Foot_R": BodyPart.RIGHT_LEG,
    },
    "cmu_01_01": {
        "Head": BodyPart.HEAD,
        "Spine1": BodyPart.TORSO,
        "LThumb": BodyPart.LEFT_ARM,
        "RightForeArm": BodyPart.RIGHT_ARM,
        "LHipJoint": BodyPart.LEFT_LEG,
        "RightToeBase": BodyPart.RIGHT_LEG,
    },
    "perfume_a": {
        "Head": BodyPart.HEAD,
        "Chest4": BodyPart.TORSO,
        "LeftCollar": BodyPart.LEFT_ARM,
        "RightWrist": BodyPart.RIGHT_ARM,
        "LeftHip": BodyPart.LEFT_LEG,
        "RightKnee": BodyPart.RIGHT_LEG,
    },
}


@pytest.mark.shared_data
@pytest.mark.parametrize("name", sorted(CLIPS))
def test_every_part_found_and_topology_agrees_with_names(shared_data, name):
    clip = load_clip(shared_data, name)
    parts = map_body_parts(clip)
    for part in BodyPart:
        assert len(parts.joints_of(part)) > 0, part
    anonymous = dataclasses.replace(clip, joint_names=tuple(f"j{i}" for i in range(len(clip.joint_names))))
    np.testing.assert_array_equal(map_body_parts(anonymous).part_of_joint, parts.part_of_joint)


@pytest.mark.shared_data
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_named_joints_land_in_their_part(shared_data, name):
    clip = load_clip(shared_data, name)
    parts = map_body_parts(clip)
    for joint, part in EXPECTED[name].items():
        assert parts.part_of_joint[clip.joint_names.index(joint)] == part, joint


@pytest.mark.shared_data
def test_bandai_world_root_is_not_on_the_body(shared_data):
    clip = load_clip(shared_data, "walk")
    parts = map_body_parts(clip)
    assert clip.joint_names.index("joint_Root") not in parts.body_points
    assert clip.joint_names.index("Hips") in parts.body_points
