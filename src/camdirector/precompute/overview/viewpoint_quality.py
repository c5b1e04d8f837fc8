"""Viewpoint quality V of camera positions at frames (paper Section 3).

    V = sum_generic E_desc + (1 - S_p) * E_wide + S_p * sum_limbs S_limb * E_limb

Generic descriptors (after Halper et al. 2001; the paper does not define them, "due to space
limitations", so the forms below are ours, each in [0, 1]):

* three-quarter view: exp(-((|phi| - 45 deg) / 45 deg)^2), phi the horizontal angle between the
  character's front and the direction to the camera (front 0.37, three-quarter 1, side 0.37,
  back 0.0001);
* perpendicular to motion: w * (1 - |cos theta|), theta the horizontal angle between the
  character's velocity and the direction to the camera, w = min(1, speed /
  `moving_speed_heights_s`) so that a character standing still has no motion direction;
* distance: exp(-ln(d / d*)^2 / (2 sigma^2)) with d* = `preferred_distance_heights` and
  sigma = `distance_tolerance_log`;
* occlusion by static scene objects, only when a scene is given: the fraction of the character's
  sample points (pelvis and the tips of head, arms, legs) that a ray from the camera reaches
  before any scene triangle. Computed every `_OCCLUSION_STEP_S` and held in between.

Widest aspect E_wide: PCA of the body points; the third eigenvector is the normal of the plane
with the largest projection; E_wide = |cos| of the angle between it and the view direction.
"When the third eigenvalue is significantly high [...] the descriptor is not considered": we
weigh it by clip(1 - (lambda3/lambda2) / `wide_max_eigen_ratio`, 0, 1), which drops it smoothly.

Limb term: E_limb is read from limb_visibility.py's renders by bilinear interpolation in the
direction from the look-at point to the camera. Frames that were not rendered (pose saliency below
`limb_min_saliency`) use E_wide in place of the limb term.
"""

from __future__ import annotations

import numpy as np

from camdirector.precompute.overview.body_parts import BodyPart, BodyPartMap
from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.limb_visibility import LimbVisibility
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.saliency import Saliency

_OCCLUSION_STEP_S = 0.5  # occlusion by the static scene is computed this often, s


def three_quarter_view(
    track: CharacterTrack, frames: np.ndarray, positions_m: np.ndarray, settings: OverviewSettings
) -> np.ndarray:
    """(len(frames), P) descriptor in [0, 1] of (P, 3) camera positions."""
    to_cam = positions_m[None, :, [0, 2]] - track.look_at_m[frames][:, None, [0, 2]]
    to_cam /= np.maximum(np.linalg.norm(to_cam, axis=2, keepdims=True), 1e-9)
    cos_phi = np.einsum("tpk,tk->tp", to_cam, track.forward[frames][:, [0, 2]])
    phi_deg = np.degrees(np.arccos(np.clip(cos_phi, -1.0, 1.0)))
    return np.exp(-(((phi_deg - settings.three_quarter_angle_deg) / settings.three_quarter_width_deg) ** 2))


def perpendicular_to_motion(
    track: CharacterTrack, frames: np.ndarray, positions_m: np.ndarray, settings: OverviewSettings
) -> np.ndarray:
    """(len(frames), P) descriptor in [0, 1]: 1 when the camera looks across the motion."""
    velocity = track.velocity_m_s[frames][:, [0, 2]]
    speed = np.linalg.norm(velocity, axis=1)
    weight = np.minimum(1.0, speed / (settings.moving_speed_heights_s * track.height_m))
    direction = velocity / np.maximum(speed, 1e-9)[:, None]
    to_cam = positions_m[None, :, [0, 2]] - track.look_at_m[frames][:, None, [0, 2]]
    to_cam /= np.maximum(np.linalg.norm(to_cam, axis=2, keepdims=True), 1e-9)
    cos_theta = np.abs(np.einsum("tpk,tk->tp", to_cam, direction))
    return weight[:, None] * (1.0 - cos_theta)


def distance_preference(
    track: CharacterTrack, frames: np.ndarray, positions_m: np.ndarray, settings: OverviewSettings
) -> np.ndarray:
    """(len(frames), P) descriptor in [0, 1]: 1 at the preferred distance."""
    d = np.linalg.norm(positions_m[None] - track.look_at_m[frames][:, None], axis=2)
    preferred = settings.preferred_distance_heights * track.height_m
    return np.exp(-(np.log(np.maximum(d, 1e-6) / preferred) ** 2) / (2.0 * settings.distance_tolerance_log**2))


def widest_aspect(track: CharacterTrack, frames: np.ndarray, positions_m: np.ndarray, settings: OverviewSettings) -> np.ndarray:
    """(len(frames), P) E_wide in [0, 1] from the PCA of the body points."""
    pts = track.points_m[frames]
    centred = pts - pts.mean(axis=1, keepdims=True)
    cov = np.einsum("tki,tkj->tij", centred, centred) / pts.shape[1]
    values, vectors = np.linalg.eigh(cov)  # ascending eigenvalues
    normal = vectors[:, :, 0]  # (T, 3) third principal axis
    ratio = values[:, 0] / np.maximum(values[:, 1], 1e-12)
    weight = np.clip(1.0 - ratio / settings.wide_max_eigen_ratio, 0.0, 1.0)
    view = positions_m[None] - track.look_at_m[frames][:, None]
    view /= np.maximum(np.linalg.norm(view, axis=2, keepdims=True), 1e-9)
    return weight[:, None] * np.abs(np.einsum("tpk,tk->tp", view, normal))


