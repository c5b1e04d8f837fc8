"""The six main body parts of a skeleton: head, torso, two arms, two legs.

The paper (Section 3, limb visibility descriptor and limb saliency) works on "six main body parts
(head, torso, two legs and two arms)". This module assigns every joint of any skeleton to one of
them, first by name (Bandai ``UpperArm_L``, CMU/cgspeed ``LeftForeArm``/``LHipJoint``, Perfume
``LeftCollar``/``RightKnee``), and when names do not resolve all six parts, by topology:

* the trunk is the chain from the root to the end site that is highest on average over the clip;
* the two subtrees hanging off the trunk whose tips are lowest are the legs, the next two largest
  are the arms; the top joint of the trunk is the head (as with names: a neck is torso), the rest
  of the trunk and any other small subtree are the torso;
* left and right come from the names when they carry a side; otherwise from the feet: the last
  bone of a planted foot (ankle to toe) points forward, the character's left is up x forward, and
  a limb is left when its joints lie on that side of the hips on average.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from camdirector.precompute.overview.bvh import MotionClip


class BodyPart(IntEnum):
    """Index of each part in per-part arrays (saliency, visibility)."""

    HEAD = 0
    TORSO = 1
    LEFT_ARM = 2
    RIGHT_ARM = 3
    LEFT_LEG = 4
    RIGHT_LEG = 5


PART_COUNT = len(BodyPart)


_RIGID_BONE_TOLERANCE = 0.01  # a bone whose length varies by more than this fraction is not a bone


@dataclass(frozen=True)
class BodyPartMap:
    """part_of_joint: (J,) int BodyPart of each joint; root: the root joint index;
    left_hip, right_hip: first joint of each leg (their difference is the lateral axis);
    body_points: (K,) indices into `MotionClip.all_points_m` (joints, then end sites) of the points
    on the body. A joint joined to the rest only by bones whose length changes over the clip is
    not on the body: Bandai's ``joint_Root`` stays at the world origin while the actor walks away.
    """

    part_of_joint: np.ndarray
    root: int
    left_hip: int
    right_hip: int
    body_points: np.ndarray

    def joints_of(self, part: int) -> np.ndarray:
        """Indices of the joints of `part` (a BodyPart, or its number)."""
        return np.flatnonzero(self.part_of_joint == part)


_HEAD = re.compile(r"head", re.IGNORECASE)
_ARM = re.compile(r"shoulder|collar|clavicle|arm|elbow|wrist|hand|finger|thumb|index|pinky", re.IGNORECASE)
_LEG = re.compile(r"hip|thigh|upleg|leg|knee|ankle|foot|toe|heel", re.IGNORECASE)


def _side_of(name: str) -> str | None:
    # The case-sensitive prefix test ("LHipJoint", "RThumb") needs the raw name.
    if re.match(r"^L(?=[A-Z_])", name) or re.search(r"(^left|_l$|_l_|\.l$|left)", name, re.I):
        return "left"
    if re.match(r"^R(?=[A-Z_])", name) or re.search(r"(^right|_r$|_r_|\.r$|right)", name, re.I):
        return "right"
    return None


def _map_by_name(names: tuple[str, ...], parents: np.ndarray) -> np.ndarray:
    """(J,) part per joint; children inherit a limb or head part, unnamed joints are torso."""
    parts = np.full(len(names), BodyPart.TORSO, dtype=np.int64)
    for j, name in enumerate(names):
        side = _side_of(name)
        parent = parents[j]
        inherited = parts[parent] if parent >= 0 else BodyPart.TORSO
        if inherited in (BodyPart.LEFT_ARM, BodyPart.RIGHT_ARM, BodyPart.LEFT_LEG, BodyPart.RIGHT_LEG, BodyPart.HEAD):
            parts[j] = inherited
        elif _HEAD.search(name):
            parts[j] = BodyPart.HEAD
        elif side is not None and _ARM.search(name):
            parts[j] = BodyPart.LEFT_ARM if side == "left" else BodyPart.RIGHT_ARM
        elif side is not None and _LEG.search(name):
            parts[j] = BodyPart.LEFT_LEG if side == "left" else BodyPart.RIGHT_LEG
        else:
            parts[j] = BodyPart.TORSO
    return parts


def _children(parents: np.ndarray) -> list[list[int]]:
    kids: list[list[int]] = [[] for _ in parents]
    for j, p in enumerate(parents):
        if p >= 0:
            kids[p].append(j)
    return kids


def _subtree(kids: list[list[int]], j: int) -> list[int]:
    out, todo = [], [j]
    while todo:
        k = todo.pop()
        out.append(k)
        todo.extend(kids[k])
    return out


def _map_by_topology(clip: MotionClip) -> np.ndarray:
    parents = clip.parents
    kids = _children(parents)
    mean_y = clip.positions_m[:, :, 1].mean(axis=0)
    leaves = [j for j in range(len(parents)) if not kids[j]]
    head_leaf = max(leaves, key=lambda j: mean_y[j])
    trunk = [head_leaf]
    while parents[trunk[-1]] >= 0:
        trunk.append(int(parents[trunk[-1]]))
    trunk = trunk[::-1]  # root ... head leaf
    on_trunk = set(trunk)
    hanging = [(t_idx, c) for t_idx, t in enumerate(trunk) for c in kids[t] if c not in on_trunk]
    if len(hanging) < 4:
        raise ValueError(
            "cannot map the skeleton to head, torso, two arms and two legs: "
            f"fewer than four limbs hang off the trunk ({len(hanging)})"
        )
    tip_y = {c: min(mean_y[k] for k in _subtree(kids, c)) for _, c in hanging}
    size = {c: len(_subtree(kids, c)) for _, c in hanging}
    legs = sorted(hanging, key=lambda h: tip_y[h[1]])[:2]
    rest = [h for h in hanging if h not in legs]
    arms = sorted(rest, key=lambda h: -size[h[1]])[:2]
    parts = np.full(len(parents), BodyPart.TORSO, dtype=np.int64)
    parts[head_leaf] = BodyPart.HEAD
    lateral = _left_offsets(clip, kids, legs[0][1], legs[1][1])
    for pair, left_part, right_part in (
        (legs, BodyPart.LEFT_LEG, BodyPart.RIGHT_LEG),
        (arms, BodyPart.LEFT_ARM, BodyPart.RIGHT_ARM),
    ):
        a, b = pair[0][1], pair[1][1]
        side_a = _side_of(clip.joint_names[a])
        a_is_left = side_a == "left" if side_a else lateral[_subtree(kids, a)].mean() > lateral[_subtree(kids, b)].mean()
        parts[_subtree(kids, a)] = left_part if a_is_left else right_part
        parts[_subtree(kids, b)] = right_part if a_is_left else left_part
    return parts


def _left_offsets(clip: MotionClip, kids: list[list[int]], leg_a: int, leg_b: int) -> np.ndarray:
    """(J,) mean over frames of each joint's offset from between the hips along the character's
    left, m.

    Forward is the horizontal direction of the last bone of each leg (ankle to toe) in the frames
    where that foot is planted (its tip within 5% of the height of its lowest point: a swinging
    foot can point anywhere), summed over the clip; left = up x forward (+Y x +Z = +X for a
    character facing +Z). One direction for the whole clip is enough to tell the sides apart."""
    pos = clip.positions_m
    height = clip.character_height_m()
    forward = np.zeros(3)
    for leg in (leg_a, leg_b):
        members = _subtree(kids, leg)
        depth = {members[0]: 0}
        for j in members[1:]:
            depth[j] = depth[int(clip.parents[j])] + 1
        tip = max(members, key=lambda j: depth[j])
        foot = pos[:, tip] - pos[:, clip.parents[tip]]
        planted = pos[:, tip, 1] <= pos[:, tip, 1].min() + 0.05 * height
        foot[:, 1] = 0.0
        foot /= np.maximum(np.linalg.norm(foot, axis=1, keepdims=True), 1e-9)
        forward += foot[planted].sum(axis=0)
    left = np.cross(np.array([0.0, 1.0, 0.0]), forward)
    left /= max(float(np.linalg.norm(left)), 1e-9)
    reference = 0.5 * (pos[:, leg_a] + pos[:, leg_b])[:, None]  # between the hips
    return np.einsum("fjk,k->fj", pos - reference, left).mean(axis=0)


def map_body_parts(clip: MotionClip) -> BodyPartMap:
    """Assign each joint to a body part, by names first, by topology when names do not give all six.
    Raises ValueError when neither works."""
    parts = _map_by_name(clip.joint_names, clip.parents)
    if not all(np.any(parts == p) for p in BodyPart):
        parts = _map_by_topology(clip)
    first = {}
    for p in (BodyPart.LEFT_LEG, BodyPart.RIGHT_LEG):
        members = np.flatnonzero(parts == p)
        # The leg's first joint: the member whose parent is not in the leg.
        first[p] = int(next(j for j in members if parts[clip.parents[j]] != p))
    root = int(np.flatnonzero(clip.parents < 0)[0])
    return BodyPartMap(
        part_of_joint=parts,
        root=root,
        left_hip=first[BodyPart.LEFT_LEG],
        right_hip=first[BodyPart.RIGHT_LEG],
        body_points=_body_points(clip),
    )


def rigid_bones(clip: MotionClip) -> tuple[np.ndarray, np.ndarray]:
    """(B,) parent and (B,) child point indices (into `MotionClip.all_points_m`) of the bones whose
    length stays within 1% of its mean over the clip; zero-length bones count as rigid."""
    n_joints = len(clip.joint_names)
    order = np.flatnonzero(clip.parents >= 0)
    parent = np.concatenate([clip.parents[order], clip.end_site_parents]).astype(np.int64)
    child = np.concatenate([order, n_joints + np.arange(len(clip.end_site_parents))])
    points = clip.all_points_m
    lengths = np.linalg.norm(points[:, child] - points[:, parent], axis=2)  # (F, B)
    mean = lengths.mean(axis=0)
    rigid = lengths.std(axis=0) <= _RIGID_BONE_TOLERANCE * np.maximum(mean, 1e-9)
    return parent[rigid], child[rigid]


def _body_points(clip: MotionClip) -> np.ndarray:
    parent, child = rigid_bones(clip)
    return np.unique(np.concatenate([parent, child]))
