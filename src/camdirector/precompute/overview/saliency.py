"""Pose saliency S_p(t) and limb saliency S_limb(t) (paper Section 3, after Assa et al. 2005).

Method, as the paper describes it:

1. Every frame becomes a high-dimensional point of "relative joint location and speed": joint
   positions relative to the pelvis, and joint velocities, both in character heights. Velocities are
   multiplied by `speed_feature_time_s` (our choice, 0.2 s) so that a joint moving at one height
   per second weighs like a 0.2-height offset.
2. Non-linear multi-dimensional scaling reduces that space curve to `mds_dimensions` (our choice,
   3) dimensions. We use Sammon's mapping (a non-linear, locality-weighted MDS, Sammon 1969),
   started from classical MDS.
3. The low-dimensional curve is compared with a smooth average curve (a Gaussian of sigma
   `saliency_smoothing_s` in time, our choice 0.5 s); the per-frame distance between them is the
   raw saliency. S_p = distance / max distance over the clip, so S_p is in [0, 1] and the most
   salient frame of the clip has S_p = 1 (the paper gives no normalisation; this one is ours).
4. Limb saliency: the same on the joints of each of the six body parts. The per-frame distances are
   made comparable by dividing each part's features by sqrt(its joint count). S_limb(t) is the
   per-frame share of each part. The paper "only consider[s] cases where there are large
   differences between the saliency of the different body parts"; we blend S_limb toward uniform
   (1/6 each) when max/mean of the six is below `limb_contrast_ratio` (our choice, 2): weight
   w = clip((max/mean - 1) / (ratio - 1), 0, 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from camdirector.precompute.overview.body_parts import PART_COUNT, BodyPartMap
from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.overview_settings import OverviewSettings

_MAX_STEP_HALVINGS = 20  # a Sammon step is halved until the stress does not grow, at most this often


@dataclass(frozen=True)
class Saliency:
    """pose: (T,) S_p in [0, 1]; limbs: (T, 6) S_limb, rows sum to 1 (BodyPart order);
    curve: (T, k) the MDS curve of the whole pose; smooth_curve: (T, k) its smooth average."""

    pose: np.ndarray
    limbs: np.ndarray
    curve: np.ndarray
    smooth_curve: np.ndarray


def classical_mds(points: np.ndarray, dimensions: int) -> np.ndarray:
    """Classical (Torgerson) MDS of the Euclidean distances of (n, D) points: (n, dimensions).

    For Euclidean distances classical MDS equals the projection on the principal axes, so it is
    computed by an SVD of the centred points (O(n D^2), not the O(n^3) eigendecomposition)."""
    centred = points - points.mean(axis=0)
    _, singular, vt = np.linalg.svd(centred, full_matrices=False)
    k = min(dimensions, vt.shape[0])
    coords = centred @ vt[:k].T
    if k < dimensions:
        coords = np.pad(coords, ((0, 0), (0, dimensions - k)))
    return coords


def pairwise_distances(points: np.ndarray) -> np.ndarray:
    """(n, n) Euclidean distances of (n, D) points, through the Gram matrix (one BLAS call)."""
    sq = np.einsum("ij,ij->i", points, points)
    d2 = sq[:, None] + sq[None, :] - 2.0 * (points @ points.T)
    np.maximum(d2, 0.0, out=d2)
    return np.sqrt(d2, out=d2)


def sammon_mapping(points: np.ndarray, dimensions: int, iterations: int) -> np.ndarray:
    """Non-linear MDS of (n, D) points to (n, dimensions) by Sammon's mapping.

    Minimises sum_{i<j} (D_ij - d_ij)^2 / D_ij with Sammon's diagonal-Newton step, starting from
    classical MDS; a step is halved until the stress does not grow (starting from twice the last
    accepted step), and the iterations stop when no halving helps.
    """
    n = points.shape[0]
    if n < 2:
        return np.zeros((n, dimensions))
    target = pairwise_distances(points)
    scale = max(float(target.max()), 1e-12)
    target /= scale
    coords = classical_mds(points, dimensions) / scale
    diagonal = np.arange(n)
    target[diagonal, diagonal] = 1.0  # the diagonal is ignored: make it 1 on both sides
    np.maximum(target, 1e-9, out=target)
    inv_target = 1.0 / target

    def stress(y: np.ndarray) -> tuple[float, np.ndarray]:
        d = pairwise_distances(y)
        d[diagonal, diagonal] = 1.0
        np.maximum(d, 1e-9, out=d)
        diff = target - d
        return float(np.einsum("ij,ij,ij->", diff, diff, inv_target)), d

    current, d = stress(coords)
    step = 1.0
    for _ in range(iterations):
        inv_d = np.reciprocal(d, out=d)
        delta = inv_d - inv_target
        delta_one = delta.sum(axis=1, keepdims=True)
        gradient = delta @ coords - coords * delta_one
        inv_d3 = np.power(inv_d, 3, out=inv_d)
        y2 = coords**2
        hessian = inv_d3 @ y2 - delta_one - 2.0 * coords * (inv_d3 @ coords) + y2 * inv_d3.sum(axis=1, keepdims=True)
        direction = -gradient / np.maximum(np.abs(hessian), 1e-12)
        step = min(1.0, 2.0 * step)  # start near the last accepted step: fewer stress passes
        for _halving in range(_MAX_STEP_HALVINGS):
            trial = coords + step * direction
            trial_stress, trial_d = stress(trial)
            if trial_stress <= current:
                break
            step *= 0.5
        else:
            break
        coords, current, d = trial, trial_stress, trial_d
    return coords * scale


def _curve_distance(features: np.ndarray, settings: OverviewSettings, dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance (T,) of the MDS curve of (T, D) features to its smooth average; curve; smooth."""
    curve = sammon_mapping(features, settings.mds_dimensions, settings.mds_iterations)
    smooth = gaussian_filter1d(curve, settings.saliency_smoothing_s / dt_s, axis=0, mode="nearest")
    return np.linalg.norm(curve - smooth, axis=1), curve, smooth


