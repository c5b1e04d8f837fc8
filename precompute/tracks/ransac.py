"""Sequential RANSAC line clustering of the camera samples into camera tracks (Section 4.3).

Samples are clustered per sampling direction (eye level left, eye level right, high angle left,
..., the skeleton points): our choice, since one cloud of all directions yields lines that cut
across the corridors through dense spots, where one direction's samples line up with the
skeleton they were cast from, the tracks the paper shows (Figures 5 to 7). Each cloud then goes
through the paper's sequential RANSAC: the consensus set of a line mu over the points P is CS(mu, P, eps) = {p in P | R(mu, p) < eps}
with R the point-to-line distance and eps = `ransac_threshold_m`. The best line's inliers are
removed from P and RANSAC runs again on the rest, until `ransac_max_lines` lines (the paper's
iteration count) or until the best line has fewer than `ransac_min_inliers` inliers.

Our choices, documented: a hypothesis joins a random remaining point to one of its 16 nearest
remaining neighbours within `ransac_pair_radius_m` (local sampling: a pair from opposite ends of
the level almost never lies on a track); each round works in the window of `ransac_window_m`
around a random remaining seed point (its `ransac_hypotheses` hypotheses and consensus are taken
there, scored on at most `ransac_score_subsample` of its points), so a round costs the same on
any level and the whole clustering stays O(n) as the paper wants; a round whose best line has
fewer than `ransac_min_inliers` inliers retires its seed point unclustered. The winner is
refitted by least squares (principal axis) on its consensus set. A line's inliers are cut into separate tracks where two consecutive
ones along the line are more than `max_inlier_gap_m` apart: one line model through two rooms is
two tracks; a lone point cut off this way stays unclustered.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from camdirector.precompute.tracks.settings import TrackSettings

_NEIGHBOURS = 16


@dataclass(frozen=True)
class Tracks:
    """Linear camera tracks: start_world, end_world (t, 3) metres (equal for a static camera);
    point_track: (n,) int, the track each camera sample supports, -1 for none."""

    start_world: np.ndarray
    end_world: np.ndarray
    point_track: np.ndarray

    def __len__(self) -> int:
        return len(self.start_world)

    @property
    def length_m(self) -> np.ndarray:
        return np.linalg.norm(self.end_world - self.start_world, axis=1)


def fit_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares line of points (k, 3): (centroid (3,), unit direction (3,)); any direction
    for a single point."""
    centroid = points.mean(axis=0)
    if len(points) < 2:
        return centroid, np.array([1.0, 0.0, 0.0])
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    return centroid, vt[0]


