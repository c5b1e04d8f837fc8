"""Redundant tracks (redundancy.py) and the sampling footprint on tiny hand-built levels."""

from __future__ import annotations

import numpy as np

from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.navmesh import derive_navmesh
from camdirector.precompute.tracks.ransac import Tracks
from camdirector.precompute.tracks.redundancy import prune_redundant_tracks, track_points
from camdirector.precompute.tracks.sampling import inside_footprint
from camdirector.precompute.tracks.skeleton import extract_skeleton
from camdirector.precompute.tracks.track_settings import TrackSettings
from camdirector.precompute.tracks.visibility_table import build_visibility_table, remesh

from .tiny_levels import two_open_floors

SETTINGS = TrackSettings(redundancy_range_m=9.0)  # the big floor is 8 m wide: every track there sees all of it near
EYE_M = 1.8


def _level():
    level = two_open_floors()
    scene = RayScene([level])
    nav = derive_navmesh(level, scene, SETTINGS)
    return scene, nav, remesh(nav, extract_skeleton(nav, SETTINGS), SETTINGS)


def _tracks():
    """Four long parallel tracks over the big floor, a short one between them (redundant), and a
    short one over the small floor, the only track that sees it (needed)."""
    start = np.array([[1, EYE_M, 2], [1, EYE_M, 3], [1, EYE_M, 5], [1, EYE_M, 6], [9, EYE_M, 4], [2, EYE_M, 33]], float)
    end = np.array([[19, EYE_M, 2], [19, EYE_M, 3], [19, EYE_M, 5], [19, EYE_M, 6], [11, EYE_M, 4], [4, EYE_M, 33]], float)
    point_track = np.array([0, 0, 1, 2, 3, 4, 4, 5, -1])
    return Tracks(start, end, point_track)


def test_a_redundant_track_is_dropped_and_the_only_one_seeing_a_floor_is_kept():
    scene, _, refined = _level()
    tracks = _tracks()
    kept = prune_redundant_tracks(tracks, refined, scene, SETTINGS, np.random.default_rng(0))
    kept_starts = {tuple(p) for p in kept.start_world}
    assert (9.0, EYE_M, 4.0) not in kept_starts  # the short track in the middle of the parallel ones
    assert (2.0, EYE_M, 33.0) in kept_starts  # the small floor's only camera
    # k = 2: two of the four identical long tracks stay, so the director can cut between them
    assert len(kept) == 1 + SETTINGS.redundancy_k
    # samples of dropped tracks support none; those of kept tracks follow their renumbered track
    for sample, old in enumerate(tracks.point_track):
        new = kept.point_track[sample]
        if old < 0 or tuple(tracks.start_world[old]) not in kept_starts:
            assert new == -1
        else:
            assert np.array_equal(kept.start_world[new], tracks.start_world[old])


def test_pruning_keeps_what_the_tracks_saw():
    scene, _, refined = _level()
    tracks = _tracks()
    kept = prune_redundant_tracks(tracks, refined, scene, SETTINGS, np.random.default_rng(0))

    def seen(t):
        points, _ = track_points(t, SETTINGS.max_edge_length_m)
        return build_visibility_table(points, refined, scene, SETTINGS, np.random.default_rng(1)).seen_triangles()

    before, after = seen(tracks), seen(kept)
    assert before.mean() > 0.9
    assert np.all(after[before])


def test_redundancy_k_zero_keeps_every_track():
    scene, _, refined = _level()
    tracks = _tracks()
    settings = TrackSettings(redundancy_k=0, redundancy_range_m=9.0)
    kept = prune_redundant_tracks(tracks, refined, scene, settings, np.random.default_rng(0))
    assert len(kept) == len(tracks)


def test_samples_beyond_the_footprint_margin_are_outside():
    _, nav, _ = _level()
    margin = SETTINGS.footprint_margin_m
    points = np.array(
        [[10, EYE_M, 4], [10, EYE_M, 8 + margin + 1.0], [10, EYE_M, 8 + 0.5 * margin], [3, 0, 33], [30, 0, 4]], float
    )
    assert inside_footprint(points, nav, margin).tolist() == [True, False, True, True, False]
