"""Final framing at the clip's own frame rate: camera position, look-at, up, field of view
(paper Section 4, last paragraph: "The camera field of view is calculated separately for each shot
by using the largest character silhouette bounding box in every frame in the shot, and setting the
lookat vector to point to the character").

* Positions: the path found at the analysis rate is interpolated linearly between analysis frames
  of the same shot; clip frames after a shot's last analysis frame and before the next shot's first
  hold the last position (no interpolation across a cut). Piecewise-linear interpolation never
  exceeds the fastest sampled step, so the speed limit holds at the clip's rate too.
* Look-at: the centre of the body's bounding box smoothed in time (character_track.py), at every
  clip frame. Up is world +Y (no roll).
* Field of view: per shot, the smallest symmetric vertical FOV (with the frame's aspect) around
  the look-at direction that holds the projected bounding box of every body point (joints and end
  sites) in every frame of the shot, with `frame_margin` of the half-frame to spare.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.transforms import UP_WORLD, matrix_to_quat
from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.overview_settings import OverviewSettings


@dataclass(frozen=True)
class Framing:
    """Per clip frame (F): position_m (F, 3), look_at_m (F, 3), up (F, 3), rotation_xyzw (F, 4)
    camera-to-world (looks down -Z), vertical_fov_deg (F,), shot_index (F,) int; shots (S, 2)
    int [first, last] clip frames."""

    position_m: np.ndarray
    look_at_m: np.ndarray
    up: np.ndarray
    rotation_xyzw: np.ndarray
    vertical_fov_deg: np.ndarray
    shot_index: np.ndarray
    shots: np.ndarray


def camera_rotations(position_m: np.ndarray, look_at_m: np.ndarray) -> np.ndarray:
    """(F, 3, 3) camera-to-world rotations looking from positions at look-at points, +Y up."""
    back = position_m - look_at_m
    back /= np.maximum(np.linalg.norm(back, axis=1, keepdims=True), 1e-12)
    right = np.cross(UP_WORLD, back)
    right /= np.maximum(np.linalg.norm(right, axis=1, keepdims=True), 1e-12)
    up = np.cross(back, right)
    return np.stack([right, up, back], axis=2)  # columns: camera x, y, z in world


def required_tan_half_fov(rotations: np.ndarray, position_m: np.ndarray, points_m: np.ndarray, aspect: float) -> np.ndarray:
    """(F,) tan(vertical FOV / 2) that just holds (F, K, 3) points; inf if one is behind."""
    cam = np.einsum("fkj,fji->fki", points_m - position_m[:, None], rotations)  # R^T (p - c)
    depth = -cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.maximum(np.abs(cam[..., 1]) / depth, np.abs(cam[..., 0]) / (depth * aspect))
    need = np.where(depth > 0.0, need, np.inf)
    return need.max(axis=1)


def frame_clip(
    track_full: CharacterTrack, path_m: np.ndarray, shots: np.ndarray, analysis_frames: np.ndarray, settings: OverviewSettings
) -> Framing:
    """Framing at every clip frame. track_full: the character at every clip frame; path_m (T, 3)
    at `analysis_frames` (T,) clip frames; shots (S, 2) in analysis-frame indices."""
    n = track_full.frame_count
    position = np.empty((n, 3))
    shot_index = np.empty(n, dtype=np.int64)
    clip_shots = []
    for k, (a, b) in enumerate(shots):
        start = int(analysis_frames[a]) if k > 0 else 0
        end = int(analysis_frames[shots[k + 1][0]]) - 1 if k + 1 < len(shots) else n - 1
        clip_shots.append((start, end))
        shot_index[start : end + 1] = k
        frames = np.arange(start, end + 1)
        keys = analysis_frames[a : b + 1]
        for axis in range(3):
            position[start : end + 1, axis] = np.interp(frames, keys, path_m[a : b + 1, axis])
    look_at = track_full.look_at_m
    rotations = camera_rotations(position, look_at)
    points = track_full.points_m
    tan_need = required_tan_half_fov(rotations, position, points, settings.aspect)
    tan_need = tan_need / (1.0 - settings.frame_margin)
    fov = np.empty(n)
    for start, end in clip_shots:
        fov[start : end + 1] = 2.0 * math.degrees(math.atan(float(tan_need[start : end + 1].max())))
    quats = np.array([matrix_to_quat(r) for r in rotations])
    return Framing(
        position_m=position,
        look_at_m=look_at,
        up=np.tile(UP_WORLD, (n, 1)),
        rotation_xyzw=quats,
        vertical_fov_deg=fov,
        shot_index=shot_index,
        shots=np.array(clip_shots, dtype=np.int64),
    )
