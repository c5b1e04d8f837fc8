"""Sequential RANSAC line clustering of the camera samples into camera tracks (Section 4.3).

Samples are clustered per sampling direction (eye level left, eye level right, high angle left,
..., the skeleton points): our choice, since one cloud of all directions yields lines that cut
across the corridors through dense spots, where one direction's samples line up with the
skeleton they were cast from, the tracks the paper shows (Figures 5 to 7). Each cloud then goes
through the paper's sequential RANSAC: the consensus set of a line mu over the points P is
CS(mu, P, eps) = {p in P | R(mu, p) < eps} with R the point-to-line distance and eps =
`ransac_threshold_m`. Each step takes, over all the points left, the hypothesis with the largest
consensus set of `ransac_hypotheses`, refits it by least squares (principal axis) on that set,
removes the set from P and runs again on the rest, until `ransac_max_lines` lines (the paper's
iteration count, which it leaves open) or until the best set has fewer than
`ransac_min_inliers` points (our stopping rule, the usual one of sequential RANSAC: the points
left stay unclustered). Largest consensus first is what makes the tracks long: the line along a
corridor takes its samples before any short chord across them can.

Our deviation, documented: the model is a track, a segment, so a hypothesis' consensus set is
the largest run of its inliers along the line with no gap over `max_inlier_gap_m` (the other
inliers stay in P for later lines). The paper relies on filter #1 to cut a line where it runs
through a wall between two groups of inliers (Section 4.4, Figure 7); on levels open to the sky
(nav_test, zdm2) nothing lies between the high-angle samples of two far corridors, and the pure
line model strings five samples over 60 m into one "track" across the level, again and again
(nav_test: 1636 nodes and 2281 edges, against 617 and 556 with 4 m gaps, at 0.998 against 0.995
coverage). 4 m is under three ray spacings along the skeleton: a doorway does not cut a track.
(An earlier version grew each line in a 15 m window around a random seed, in random order, and
short chords broke the corridors' lines into pieces a few metres long.)

Static cameras (our completion of the paper's first requirement, "populating the environment
with static cameras observing large areas", Section 1): a skeleton component, a room or a
corridor piece cut off by the layers, none of whose samples supports a track (it is too short
for `ransac_min_inliers` collinear samples) gets one static camera, its sample furthest from the
skeleton (the widest view); the graph keeps it as a lone node (Section 4.6 i).

Our choices, documented: a hypothesis joins a random remaining point to a random remaining one
of its 32 nearest neighbours within `ransac_pair_radius_m` (local sampling, as NAPSAC: a pair
from opposite ends of the level almost never lies on a track); when more than
`ransac_score_subsample` points are left, hypotheses are pre-scored on that many of them and the
16 best have their runs measured on all, so a step costs O(n) as the paper wants.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from camdirector.precompute.tracks.track_settings import TrackSettings

_NEIGHBOURS = 32
_EXACT_SCORED = 16  # best pre-scored hypotheses whose runs of inliers are measured on every alive point


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


def neighbour_table(points: np.ndarray, radius_m: float) -> np.ndarray:
    """(n, 32) int indices of each point's nearest other points within radius_m (n where fewer)."""
    k = min(_NEIGHBOURS + 1, len(points))
    if k < 2:
        return np.full((len(points), _NEIGHBOURS), len(points), dtype=np.int64)
    _, idx = cKDTree(points).query(points, k=k, distance_upper_bound=radius_m)
    idx = idx[:, 1:]
    if idx.shape[1] < _NEIGHBOURS:
        idx = np.hstack([idx, np.full((len(points), _NEIGHBOURS - idx.shape[1]), len(points))])
    return idx


