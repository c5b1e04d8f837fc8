"""BVH motion capture: parsing, unit inference and forward kinematics.

The paper (motion-overview-human-actions.md, Section 1, "Overview") starts from a motion capture
clip; this module turns a BVH file into joint positions in metres, +Y up, one row per frame.

BVH conventions used here (they hold for the three shared skeletons: Bandai, CMU/cgspeed, Perfume):

* Rotation channels are in degrees and are applied in the order they are listed: for
  ``Zrotation Xrotation Yrotation`` the local rotation is ``Rz @ Rx @ Ry`` acting on column vectors.
* A position channel *replaces* the OFFSET component on its axis (Bandai children repeat their
  OFFSET in their position channels, so adding the two would double every bone).
* Units are inferred from the skeleton's height unless a scale is given: centimetres
  (0.01 m/unit), CMU units (0.056444 m/unit) or metres (1 m/unit), whichever makes the character
  closest to ``TYPICAL_HEIGHT_M``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

CM_PER_UNIT_M = 0.01  # centimetre skeletons (Bandai, Perfume), m per file unit
CMU_UNIT_M = 0.056444  # CMU/cgspeed skeletons, m per file unit (SOURCES.md section 2b)
METRE_UNIT_M = 1.0  # skeletons already in metres
KNOWN_SCALES_M_PER_UNIT = (CM_PER_UNIT_M, CMU_UNIT_M, METRE_UNIT_M)
TYPICAL_HEIGHT_M = 1.7  # adult height the unit inference aims at, m

_AXES = {"X": 0, "Y": 1, "Z": 2}


@dataclass(frozen=True)
class BvhSkeleton:
    """The HIERARCHY section.

    joint_names: J names (ROOT first, then JOINTs in file order); parents: (J,) int, -1 for the root;
    offsets_units: (J, 3) float64 file units; channels: per joint, the channel names in file order;
    channel_start: (J,) int index of each joint's first channel in a motion row;
    end_site_parents: (E,) int joint index; end_site_offsets_units: (E, 3) float64 file units.
    """

    joint_names: tuple[str, ...]
    parents: np.ndarray
    offsets_units: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    channel_start: np.ndarray
    end_site_parents: np.ndarray
    end_site_offsets_units: np.ndarray

    @property
    def channel_count(self) -> int:
        return int(sum(len(c) for c in self.channels))


@dataclass(frozen=True)
class BvhClip:
    """A parsed BVH file: skeleton, motion (F, C) float64 (file units and degrees), frame time s."""

    skeleton: BvhSkeleton
    motion: np.ndarray
    frame_time_s: float


@dataclass(frozen=True)
class MotionClip:
    """Joint positions of a clip in metres, world +Y up.

    positions_m: (F, J, 3) float64; end_site_positions_m: (F, E, 3) float64 (bone tips such as the
    top of the head); parents: (J,) int, -1 for the root; end_site_parents: (E,) int;
    frame_time_s: seconds between frames; scale_m_per_unit: the file-unit scale that was applied.
    """

    joint_names: tuple[str, ...]
    parents: np.ndarray
    positions_m: np.ndarray
    end_site_parents: np.ndarray
    end_site_positions_m: np.ndarray
    frame_time_s: float
    scale_m_per_unit: float

    @property
    def frame_count(self) -> int:
        return int(self.positions_m.shape[0])

    @property
    def all_points_m(self) -> np.ndarray:
        """(F, J + E, 3) joints then end sites."""
        return np.concatenate([self.positions_m, self.end_site_positions_m], axis=1)

    def character_height_m(self) -> float:
        """Standing height, m: the 90th percentile over frames of the vertical extent of all points.

        A percentile rather than the maximum so that a jump with raised arms does not count, and
        rather than the median so that crouching and floor moves do not lower it.
        """
        y = self.all_points_m[:, :, 1]
        return float(np.percentile(y.max(axis=1) - y.min(axis=1), 90.0))


def read_bvh(path: str | Path) -> BvhClip:
    """Parse a BVH file from disk; see `parse_bvh`."""
    return parse_bvh(Path(path).read_text(encoding="utf-8", errors="replace"))


def parse_bvh(text: str) -> BvhClip:
    """Parse BVH text. Raises ValueError naming what is wrong (not BVH, truncated, inconsistent
    channel counts, zero frames, non-numeric values)."""
    head, sep, tail = text.partition("MOTION")
    tokens = head.replace("{", " { ").replace("}", " } ").split()
    if not tokens or tokens[0].upper() != "HIERARCHY":
        raise ValueError("not a BVH file: it must start with 'HIERARCHY'")
    skeleton = _parse_hierarchy(tokens[1:])
    if not sep:
        raise ValueError("truncated BVH: no 'MOTION' section after the hierarchy")
    motion, frame_time_s = _parse_motion(tail, skeleton.channel_count)
    return BvhClip(skeleton=skeleton, motion=motion, frame_time_s=frame_time_s)


def _parse_hierarchy(tokens: list[str]) -> BvhSkeleton:
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    end_parents: list[int] = []
    end_offsets: list[list[float]] = []
    stack: list[int] = []  # joint index per open brace; -2 marks an End Site block
    pos = 0

    def take() -> str:
        nonlocal pos
        if pos >= len(tokens):
            raise ValueError("truncated BVH: the hierarchy ends inside a joint block")
        pos += 1
        return tokens[pos - 1]

    def take_floats(n: int, what: str) -> list[float]:
        values = [take() for _ in range(n)]
        try:
            return [float(v) for v in values]
        except ValueError:
            raise ValueError(f"bad BVH hierarchy: {what} expects {n} numbers, got {values}") from None

    if take().upper() != "ROOT":
        raise ValueError("not a BVH file: expected 'ROOT' after 'HIERARCHY'")
    pending: tuple[str, int] | None = ("joint", -1)
    names.append(take())
    while True:
        if pending is not None:
            if take() != "{":
                raise ValueError(f"bad BVH hierarchy: expected '{{' after joint '{names[-1]}'")
            kind, parent = pending
            pending = None
            if kind == "joint":
                parents.append(parent)
                offsets.append([0.0, 0.0, 0.0])
                channels.append(())
                stack.append(len(names) - 1)
            else:
                end_parents.append(parent)
                end_offsets.append([0.0, 0.0, 0.0])
                stack.append(-2)
            continue
        if not stack:
            break
        word = take()
        current = stack[-1]
        upper = word.upper()
        if upper == "OFFSET":
            values = take_floats(3, "OFFSET")
            if current == -2:
                end_offsets[-1] = values
            else:
                offsets[current] = values
        elif upper == "CHANNELS":
            if current == -2:
                raise ValueError("bad BVH hierarchy: an End Site cannot have CHANNELS")
            count_text = take()
            if not count_text.isdigit():
                raise ValueError(f"bad BVH hierarchy: CHANNELS count '{count_text}' is not a number")
            count = int(count_text)
            listed = []
            while pos < len(tokens) and tokens[pos].upper() in _CHANNEL_NAMES:
                listed.append(tokens[pos])
                pos += 1
            if len(listed) != count:
                raise ValueError(
                    f"inconsistent BVH channels: joint '{names[current]}' declares {count} channels but lists {len(listed)}"
                )
            channels[current] = tuple(_CHANNEL_NAMES[c.upper()] for c in listed)
        elif upper == "JOINT":
            if current == -2:
                raise ValueError("bad BVH hierarchy: JOINT inside an End Site")
            names.append(take())
            pending = ("joint", current)
        elif upper == "END":
            if take().upper() != "SITE":
                raise ValueError("bad BVH hierarchy: 'End' must be followed by 'Site'")
            pending = ("end", current)
        elif word == "}":
            stack.pop()
        else:
            raise ValueError(f"bad BVH hierarchy: unexpected token '{word}'")
    if pos != len(tokens):
        raise ValueError(f"bad BVH hierarchy: unexpected '{tokens[pos]}' after the root block")
    counts = [len(c) for c in channels]
    return BvhSkeleton(
        joint_names=tuple(names),
        parents=np.array(parents, dtype=np.int64),
        offsets_units=np.array(offsets, dtype=np.float64).reshape(-1, 3),
        channels=tuple(channels),
        channel_start=np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64),
        end_site_parents=np.array(end_parents, dtype=np.int64),
        end_site_offsets_units=np.array(end_offsets, dtype=np.float64).reshape(-1, 3),
    )


_CHANNEL_NAMES = {n.upper(): n for n in ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")}


def _parse_motion(text: str, channel_count: int) -> tuple[np.ndarray, float]:
    lines = [line.strip() for line in text.splitlines()]
    lines = [line for line in lines if line]
    if len(lines) < 2:
        raise ValueError("truncated BVH: the MOTION section needs 'Frames:' and 'Frame Time:'")
    frames_key, _, frames_text = lines[0].partition(":")
    time_key, _, time_text = lines[1].partition(":")
    if frames_key.strip().lower() != "frames" or time_key.strip().lower() != "frame time":
        raise ValueError("bad BVH motion header: expected 'Frames:' then 'Frame Time:'")
    try:
        frame_count = int(frames_text)
        frame_time_s = float(time_text)
    except ValueError:
        raise ValueError(f"bad BVH motion header: {lines[0]!r}, {lines[1]!r}") from None
    if frame_count <= 0:
        raise ValueError("BVH has zero frames")
    if not (frame_time_s > 0.0 and math.isfinite(frame_time_s)):
        raise ValueError(f"bad BVH frame time {frame_time_s}: must be a positive number of seconds")
    rows = lines[2:]
    if len(rows) < frame_count:
        raise ValueError(f"truncated BVH: 'Frames: {frame_count}' but only {len(rows)} data rows")
    if len(rows) > frame_count:
        raise ValueError(f"inconsistent BVH: 'Frames: {frame_count}' but {len(rows)} data rows")
    motion = np.empty((frame_count, channel_count), dtype=np.float64)
    for i, row in enumerate(rows):
        values = row.split()
        if len(values) != channel_count:
            raise ValueError(
                f"inconsistent BVH channel count: frame {i} has {len(values)} values, "
                f"the hierarchy declares {channel_count} channels"
            )
        try:
            motion[i] = [float(v) for v in values]
        except ValueError:
            raise ValueError(f"bad BVH motion: frame {i} has a non-numeric value") from None
    if not np.all(np.isfinite(motion)):
        raise ValueError("bad BVH motion: NaN or infinite values")
    return motion, frame_time_s


def _axis_rotations(angles_rad: np.ndarray, axis: int) -> np.ndarray:
    """(F,) angles -> (F, 3, 3) rotation matrices about one axis (0=X, 1=Y, 2=Z)."""
    c, s = np.cos(angles_rad), np.sin(angles_rad)
    m = np.zeros(angles_rad.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m[:, axis, axis] = 1.0
    m[:, i, i] = c
    m[:, j, j] = c
    m[:, i, j] = -s
    m[:, j, i] = s
    return m


def _fk_units(skeleton: BvhSkeleton, motion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics in file units: joints (F, J, 3) and end sites (F, E, 3).

    Vectorised over frames; one pass over joints in file order (a parent always precedes its child).
    """
    n_frames = motion.shape[0]
    n_joints = len(skeleton.joint_names)
    rot = np.empty((n_joints, n_frames, 3, 3))
    pos = np.empty((n_joints, n_frames, 3))
    for j in range(n_joints):
        local_t = np.broadcast_to(skeleton.offsets_units[j], (n_frames, 3)).copy()
        local_r = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        for k, name in enumerate(skeleton.channels[j]):
            column = motion[:, skeleton.channel_start[j] + k]
            axis = _AXES[name[0]]
            if name.endswith("position"):
                local_t[:, axis] = column
            else:
                local_r = local_r @ _axis_rotations(np.radians(column), axis)
        parent = skeleton.parents[j]
        if parent < 0:
            rot[j] = local_r
            pos[j] = local_t
        else:
            rot[j] = rot[parent] @ local_r
            pos[j] = pos[parent] + np.einsum("fij,fj->fi", rot[parent], local_t)
    ends = np.empty((len(skeleton.end_site_parents), n_frames, 3))
    for e, parent in enumerate(skeleton.end_site_parents):
        ends[e] = pos[parent] + rot[parent] @ skeleton.end_site_offsets_units[e]
    return pos.transpose(1, 0, 2), ends.transpose(1, 0, 2)