def line_distance(points: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Distances (k,) of points (k, 3) to the line origin + t direction (unit)."""
    d = points - origin
    return np.linalg.norm(d - (d @ direction)[:, None] * direction, axis=1)


def split_at_gaps(t: np.ndarray, max_gap: float) -> list[np.ndarray]:
    """Indices into t (k,) of the runs of sorted parameters no further apart than max_gap."""
    order = np.argsort(t)
    cuts = np.flatnonzero(np.diff(t[order]) > max_gap) + 1
    return np.split(order, cuts)


def _hypotheses(points: np.ndarray, alive: np.ndarray, neighbours: np.ndarray, candidates: np.ndarray,
                count: int, min_separation: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Up to `count` lines (origins (h, 3), unit directions (h, 3)) through pairs of alive points."""
    first = rng.choice(candidates, size=count)
    column = rng.integers(0, neighbours.shape[1], size=count)
    second = neighbours[first, column]
    valid = second < len(points)
    first, second = first[valid], second[valid]
    valid = alive[second]
    first, second = first[valid], second[valid]
    delta = points[second] - points[first]
    length = np.linalg.norm(delta, axis=1)
    valid = length > min_separation
    return points[first[valid]], delta[valid] / length[valid, None]


def ransac_line(points: np.ndarray, candidates: np.ndarray, neighbours: np.ndarray, alive: np.ndarray,
                settings: TrackSettings, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """One RANSAC step over the candidate points: (origin (3,), unit direction (3,), inlier indices
    into points) of the best line refitted on its consensus set, or None when no hypothesis can be
    drawn.

    points (n, 3); candidates (c,) int alive indices; neighbours (n, k) int nearest-neighbour
    table (n = missing); alive (n,) bool.
    """
    if len(candidates) < 2:
        return None
    origins, directions = _hypotheses(points, alive, neighbours, candidates, settings.ransac_hypotheses,
                                      settings.ransac_threshold_m, rng)
    if not len(origins):
        return None
    subset = candidates if len(candidates) <= settings.ransac_score_subsample else \
        rng.choice(candidates, size=settings.ransac_score_subsample, replace=False)
    d = points[subset][None, :, :] - origins[:, None, :]                       # (h, s, 3)
    along = np.einsum("hsk,hk->hs", d, directions)
    dist2 = np.einsum("hsk,hsk->hs", d, d) - along * along
    best = int(np.argmax((dist2 < settings.ransac_threshold_m ** 2).sum(axis=1)))
    origin, direction = origins[best], directions[best]
    inliers = candidates[line_distance(points[candidates], origin, direction) < settings.ransac_threshold_m]
    if len(inliers) >= 2:
        origin, direction = fit_line(points[inliers])
        refit = candidates[line_distance(points[candidates], origin, direction) < settings.ransac_threshold_m]
        if len(refit) >= len(inliers):
            inliers = refit
    return origin, direction, inliers


def neighbour_table(points: np.ndarray, radius_m: float) -> np.ndarray:
    """(n, 16) int indices of each point's nearest other points within radius_m (n where fewer)."""
    if len(points) < 2:
        return np.full((len(points), _NEIGHBOURS), len(points), dtype=np.int64)
    k = min(_NEIGHBOURS + 1, len(points))
    _, idx = cKDTree(points).query(points, k=k, distance_upper_bound=radius_m)
    idx = idx[:, 1:]
    if idx.shape[1] < _NEIGHBOURS:
        idx = np.hstack([idx, np.full((len(points), _NEIGHBOURS - idx.shape[1]), len(points))])
    return idx


def cluster_tracks(points_world: np.ndarray, group: np.ndarray, settings: TrackSettings,
                   rng: np.random.Generator) -> Tracks:
    """Sequential RANSAC over camera samples (n, 3) metres, run separately on each group of
    samples (n,) int (the sampling direction): the module docstring's tracks."""
    points = np.asarray(points_world, dtype=np.float64)
    point_track = np.full(len(points), -1, dtype=np.int64)
    starts: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    for g in np.unique(group):
        members = np.flatnonzero(group == g)
        own = _sequential_ransac(points[members], settings.ransac_max_lines - len(starts), settings, rng)
        assigned = own.point_track >= 0
        point_track[members[assigned]] = own.point_track[assigned] + len(starts)
        starts.extend(own.start_world)
        ends.extend(own.end_world)
    return Tracks(np.asarray(starts, dtype=np.float64).reshape(-1, 3),
                  np.asarray(ends, dtype=np.float64).reshape(-1, 3), point_track)


def _sequential_ransac(points: np.ndarray, max_lines: int, settings: TrackSettings,
                       rng: np.random.Generator) -> Tracks:
    n = len(points)
    point_track = np.full(n, -1, dtype=np.int64)
    starts, ends = [], []
    alive = np.ones(n, dtype=bool)
    alive_count = n
    neighbours = neighbour_table(points, settings.ransac_pair_radius_m)
    tree = cKDTree(points) if n else None
    while len(starts) < max_lines and alive_count >= settings.ransac_min_inliers:
        seed = rng.choice(np.flatnonzero(alive)) if alive_count < n // 8 or alive_count < 64 else \
            _random_alive(alive, rng)
        window = np.asarray(tree.query_ball_point(points[seed], settings.ransac_window_m), dtype=np.int64)
        window = window[alive[window]]
        found = ransac_line(points, window, neighbours, alive, settings, rng)
        if found is None or len(found[2]) < settings.ransac_min_inliers:
            alive[seed] = False  # no line through this point's surroundings: it stays unclustered
            alive_count -= 1
            continue
        origin, direction, inliers = found
        t = (points[inliers] - origin) @ direction
        for run in split_at_gaps(t, settings.max_inlier_gap_m):
            if len(run) < 2:
                continue  # a lone point cut off by a gap stays unclustered
            point_track[inliers[run]] = len(starts)
            starts.append(origin + t[run].min() * direction)
            ends.append(origin + t[run].max() * direction)
        alive[inliers] = False
        alive_count -= len(inliers)
    return Tracks(np.asarray(starts, dtype=np.float64).reshape(-1, 3),
                  np.asarray(ends, dtype=np.float64).reshape(-1, 3), point_track)


def _random_alive(alive: np.ndarray, rng: np.random.Generator) -> int:
    """A uniformly random alive index by rejection (cheap while most points are alive)."""
    while True:
        i = int(rng.integers(0, len(alive)))
        if alive[i]:
            return i