def _features(track: CharacterTrack, joints: np.ndarray, settings: OverviewSettings) -> np.ndarray:
    """(T, 6 * len(joints)) positions relative to the pelvis and scaled velocities, in heights."""
    rel = (track.joints_m[:, joints] - track.pelvis_m[:, None]) / track.height_m
    vel = np.gradient(track.joints_m[:, joints], track.dt_s, axis=0) / track.height_m
    feats = np.concatenate([rel, vel * settings.speed_feature_time_s], axis=2)
    return feats.reshape(len(feats), -1) / np.sqrt(len(joints))


def compute_saliency(track: CharacterTrack, parts: BodyPartMap, settings: OverviewSettings) -> Saliency:
    """Pose saliency and limb saliency of a character track (see the module docstring)."""
    every_joint = np.arange(track.joints_m.shape[1])
    raw, curve, smooth = _curve_distance(_features(track, every_joint, settings), settings, track.dt_s)
    pose = raw / max(float(raw.max()), 1e-12)
    limb_raw = np.stack(
        [_curve_distance(_features(track, parts.joints_of(p), settings), settings, track.dt_s)[0] for p in range(PART_COUNT)],
        axis=1,
    )
    total = np.maximum(limb_raw.sum(axis=1, keepdims=True), 1e-12)
    share = limb_raw / total
    contrast = limb_raw.max(axis=1) / np.maximum(limb_raw.mean(axis=1), 1e-12)
    weight = np.clip((contrast - 1.0) / (settings.limb_contrast_ratio - 1.0), 0.0, 1.0)[:, None]
    limbs = weight * share + (1.0 - weight) / PART_COUNT
    return Saliency(pose=pose, limbs=limbs, curve=curve, smooth_curve=smooth)