def infer_scale_m_per_unit(height_units: float) -> float:
    """The known unit (cm, CMU, m) that makes a character `height_units` tall closest to 1.7 m."""
    if not (height_units > 0.0 and math.isfinite(height_units)):
        raise ValueError(f"cannot infer BVH units from a skeleton height of {height_units}")
    errors = [abs(math.log(height_units * s / TYPICAL_HEIGHT_M)) for s in KNOWN_SCALES_M_PER_UNIT]
    return KNOWN_SCALES_M_PER_UNIT[int(np.argmin(errors))]


def forward_kinematics(clip: BvhClip, *, scale_m_per_unit: float | None = None, skip_frames: int = 0) -> MotionClip:
    """Joint positions of a parsed clip, metres, +Y up.

    scale_m_per_unit: metres per file unit; None infers it from the skeleton height (see
    `infer_scale_m_per_unit`). skip_frames: leading frames to drop (CMU/cgspeed and Perfume
    files start with a T-pose or rest pose, SOURCES.md section 2).
    """
    if skip_frames < 0 or skip_frames >= clip.motion.shape[0]:
        raise ValueError(f"skip_frames={skip_frames} must be in [0, {clip.motion.shape[0] - 1}] for this clip")
    if scale_m_per_unit is not None and not (scale_m_per_unit > 0 and math.isfinite(scale_m_per_unit)):
        raise ValueError("scale_m_per_unit must be a positive number of metres per file unit")
    joints_u, ends_u = _fk_units(clip.skeleton, clip.motion[skip_frames:])
    if scale_m_per_unit is None:
        unscaled = MotionClip(
            clip.skeleton.joint_names,
            clip.skeleton.parents,
            joints_u,
            clip.skeleton.end_site_parents,
            ends_u,
            clip.frame_time_s,
            1.0,
        )
        scale_m_per_unit = infer_scale_m_per_unit(unscaled.character_height_m())
    return MotionClip(
        joint_names=clip.skeleton.joint_names,
        parents=clip.skeleton.parents,
        positions_m=joints_u * scale_m_per_unit,
        end_site_parents=clip.skeleton.end_site_parents,
        end_site_positions_m=ends_u * scale_m_per_unit,
        frame_time_s=clip.frame_time_s,
        scale_m_per_unit=float(scale_m_per_unit),
    )


def load_motion(path: str | Path, *, scale_m_per_unit: float | None = None, skip_frames: int = 0) -> MotionClip:
    """Read a BVH file and run forward kinematics on it (see `forward_kinematics`)."""
    return forward_kinematics(read_bvh(path), scale_m_per_unit=scale_m_per_unit, skip_frames=skip_frames)
