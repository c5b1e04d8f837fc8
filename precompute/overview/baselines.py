"""The two reference paths of the paper's comparison (Section 5, Figure 10).

* Best static camera: "the best attribute score that can be achieved without any camera movement
  for each clip"; the node maximising sum_t S_p(t) V_t(p) among those allowed in every frame (the
  same static camera that starts the annealing, annealing.py).
* Per-frame greedy, smoothed afterwards (standing in for the paper's Halper et al. comparison, as
  the issue asks): every frame takes its best allowed node, argmax_p V_t(p), and the path is then
  smoothed by a Gaussian of sigma `greedy_smoothing_s` (our choice, 1 s). It is one shot and is
  not projected back onto the allowed positions or the speed limit: that is what makes it a
  baseline, and E's speed terms charge it for any excess.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from camdirector.precompute.overview.annealing import best_static_position
from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.potential import PotentialSpace
from camdirector.precompute.overview.settings import OverviewSettings


def static_path(space: PotentialSpace, pose_saliency: np.ndarray) -> np.ndarray:
    """(T, 3) the best static camera at every track frame."""
    n = len(pose_saliency)
    return np.tile(best_static_position(space, pose_saliency, 0, n - 1), (n, 1))


def greedy_path(track: CharacterTrack, space: PotentialSpace, settings: OverviewSettings
                ) -> np.ndarray:
    """(T, 3) the per-frame best allowed node, smoothed in time."""
    n = track.frame_count
    values = np.where(space.allowed, space.values, -np.inf).reshape(n, -1)
    best = space.positions()[np.argmax(values, axis=1)]
    return gaussian_filter1d(best, settings.greedy_smoothing_s / track.dt_s, axis=0,
                             mode="nearest")