def limb_visibility_term(
    track: CharacterTrack, frames: np.ndarray, positions_m: np.ndarray, saliency: Saliency, limbs: LimbVisibility
) -> np.ndarray:
    """(len(frames), P) sum over body parts of S_limb * E_limb, bilinear in view direction;
    0 in frames that were not rendered (`viewpoint_quality` puts E_wide there)."""
    rows = limbs.row_of_frame[frames]
    out = np.zeros((len(frames), len(positions_m)))
    have = rows >= 0
    if not np.any(have):
        return out
    f_sel = frames[have]
    view = positions_m[None] - track.look_at_m[f_sel][:, None]  # (Tr, P, 3)
    dist = np.maximum(np.linalg.norm(view, axis=2), 1e-9)
    az = np.mod(np.arctan2(view[..., 0], view[..., 2]), 2.0 * np.pi)
    el = np.arcsin(np.clip(view[..., 1] / dist, -1.0, 1.0))
    n_az = len(limbs.azimuths_rad)
    fa = az / (2.0 * np.pi / n_az)
    a0 = np.floor(fa).astype(np.int64) % n_az
    a1 = (a0 + 1) % n_az
    wa = fa - np.floor(fa)
    fe = np.interp(el, limbs.elevations_rad, np.arange(len(limbs.elevations_rad)))
    e0 = np.minimum(np.floor(fe).astype(np.int64), len(limbs.elevations_rad) - 2)
    we = fe - e0
    # Weighted sum over parts first: (Tr, n_el, n_az) table per frame.
    table = np.einsum("tl,tlea->tea", saliency.limbs[f_sel], limbs.normalised[rows[have]])
    t = np.arange(len(f_sel))[:, None]
    value = (1 - we) * ((1 - wa) * table[t, e0, a0] + wa * table[t, e0, a1]) + we * (
        (1 - wa) * table[t, e0 + 1, a0] + wa * table[t, e0 + 1, a1]
    )
    out[have] = value
    return out


def occlusion_sample_points(track: CharacterTrack, parts: BodyPartMap) -> np.ndarray:
    """(T, 6, 3) pelvis and the last joint of head, arms and legs, metres."""
    ends = []
    for part in (BodyPart.HEAD, BodyPart.LEFT_ARM, BodyPart.RIGHT_ARM, BodyPart.LEFT_LEG, BodyPart.RIGHT_LEG):
        ends.append(parts.joints_of(part)[-1])
    return np.concatenate([track.pelvis_m[:, None], track.joints_m[:, ends]], axis=1)


def scene_visibility(
    track: CharacterTrack, parts: BodyPartMap, positions_m: np.ndarray, scene, settings: OverviewSettings
) -> np.ndarray:
    """(T, P) fraction of the character's sample points seen from each position past a static
    `scene` (a trimesh.Trimesh); computed every `_OCCLUSION_STEP_S` and held between."""
    step = max(1, int(round(_OCCLUSION_STEP_S / track.dt_s)))
    keys = np.arange(0, track.frame_count, step)
    targets = occlusion_sample_points(track, parts)[:, : settings.occlusion_points]
    out_keys = np.empty((len(keys), len(positions_m)))
    for i, t in enumerate(keys):
        origins = np.repeat(positions_m, targets.shape[1], axis=0)
        ends = np.tile(targets[t], (len(positions_m), 1))
        rays = ends - origins
        length = np.linalg.norm(rays, axis=1)
        dirs = rays / np.maximum(length, 1e-9)[:, None]
        _, ray_ids, hits = scene.ray.intersects_id(origins, dirs, multiple_hits=False, return_locations=True)
        blocked = np.zeros(len(origins), dtype=bool)
        if len(ray_ids):
            hit_dist = np.linalg.norm(hits - origins[ray_ids], axis=1)
            blocked[ray_ids[hit_dist < length[ray_ids]]] = True
        out_keys[i] = 1.0 - blocked.reshape(len(positions_m), -1).mean(axis=1)
    return out_keys[np.minimum(np.arange(track.frame_count) // step, len(keys) - 1)]


def viewpoint_quality(
    track: CharacterTrack,
    frames: np.ndarray,
    positions_m: np.ndarray,
    saliency: Saliency,
    limbs: LimbVisibility,
    settings: OverviewSettings,
    visibility: np.ndarray | None = None,
) -> np.ndarray:
    """(len(frames), P) V of (P, 3) positions at track frames `frames` (see module docstring).

    visibility: (T, P) scene visibility of these positions, or None without a scene."""
    wide = widest_aspect(track, frames, positions_m, settings)
    limb = limb_visibility_term(track, frames, positions_m, saliency, limbs)
    limb = np.where((limbs.row_of_frame[frames] >= 0)[:, None], limb, wide)
    s_p = saliency.pose[frames][:, None]
    v = (
        three_quarter_view(track, frames, positions_m, settings)
        + perpendicular_to_motion(track, frames, positions_m, settings)
        + distance_preference(track, frames, positions_m, settings)
        + (1.0 - s_p) * wide
        + s_p * limb
    )
    if visibility is not None:
        v = v + visibility[frames]
    return v
