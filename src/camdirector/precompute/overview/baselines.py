"""The reference paths of the paper's comparison (Section 5, Figure 10).

* Best static camera: "To normalize the results in each of the terms, we selected the best
  attribute score that can be achieved without any camera movement for each clip". Per attribute,
  over every candidate node allowed in every frame: the lowest E (its E_internal is the angular
  terms of a camera that only turns), the lowest E_external (argmax sum_t S_p(t) V_t(p): the same
  static camera that starts the annealing, annealing.py) and the highest sum_t V_t(p). On a clip
  where the character travels these are three different cameras: the one with the best views
  pans faster than alpha_max as the character passes, the one with the lowest E stands back.
* Per-frame greedy, smoothed afterwards (standing in for the paper's Halper et al. comparison, as
  the issue asks): every frame takes its best allowed node, argmax_p V_t(p), and the path is then
  smoothed by a Gaussian of sigma `greedy_smoothing_s` (our choice, 1 s). It is one shot and is
  not projected back onto the allowed positions or the speed limit: that is what makes it a
  baseline, and E's speed terms charge it for any excess.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from camdirector.precompute.overview.annealing import StaticCameras
from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.energy import EnergyWeights
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.potential import PotentialSpace


@dataclass(frozen=True)
class BestStatic:
    """The best score a single static camera reaches on each attribute over the whole clip (one
    shot), and the node reaching it: e (lowest E), e_external (lowest E_external), v_sum (highest
    sum_t V); *_position_m: (3,) metres."""

    e: float
    e_external: float
    v_sum: float
    e_position_m: np.ndarray
    e_external_position_m: np.ndarray
    v_position_m: np.ndarray


def static_path(space: PotentialSpace, pose_saliency: np.ndarray) -> np.ndarray:
    """(T, 3) the static camera with the lowest E_external (the annealing's start) at every frame."""
    n = len(pose_saliency)
    return np.tile(StaticCameras.of_shot(space, pose_saliency, 0, n - 1).paper_start(), (n, 1))


def best_static(track: CharacterTrack, space: PotentialSpace, pose_saliency: np.ndarray, weights: EnergyWeights) -> BestStatic:
    """Each attribute's best static camera among nodes allowed in every frame (module docstring).
    Scores are those `energy.path_energy` gives the static path as one shot."""
    n = track.frame_count
    statics = StaticCameras.of_shot(space, pose_saliency, 0, n - 1)
    v_sum = space.values.reshape(n, -1)[:, statics.nodes].astype(np.float64).sum(axis=0)
    e_position, e = statics.lowest_energy(track, weights)
    i_x, i_v = int(np.argmin(statics.external)), int(np.argmax(v_sum))
    return BestStatic(
        e=e,
        e_external=float(statics.external[i_x]),
        v_sum=float(v_sum[i_v]),
        e_position_m=e_position,
        e_external_position_m=statics.position_m[i_x],
        v_position_m=statics.position_m[i_v],
    )


def greedy_path(track: CharacterTrack, space: PotentialSpace, settings: OverviewSettings) -> np.ndarray:
    """(T, 3) the per-frame best allowed node, smoothed in time."""
    n = track.frame_count
    values = np.where(space.allowed, space.values, -np.inf).reshape(n, -1)
    best = space.positions()[np.argmax(values, axis=1)]
    return gaussian_filter1d(best, settings.greedy_smoothing_s / track.dt_s, axis=0, mode="nearest")
