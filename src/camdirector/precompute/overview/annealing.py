"""Quantum-annealing optimisation of one shot's camera path (paper Section 4).

"At each iteration in quantum annealing the selected path is replaced by a randomly selected
neighboring path whenever the latter has a lower energy E. [...] The neighborhood size starts
high, and is slowly reduced through the computation, until it is below a certain discretization
threshold. As an initial solution path we used the degenerated path, a static camera placed in the
best global location p: max_p sum_t S_p(t) V(p). The neighboring path is defined by L1 distance
metric between path positions." (after Apolloni et al. 1989).

Our choices:

* A neighbour displaces the path by a raised-cosine bump: a random displacement vector of L1 norm
  up to the neighbourhood size r, centred on a random frame, with a half-width drawn log-uniformly
  between the narrowest bump whose slope stays under the speed limit (r * pi / (2 S_max dt) frames)
  and the shot length; one neighbour in ten moves the whole shot rigidly.
* r falls geometrically from `initial_neighbourhood_heights` to `final_neighbourhood_heights`
  over `annealing_iterations_per_frame` * n proposals, and at least `annealing_min_iterations`:
  the paper gives no count, and the radius has as many decades to fall in a short shot as in a
  long one (at 6 per frame the run's 36 analysis frames got 216 proposals and ended anywhere
  between E = -9 and +375 by seed, where a static camera reaches -43).
* "The neighborhood size starts high": r0 is the candidate space's margin around the character
  (3.5 heights), so a rigid neighbour of the static start can cross that margin in one step; at
  1.5 heights the walk and the run kept a camera that pans past alpha_max where a static camera
  farther back has a lower E.
* A second start (ours): the paper's start maximises sum_t S_p V, and where the character
  travels that camera pans past alpha_max, so its E is high and the local search from it can end
  above a static camera standing farther back (the run: E -37.6 against -43.3). Where the
  annealed path ends above the lowest-E static camera of the shot, that camera is annealed too
  and the lower E wins, so no shot ends worse than a static camera. It costs one extra run only
  where needed (on the shared clips: the run, and the walk with some seeds).
* The paper calls the speed limit a hard constraint; besides E's c2 term we reject any neighbour
  in which the camera moves faster than S_max between two frames, leaves the allowed positions
  (potential.py: outside the character's box, far enough to frame the body, inside the grid), or
  puts a frame with a line-of-movement prior (shots.py) on the wrong side of that line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.energy import EnergyWeights, energy_below, internal_terms
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.potential import PotentialSpace, allowed_positions

_RIGID_MOVE_SHARE = 0.1  # share of proposals that translate the whole shot
_SPEED_SLACK = 1.0 - 1e-9  # a step may use the whole speed limit but for rounding
_STATIC_NODES_PER_CHUNK = 256  # static cameras whose E_internal is evaluated at once (memory: n x chunk x 3)


@dataclass(frozen=True)
class SidePrior:
    """The camera at track frame `frame` must lie on side `side` (+1 left, -1 right, looking
    along `direction_xz`) of the horizontal line through `point_xz` (a 'line of movement')."""

    frame: int
    point_xz: np.ndarray
    direction_xz: np.ndarray
    side: int

    def holds(self, position_m: np.ndarray) -> bool:
        rel = position_m[[0, 2]] - self.point_xz
        cross = self.direction_xz[0] * rel[1] - self.direction_xz[1] * rel[0]
        return bool(np.sign(cross) == self.side)

    def holds_for_nodes(self, positions_m: np.ndarray) -> np.ndarray:
        rel = positions_m[:, [0, 2]] - self.point_xz
        cross = self.direction_xz[0] * rel[:, 1] - self.direction_xz[1] * rel[:, 0]
        return np.sign(cross) == self.side


@dataclass(frozen=True)
class StaticCameras:
    """The static cameras a shot over track frames [first, last] may use: the grid nodes allowed
    in every one of its frames and meeting its priors. nodes (K,) int flat grid indices;
    position_m (K, 3); external (K,) E_external = -sum_t S_p(t) V_t(p) of each as one shot."""

    first: int
    last: int
    nodes: np.ndarray
    position_m: np.ndarray
    external: np.ndarray

    @classmethod
    def of_shot(
        cls, space: PotentialSpace, pose_saliency: np.ndarray, first: int, last: int, priors: tuple[SidePrior, ...] = ()
    ) -> StaticCameras:
        """Raises ValueError when no node is allowed in every frame and meets the priors."""
        ok = space.allowed[first : last + 1].reshape(last - first + 1, -1).all(axis=0)
        positions = space.positions()
        for prior in priors:
            ok &= prior.holds_for_nodes(positions)
        if not np.any(ok):
            raise ValueError(
                f"no static camera position frames the character over frames {first}..{last}: raise grid_margin_heights"
            )
        nodes = np.flatnonzero(ok)
        values = space.values[first : last + 1].reshape(last - first + 1, -1)[:, nodes]
        return cls(
            first=first,
            last=last,
            nodes=nodes,
            position_m=positions[nodes],
            external=-(pose_saliency[first : last + 1] @ values.astype(np.float64)),
        )

    def paper_start(self) -> np.ndarray:
        """(3,) the node maximising sum_t S_p(t) V_t(p): the paper's start."""
        return self.position_m[int(np.argmin(self.external))]

    def lowest_energy(self, track: CharacterTrack, weights: EnergyWeights) -> tuple[np.ndarray, float]:
        """The (3,) position and E of the static camera with the lowest E over the shot. Its
        E_internal is the angular terms of a camera that only turns."""
        look_at = track.look_at_m[self.first : self.last + 1]
        n = self.last - self.first + 1
        # E_internal >= 0: visiting nodes by increasing E_external, none after the first whose
        # E_external alone reaches the lowest E found can do better.
        best_i, best_e = -1, np.inf
        order = np.argsort(self.external, kind="stable")
        for start in range(0, len(order), _STATIC_NODES_PER_CHUNK):
            idx = order[start : start + _STATIC_NODES_PER_CHUNK]
            if self.external[idx[0]] >= best_e:
                break
            chunk = self.position_m[idx]
            paths = np.broadcast_to(chunk, (n,) + chunk.shape)
            total = internal_terms(paths, look_at, weights).sum(axis=0) + self.external[idx]
            k = int(np.argmin(total))
            if total[k] < best_e:
                best_i, best_e = int(idx[k]), float(total[k])
        return self.position_m[best_i], best_e


