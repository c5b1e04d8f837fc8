"""The four track filters of Section 4.4, applied in the order of `filter_sequence`.

#1 collision: the parts of a track that cross the level are cut out by iterative splitting: a
   piece whose segment is occluded is halved, down to `collision_min_piece_m` (those that still
   collide go), and the free pieces left of one track are merged where they touch. Supporting
   points follow the piece their projection falls in; the others lose their track.
#2 visibility: a point whose segment to its projection on its track is occluded loses its track.
#3 empty: tracks with fewer than `min_support_points` supporting points go (an earlier split can
   leave a piece with none).
#4 refit: one RANSAC step (random pairs of the track's own points, consensus within
   `ransac_threshold_m`, least-squares refit) gives each track its new line; the track spans its
   inliers' projections, and the outliers lose their track.

The default order ends with #1 and #3 again: a refit line may cross a wall the old one missed.
"""

from __future__ import annotations

import numpy as np

from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.ransac import Tracks, fit_line, line_distance
from camdirector.precompute.tracks.track_settings import TrackSettings

_MAX_SPLIT_ROUNDS = 24


def _project(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Parameters t (k,) in units of the track length of points (k, 3) on tracks (k, 3)-(k, 3)."""
    d = end - start
    length2 = np.einsum("ij,ij->i", d, d)
    return np.einsum("ij,ij->i", points - start, d) / np.where(length2 > 0.0, length2, 1.0)


def remove_collisions(tracks: Tracks, points: np.ndarray, scene: RayScene, settings: TrackSettings) -> Tracks:
    """Filter #1 (module docstring)."""
    owner = np.arange(len(tracks))
    lo, hi = np.zeros(len(tracks)), np.ones(len(tracks))
    length = tracks.length_m
    free_owner, free_lo, free_hi = [], [], []
    for _ in range(_MAX_SPLIT_ROUNDS):
        if not len(owner):
            break
        a = tracks.start_world[owner] + lo[:, None] * (tracks.end_world[owner] - tracks.start_world[owner])
        b = tracks.start_world[owner] + hi[:, None] * (tracks.end_world[owner] - tracks.start_world[owner])
        blocked = (length[owner] > 0.0) & scene.occluded(a, b)
        free_owner.append(owner[~blocked])
        free_lo.append(lo[~blocked])
        free_hi.append(hi[~blocked])
        split = blocked & ((hi - lo) * length[owner] > settings.collision_min_piece_m)
        mid = 0.5 * (lo[split] + hi[split])
        owner = np.concatenate([owner[split], owner[split]])
        lo, hi = np.concatenate([lo[split], mid]), np.concatenate([mid, hi[split]])
    owner, lo, hi = np.concatenate(free_owner), np.concatenate(free_lo), np.concatenate(free_hi)
    order = np.lexsort((lo, owner))
    owner, lo, hi = owner[order], lo[order], hi[order]
    new_run = np.ones(len(owner), dtype=bool)
    new_run[1:] = (owner[1:] != owner[:-1]) | ~np.isclose(lo[1:], hi[:-1])
    run_owner, run_lo = owner[new_run], lo[new_run]
    run_hi = np.maximum.reduceat(hi, np.flatnonzero(new_run)) if len(hi) else hi
    start = tracks.start_world[run_owner] + run_lo[:, None] * (tracks.end_world[run_owner] - tracks.start_world[run_owner])
    end = tracks.start_world[run_owner] + run_hi[:, None] * (tracks.end_world[run_owner] - tracks.start_world[run_owner])

    point_track = np.full(len(points), -1, dtype=np.int64)
    supported = np.flatnonzero(tracks.point_track >= 0)
    if len(supported) and len(run_owner):
        old = tracks.point_track[supported]
        t = np.clip(_project(points[supported], tracks.start_world[old], tracks.end_world[old]), 0.0, 1.0)
        run = np.maximum(np.searchsorted(run_owner * 4.0 + run_lo, old * 4.0 + t + 1e-9, side="right") - 1, 0)
        inside = (run_owner[run] == old) & (t <= run_hi[run] + 1e-9)
        point_track[supported[inside]] = run[inside]
    return Tracks(start, end, point_track)


def remove_hidden_points(tracks: Tracks, points: np.ndarray, scene: RayScene) -> Tracks:
    """Filter #2 (module docstring)."""
    supported = np.flatnonzero(tracks.point_track >= 0)
    track = tracks.point_track[supported]
    start, end = tracks.start_world[track], tracks.end_world[track]
    t = np.clip(_project(points[supported], start, end), 0.0, 1.0)
    foot = start + t[:, None] * (end - start)
    apart = np.linalg.norm(foot - points[supported], axis=1) > 1e-6
    hidden = np.zeros(len(supported), dtype=bool)
    hidden[apart] = scene.occluded(points[supported][apart], foot[apart])
    point_track = tracks.point_track.copy()
    point_track[supported[hidden]] = -1
    return Tracks(tracks.start_world, tracks.end_world, point_track)


def remove_empty(tracks: Tracks, settings: TrackSettings) -> Tracks:
    """Filter #3 (module docstring)."""
    support = np.bincount(tracks.point_track[tracks.point_track >= 0], minlength=len(tracks))
    keep = support >= settings.min_support_points
    new_index = np.full(len(tracks) + 1, -1, dtype=np.int64)
    new_index[np.flatnonzero(keep)] = np.arange(keep.sum())
    return Tracks(tracks.start_world[keep], tracks.end_world[keep], new_index[tracks.point_track])


def refit(tracks: Tracks, points: np.ndarray, settings: TrackSettings, rng: np.random.Generator) -> Tracks:
    """Filter #4 (module docstring)."""
    start, end = tracks.start_world.copy(), tracks.end_world.copy()
    point_track = tracks.point_track.copy()
    order = np.argsort(point_track, kind="stable")
    bounds = np.searchsorted(point_track[order], np.arange(len(tracks) + 1))
    for k in range(len(tracks)):
        members = order[bounds[k] : bounds[k + 1]]
        if len(members) < 2:
            continue
        own = points[members]
        i = rng.integers(0, len(own), size=settings.ransac_hypotheses)
        j = rng.integers(0, len(own), size=settings.ransac_hypotheses)
        delta = own[j] - own[i]
        length = np.linalg.norm(delta, axis=1)
        ok = length > 1e-9
        if ok.any():
            origins, directions = own[i[ok]], delta[ok] / length[ok, None]
            d = own[None, :, :] - origins[:, None, :]
            along = np.einsum("hsk,hk->hs", d, directions)
            dist2 = np.einsum("hsk,hsk->hs", d, d) - along * along
            best = int(np.argmax((dist2 < settings.ransac_threshold_m**2).sum(axis=1)))
            inlier = line_distance(own, origins[best], directions[best]) < settings.ransac_threshold_m
        else:
            inlier = np.ones(len(own), dtype=bool)
        if inlier.sum() < 1:
            continue
        origin, direction = fit_line(own[inlier])
        t = (own[inlier] - origin) @ direction
        start[k], end[k] = origin + t.min() * direction, origin + t.max() * direction
        point_track[members[~inlier]] = -1
    return Tracks(start, end, point_track)


def filter_tracks(
    tracks: Tracks, points_world: np.ndarray, scene: RayScene, settings: TrackSettings, rng: np.random.Generator
) -> Tracks:
    """Filters of `settings.filter_sequence` in order; points_world (n, 3) are the samples the
    tracks' `point_track` refers to."""
    for number in settings.filter_sequence:
        if number == 1:
            tracks = remove_collisions(tracks, points_world, scene, settings)
        elif number == 2:
            tracks = remove_hidden_points(tracks, points_world, scene)
        elif number == 3:
            tracks = remove_empty(tracks, settings)
        else:
            tracks = refit(tracks, points_world, settings, rng)
    return tracks
