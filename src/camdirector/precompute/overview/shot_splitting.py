"""Iterative shot splitting (paper Section 4).

"The relative quality of a given camera location for a given frame Q(p_t) is expressed by the
ratio V_t(p_t) / max_p(V_t). [...] A low path quality (in our case below 70% of the average
saliency) motivates the separation into shots. [...] The shots split frame t_split is selected by
locating the lowest quality Q(p_t) frame among the sufficiently low saliency (in our case below
80%) frames. We avoid splits which generate short shots. [...] we enforce this restriction [not
crossing the line of movement] to the camera locations in neighboring frames in the two shots by
adding a hard 'line of movement' side prior [...] we apply the optimization with priors on both
sides, and select the solution with the better viewpoint quality." Up to 6 shots per 1000 frames.

Our reading of the ambiguous parts:

* "below 70% of the average saliency": a shot's quality is the saliency-weighted mean of Q,
  sum S_p Q / sum S_p; a shot is split while that is below `split_quality` (0.7).
* "below 80%" saliency: frames with S_p < `split_max_saliency` (0.8; S_p is in [0, 1]).
* The worst shot is split first; a split is kept only if it lowers the shot's energy E (the paper:
  splitting "potentially can improve the total energy"); a shot that cannot be split is left.
* The cut falls between t_split and t_split + 1: the first shot ends at t_split, the second starts
  at t_split + 1, and the side prior holds at both of those frames. Priors found earlier stay.
* The line of movement is the horizontal line through the look-at point at t_split along the
  character's velocity; when the character moves slower than `moving_speed_heights_s` / 2 it
  has no line of movement of its own and we use its facing direction (the line of action).
* "better viewpoint quality": the larger saliency-weighted quality over the two new shots.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from camdirector.precompute.overview.annealing import SidePrior, anneal_shot
from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.energy import EnergyWeights, internal_terms
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.potential import PotentialSpace


@dataclass(frozen=True)
class ShotPlan:
    """path_m: (T, 3) camera position per track frame; shots: (S, 2) int [first, last] track
    frames; quality_history: (iterations, T) Q per frame after the first optimisation and after
    each kept split (the paper's Figure 9); shots_history: the shots after each of those."""

    path_m: np.ndarray
    shots: np.ndarray
    quality_history: np.ndarray
    shots_history: tuple[np.ndarray, ...]


def frame_quality(space: PotentialSpace, path_m: np.ndarray) -> np.ndarray:
    """(T,) Q(p_t) = V_t(p_t) / max_p V_t."""
    frames = np.arange(len(path_m))
    return space.sample(frames, path_m) / np.maximum(space.best, 1e-12)


def shot_quality(quality: np.ndarray, pose_saliency: np.ndarray, first: int, last: int) -> float:
    """Saliency-weighted mean of Q over frames [first, last]."""
    s = pose_saliency[first : last + 1]
    return float(np.dot(s, quality[first : last + 1]) / max(float(s.sum()), 1e-12))


def _shot_energy(
    path_m: np.ndarray,
    track: CharacterTrack,
    space: PotentialSpace,
    pose_saliency: np.ndarray,
    w: EnergyWeights,
    first: int,
    last: int,
) -> float:
    frames = np.arange(first, last + 1)
    internal = internal_terms(path_m, track.look_at_m[first : last + 1], w).sum()
    return float(internal - np.dot(pose_saliency[first : last + 1], space.sample(frames, path_m)))


def _line_of_movement(track: CharacterTrack, t: int, settings: OverviewSettings) -> tuple[np.ndarray, np.ndarray]:
    velocity = track.velocity_m_s[t, [0, 2]]
    speed = float(np.linalg.norm(velocity))
    if speed >= 0.5 * settings.moving_speed_heights_s * track.height_m:
        direction = velocity / speed
    else:
        direction = track.forward[t, [0, 2]]
    return track.look_at_m[t, [0, 2]], direction


def plan_shots(
    track: CharacterTrack,
    space: PotentialSpace,
    pose_saliency: np.ndarray,
    weights: EnergyWeights,
    settings: OverviewSettings,
    rng: np.random.Generator,
    max_shots: int,
) -> ShotPlan:
    """Optimise one shot over the whole clip, then split while shots are of low quality."""
    n = track.frame_count
    min_len = max(2, int(round(settings.min_shot_s / track.dt_s)))
    path = anneal_shot(track, space, pose_saliency, weights, settings, rng, 0, n - 1)
    shots: list[tuple[int, int]] = [(0, n - 1)]
    priors: list[SidePrior] = []
    final: set[tuple[int, int]] = set()
    quality = frame_quality(space, path)
    history, shots_history = [quality], [np.array(shots)]
    while len(shots) < max_shots:
        open_shots = [
            (shot_quality(quality, pose_saliency, a, b), (a, b))
            for a, b in shots
            if (a, b) not in final and b - a + 1 >= 2 * min_len
        ]
        open_shots = [item for item in open_shots if item[0] < settings.split_quality]
        if not open_shots:
            break
        _, (a, b) = min(open_shots)
        candidates = np.arange(a + min_len - 1, b - min_len + 1)  # t_split: last of shot one
        candidates = candidates[pose_saliency[candidates] < settings.split_max_saliency]
        if len(candidates) == 0:
            final.add((a, b))
            continue
        t_split = int(candidates[np.argmin(quality[candidates])])
        point, direction = _line_of_movement(track, t_split, settings)
        inherited = tuple(p for p in priors if a <= p.frame <= b)
        best = None
        for side in (1, -1):
            new_priors = (SidePrior(t_split, point, direction, side), SidePrior(t_split + 1, point, direction, side))
            try:
                first_path = anneal_shot(track, space, pose_saliency, weights, settings, rng, a, t_split, inherited + new_priors)
                second_path = anneal_shot(
                    track, space, pose_saliency, weights, settings, rng, t_split + 1, b, inherited + new_priors
                )
            except ValueError:
                continue  # no static start on this side of the line
            trial = path.copy()
            trial[a : t_split + 1] = first_path
            trial[t_split + 1 : b + 1] = second_path
            q = frame_quality(space, trial)
            score = shot_quality(q, pose_saliency, a, b)
            if best is None or score > best[0]:
                best = (score, trial, new_priors)
        if best is None:
            final.add((a, b))
            continue
        _, trial, new_priors = best
        before = _shot_energy(path[a : b + 1], track, space, pose_saliency, weights, a, b)
        after = _shot_energy(trial[a : t_split + 1], track, space, pose_saliency, weights, a, t_split) + _shot_energy(
            trial[t_split + 1 : b + 1], track, space, pose_saliency, weights, t_split + 1, b
        )
        if after >= before:
            final.add((a, b))
            continue
        path = trial
        priors.extend(new_priors)
        shots.remove((a, b))
        shots.extend([(a, t_split), (t_split + 1, b)])
        shots.sort()
        quality = frame_quality(space, path)
        history.append(quality)
        shots_history.append(np.array(shots))
    return ShotPlan(
        path_m=path, shots=np.array(shots, dtype=np.int64), quality_history=np.array(history), shots_history=tuple(shots_history)
    )