def anneal_shot(
    track: CharacterTrack,
    space: PotentialSpace,
    pose_saliency: np.ndarray,
    weights: EnergyWeights,
    settings: OverviewSettings,
    rng: np.random.Generator,
    first: int,
    last: int,
    priors: tuple[SidePrior, ...] = (),
) -> np.ndarray:
    """(last - first + 1, 3) optimised camera path over track frames [first, last], metres: the
    paper's start annealed, or, where that ends above the lowest-E static camera, the better of
    it and that camera annealed (module docstring)."""
    args = (track, space, pose_saliency, weights, settings, rng, first, last, priors)
    statics = StaticCameras.of_shot(space, pose_saliency, first, last, priors)
    path, energy = _anneal_from(statics.paper_start(), *args)
    low_start, low_energy = statics.lowest_energy(track, weights)
    if energy_below(low_energy, energy):
        low_path, low_path_energy = _anneal_from(low_start, *args)
        if energy_below(low_path_energy, energy):
            return low_path
    return path


def _anneal_from(
    start_m: np.ndarray,
    track: CharacterTrack,
    space: PotentialSpace,
    pose_saliency: np.ndarray,
    weights: EnergyWeights,
    settings: OverviewSettings,
    rng: np.random.Generator,
    first: int,
    last: int,
    priors: tuple[SidePrior, ...],
) -> tuple[np.ndarray, float]:
    """The path annealed from a static camera at start_m (3,) over frames [first, last], and its E."""
    n = last - first + 1
    path = np.tile(start_m, (n, 1))
    frames = np.arange(first, last + 1)
    look_at = track.look_at_m[first : last + 1]
    sal = pose_saliency[first : last + 1]
    if n < 2:
        return path, -float(np.dot(sal, space.sample(frames, path)))
    v_now = space.sample(frames, path)
    step_limit = weights.max_speed_m_s * weights.dt_s * _SPEED_SLACK
    local_priors = [(p.frame - first, p) for p in priors if first <= p.frame <= last]
    h = track.height_m
    r0, r1 = settings.initial_neighbourhood_heights * h, settings.final_neighbourhood_heights * h
    iterations = max(settings.annealing_min_iterations, int(round(settings.annealing_iterations_per_frame * n)))
    decay = (r1 / r0) ** (1.0 / iterations)
    radius = r0
    for _ in range(iterations):
        radius *= decay
        direction = rng.uniform(-1.0, 1.0, 3)
        displacement = direction * (radius * rng.uniform() / max(np.abs(direction).sum(), 1e-12))
        if rng.uniform() < _RIGID_MOVE_SHARE:
            lo, hi = 0, n - 1
            bump = np.ones(n)
        else:
            min_half = max(1.0, float(np.linalg.norm(displacement)) * math.pi / (2.0 * step_limit))
            max_half = max(min_half, float(n))
            half = math.exp(rng.uniform(math.log(min_half), math.log(max_half)))
            centre = rng.integers(0, n)
            lo, hi = max(0, int(math.ceil(centre - half))), min(n - 1, int(math.floor(centre + half)))
            offsets = (np.arange(lo, hi + 1) - centre) / half
            bump = 0.5 * (1.0 + np.cos(np.pi * np.clip(offsets, -1.0, 1.0)))
        new_seg = path[lo : hi + 1] + bump[:, None] * displacement
        if not np.all(allowed_positions(track, space, frames[lo : hi + 1], new_seg)):
            continue
        if any(lo <= k <= hi and not prior.holds(new_seg[k - lo]) for k, prior in local_priors):
            continue
        a, b = max(lo - 2, 0), min(hi + 2, n - 1)  # internal terms at lo-1..hi+1 change
        old_internal = internal_terms(path[a : b + 1], look_at[a : b + 1], weights).sum()
        trial = path[a : b + 1].copy()
        trial[lo - a : hi - a + 1] = new_seg
        steps = np.linalg.norm(np.diff(trial, axis=0), axis=1)
        if np.any(steps > step_limit):
            continue
        new_internal = internal_terms(trial, look_at[a : b + 1], weights).sum()
        v_new = space.sample(frames[lo : hi + 1], new_seg)
        delta = (new_internal - old_internal) - float(np.dot(sal[lo : hi + 1], v_new - v_now[lo : hi + 1]))
        if delta < 0.0:
            path[lo : hi + 1] = new_seg
            v_now[lo : hi + 1] = v_new
    return path, float(internal_terms(path, look_at, weights).sum() - np.dot(sal, v_now))
