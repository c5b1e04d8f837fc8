"""The character as the later stages see it: sampled frames, centre, facing, velocity, extent.

Every stage after this one works on frames sampled every `step` clip frames (the analysis rate,
see pipeline.py); framing.py builds the same track at step 1 to frame every clip frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from camdirector.geometry.transforms import UP_WORLD
from camdirector.precompute.overview.body_parts import BodyPartMap
from camdirector.precompute.overview.bvh import MotionClip
from camdirector.precompute.overview.overview_settings import OverviewSettings

_FACING_SMOOTHING_S = 0.2  # Gaussian sigma on the hips' lateral axis before taking the front, s
_VELOCITY_SMOOTHING_S = 0.25  # Gaussian sigma on the root path before differentiating, s


@dataclass(frozen=True)
class CharacterTrack:
    """The character at T sampled frames. Positions in metres, world, +Y up.

    frame_indices: (T,) int clip frames; dt_s: seconds between samples; joints_m: (T, J, 3);
    points_m: (T, K, 3) the points on the body (`BodyPartMap.body_points`: joints and end sites);
    look_at_m: (T, 3) centre of the points' bounding
    box, smoothed in time (the camera looks here); radius_m: (T,) distance from look_at_m to the
    farthest point plus the thickest body radius (a sphere holding the whole body);
    box_min_m, box_max_m: (T, 3) bounding box of the points grown by the thickest body radius;
    forward: (T, 3) unit horizontal front of the character; velocity_m_s: (T, 3) horizontal
    velocity of the pelvis; pelvis_m: (T, 3) midpoint of the two legs' first joints (the BVH root
    is not always the pelvis: Bandai's ``joint_Root`` stays at the origin); height_m: standing
    height; floor_y_m: lowest point of the clip.
    """

    frame_indices: np.ndarray
    dt_s: float
    joints_m: np.ndarray
    points_m: np.ndarray
    look_at_m: np.ndarray
    radius_m: np.ndarray
    box_min_m: np.ndarray
    box_max_m: np.ndarray
    forward: np.ndarray
    velocity_m_s: np.ndarray
    pelvis_m: np.ndarray
    height_m: float
    floor_y_m: float

    @property
    def frame_count(self) -> int:
        return int(len(self.frame_indices))


def sample_frames(frame_count: int, clip_frame_time_s: float, analysis_rate_hz: float) -> np.ndarray:
    """(T,) clip frames 0, k, 2k, ... with k = round(clip rate / analysis rate), evenly spaced so
    that one dt serves every step (the last k - 1 clip frames at most fall after the last one)."""
    step = max(1, int(round(1.0 / (clip_frame_time_s * analysis_rate_hz))))
    return np.arange(0, frame_count, step)


def track_character(
    clip: MotionClip, parts: BodyPartMap, settings: OverviewSettings, frame_indices: np.ndarray
) -> CharacterTrack:
    """The character at `frame_indices` (evenly spaced increasing clip frames)."""
    height = clip.character_height_m()
    if len(frame_indices) > 1:
        dt_s = float(np.median(np.diff(frame_indices))) * clip.frame_time_s
    else:
        dt_s = clip.frame_time_s
    joints = clip.positions_m[frame_indices]
    points = clip.all_points_m[frame_indices][:, parts.body_points]
    thickest = height * max(
        settings.head_radius_heights, settings.torso_radius_heights, settings.arm_radius_heights, settings.leg_radius_heights
    )
    lo, hi = points.min(axis=1), points.max(axis=1)
    centre = 0.5 * (lo + hi)
    sigma = settings.look_at_smoothing_s / dt_s
    look_at = gaussian_filter1d(centre, sigma, axis=0, mode="nearest") if sigma > 0 else centre
    radius = np.linalg.norm(points - look_at[:, None], axis=2).max(axis=1) + thickest
    lateral = joints[:, parts.left_hip] - joints[:, parts.right_hip]
    lateral = gaussian_filter1d(lateral, _FACING_SMOOTHING_S / dt_s, axis=0, mode="nearest")
    forward = np.cross(lateral, UP_WORLD)
    forward[:, 1] = 0.0
    forward /= np.maximum(np.linalg.norm(forward, axis=1, keepdims=True), 1e-9)
    pelvis = 0.5 * (joints[:, parts.left_hip] + joints[:, parts.right_hip])
    root_path = gaussian_filter1d(pelvis, _VELOCITY_SMOOTHING_S / dt_s, axis=0, mode="nearest")
    velocity = np.gradient(root_path, dt_s, axis=0) if len(root_path) > 1 else np.zeros_like(root_path)
    velocity[:, 1] = 0.0
    return CharacterTrack(
        frame_indices=np.asarray(frame_indices, dtype=np.int64),
        dt_s=dt_s,
        joints_m=joints,
        points_m=points,
        look_at_m=look_at,
        radius_m=radius,
        box_min_m=lo - thickest,
        box_max_m=hi + thickest,
        forward=forward,
        velocity_m_s=velocity,
        pelvis_m=pelvis,
        height_m=height,
        floor_y_m=float(clip.all_points_m[:, :, 1].min()),
    )