def _hypotheses(
    points: np.ndarray,
    alive_idx: np.ndarray,
    alive: np.ndarray,
    neighbours: np.ndarray,
    count: int,
    min_separation_m: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Up to `count` lines (origins (h, 3), unit directions (h, 3)) through a random alive point
    and a random alive one of its neighbours."""
    first = rng.choice(alive_idx, size=count)
    second = neighbours[first, rng.integers(0, neighbours.shape[1], size=count)]
    valid = second < len(points)
    first, second = first[valid], second[valid]
    valid = alive[second]
    first, second = first[valid], second[valid]
    delta = points[second] - points[first]
    length = np.linalg.norm(delta, axis=1)
    valid = length > min_separation_m
    return points[first[valid]], delta[valid] / length[valid, None]


def _inlier_counts(points: np.ndarray, origins: np.ndarray, directions: np.ndarray, threshold_m: float) -> np.ndarray:
    """(h,) number of points (s, 3) within threshold_m of each line (h, 3)-(h, 3)."""
    d = points[None, :, :] - origins[:, None, :]  # (h, s, 3)
    along = np.einsum("hsk,hk->hs", d, directions)
    dist2 = np.einsum("hsk,hsk->hs", d, d) - along * along
    return (dist2 < threshold_m**2).sum(axis=1)


def largest_run(t: np.ndarray, max_gap_m: float) -> np.ndarray:
    """Indices into t (k,) of the largest run of its sorted values with no step over max_gap_m."""
    order = np.argsort(t)
    runs = np.split(order, np.flatnonzero(np.diff(t[order]) > max_gap_m) + 1)
    return max(runs, key=len)


def _segment_inliers(
    points: np.ndarray, candidates: np.ndarray, origin: np.ndarray, direction: np.ndarray, settings: TrackSettings
) -> np.ndarray:
    """The consensus set of a track on the line origin + t direction: the largest run of the
    candidates within `ransac_threshold_m` of it (module docstring), as indices into points."""
    near = candidates[line_distance(points[candidates], origin, direction) < settings.ransac_threshold_m]
    if not len(near):
        return near
    return near[largest_run((points[near] - origin) @ direction, settings.max_inlier_gap_m)]


def ransac_line(
    points: np.ndarray, alive: np.ndarray, neighbours: np.ndarray, settings: TrackSettings, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """One RANSAC step over the alive points: (origin (3,), unit direction (3,), inlier indices
    into points) of the track with the largest consensus set, refitted by least squares, or None
    when no hypothesis can be drawn.

    points (n, 3); alive (n,) bool; neighbours: `neighbour_table` of the points.
    """
    alive_idx = np.flatnonzero(alive)
    if len(alive_idx) < 2:
        return None
    origins, directions = _hypotheses(
        points, alive_idx, alive, neighbours, settings.ransac_hypotheses, settings.ransac_threshold_m, rng
    )
    if not len(origins):
        return None
    subset = (
        alive_idx
        if len(alive_idx) <= settings.ransac_score_subsample
        else rng.choice(alive_idx, size=settings.ransac_score_subsample, replace=False)
    )
    rough = _inlier_counts(points[subset], origins, directions, settings.ransac_threshold_m)
    best, inliers = None, np.empty(0, np.int64)
    for h in np.argsort(-rough, kind="stable")[:_EXACT_SCORED].tolist():  # the line's count bounds its run's
        if rough[h] * len(alive_idx) / len(subset) < 0.5 * len(inliers):
            break
        run = _segment_inliers(points, alive_idx, origins[h], directions[h], settings)
        if len(run) > len(inliers):
            best, inliers = h, run
    origin, direction = origins[best], directions[best]
    if len(inliers) >= 2:
        fitted = fit_line(points[inliers])
        refit = _segment_inliers(points, alive_idx, *fitted, settings)
        if len(refit) >= len(inliers):
            (origin, direction), inliers = fitted, refit
    return origin, direction, inliers


def cluster_tracks(points_world: np.ndarray, group: np.ndarray, settings: TrackSettings, rng: np.random.Generator) -> Tracks:
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
    return Tracks(
        np.asarray(starts, dtype=np.float64).reshape(-1, 3), np.asarray(ends, dtype=np.float64).reshape(-1, 3), point_track
    )


def add_static_cameras(tracks: Tracks, points_world: np.ndarray, origin_world: np.ndarray, component: np.ndarray) -> Tracks:
    """Tracks plus one static camera (a track of one point) for every skeleton component none of
    whose samples supports a track: its sample furthest from its ray origin (module docstring).

    points_world, origin_world (n, 3): the samples and the skeleton points they were cast from;
    component (n,) int: the skeleton component of each sample's origin.
    """
    supported = np.zeros(component.max() + 1 if len(component) else 0, dtype=bool)
    supported[component[tracks.point_track >= 0]] = True
    reach = np.linalg.norm(points_world - origin_world, axis=1)
    picks = []
    for c in np.flatnonzero(~supported):
        own = np.flatnonzero(component == c)
        if len(own):
            picks.append(int(own[np.argmax(reach[own])]))
    if not picks:
        return tracks
    point_track = tracks.point_track.copy()
    point_track[picks] = len(tracks) + np.arange(len(picks))
    return Tracks(
        np.vstack([tracks.start_world, points_world[picks]]), np.vstack([tracks.end_world, points_world[picks]]), point_track
    )


def _sequential_ransac(points: np.ndarray, max_lines: int, settings: TrackSettings, rng: np.random.Generator) -> Tracks:
    n = len(points)
    point_track = np.full(n, -1, dtype=np.int64)
    starts: list[npt.NDArray[np.float64]] = []
    ends: list[npt.NDArray[np.float64]] = []
    alive = np.ones(n, dtype=bool)
    neighbours = neighbour_table(points, settings.ransac_pair_radius_m)
    while len(starts) < max_lines and alive.sum() >= settings.ransac_min_inliers:
        found = ransac_line(points, alive, neighbours, settings, rng)
        if found is None or len(found[2]) < settings.ransac_min_inliers:
            break  # the best line left is too weak: the rest stays unclustered
        origin, direction, inliers = found
        t = (points[inliers] - origin) @ direction
        point_track[inliers] = len(starts)
        starts.append(origin + t.min() * direction)
        ends.append(origin + t.max() * direction)
        alive[inliers] = False
    return Tracks(
        np.asarray(starts, dtype=np.float64).reshape(-1, 3), np.asarray(ends, dtype=np.float64).reshape(-1, 3), point_track
    )
