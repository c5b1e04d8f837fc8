"""Redundant camera tracks, dropped before the graph is built (our stage; the paper has none).

Why: the paper keeps every filtered track (Section 4.4). Where walls are few (open, rolling
terrain), eye-level rays cast orthogonally to the skeleton hit nothing, their samples sit at
d_max, and RANSAC joins them into many short chords and near-parallel tracks that all see the
same open ground. The director needs a camera that sees the actor and, for cuts, an alternative
one; it does not need ten.

How: every track is sampled where the graph will put its nodes (its two ends and the points
splitting it into pieces no longer than `max_edge_length_m`; a static camera is its one
point), and those points get the same Monte Carlo visibility estimate as the final graph
(visibility_table.py, Section 4.5, up to `visibility_range_m`) against the remeshed navmesh. A
track sees the union of the triangles its points see, and sees a triangle *near* when one of its
points that sees it is within `redundancy_range_m` of the triangle's centroid. Tracks are then
considered from the one seeing the fewest triangles (shortest first among equals) to the one
seeing the most, and a track is dropped when
  - every triangle it sees is seen by at least one other kept track, and
  - every triangle it sees near is seen near by at least `redundancy_k` other kept tracks.
So every triangle seen before the pass is still seen after it (coverage is unchanged, up to the
Monte Carlo estimate of the final table and the intersection nodes the rebuilt graph loses), and every
triangle seen near by n tracks still is by min(n, `redundancy_k`): the director keeps a camera
close enough to frame the actor and alternatives to cut to. The longest, most-seeing tracks are
the last candidates, so they are the ones kept. A track that sees no triangle is dropped.
`redundancy_k` = 0 keeps every track (the paper's graph).

Measured (eval-graph on the four shared levels, against the graph without this stage): with the
default range of 5 m, inside the default long shot's framing tolerance (violated past about
5.4 m: 2.7 m optimum, framing_violation_log 0.7), nodes fall 1.7 to 2 times at unchanged coverage
and the cut rate stays (dungeon 218 -> 128 nodes, nav_test 637 -> 346, undulating 882 -> 497,
zdm2 1433 -> 696). A range of 9 m drops 3 to 4 times the nodes, but the director then finds too
few cameras close enough to keep the shot and cuts about four times as often (nav_test 62 -> 235
cuts on one route): not a trade a director would make.

Where this stops: on undulating (open, rolling terrain) every one of the 217 tracks kept is
*forced*: each is one of at most `redundancy_k` tracks that see some triangle near. A greedy
weighted set multicover (most unmet demand per graph node first, then a reverse-delete pass),
tried in place of the order above, kept the same 217, so no choice of tracks can go lower under
this rule; only the rule (k, range) or the sampling can. That is why our graph there (497 nodes)
stays above a PRM at equal coverage (about 315), whose coverage counts a triangle seen from 15 m.

Connectivity: dropping a track can split a chain of tracks into components; the director
follows edges only within a shot and cuts between components (graph distance is a sub-score,
not a constraint), and the graph stage links components again where they come close (step iii).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.graph import edge_pieces
from camdirector.precompute.tracks.ransac import Tracks
from camdirector.precompute.tracks.track_settings import TrackSettings
from camdirector.precompute.tracks.visibility_table import build_visibility_table


def track_points(tracks: Tracks, max_edge_length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Points (p, 3) where the graph puts each track's nodes before intersections (its ends and
    equal pieces no longer than max_edge_length_m; one point for a static camera), and the track
    (p,) int of each."""
    length = tracks.length_m
    pieces = edge_pieces(length, max_edge_length_m)
    count = np.where(length > 1e-9, pieces + 1, 1)
    owner = np.repeat(np.arange(len(tracks)), count)
    step = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
    frac = np.where(count[owner] > 1, step / np.maximum(count[owner] - 1, 1), 0.0)
    start, end = tracks.start_world[owner], tracks.end_world[owner]
    return start + frac[:, None] * (end - start), owner


def prune_redundant_tracks(
    tracks: Tracks, refined: TriMesh, scene: RayScene, settings: TrackSettings, rng: np.random.Generator
) -> Tracks:
    """Tracks (module docstring) with the redundant ones dropped; `point_track` is renumbered,
    -1 for the samples of dropped tracks."""
    k = settings.redundancy_k
    if k == 0 or len(tracks) == 0 or refined.triangle_count == 0:
        return tracks
    points, owner = track_points(tracks, settings.max_edge_length_m)
    table = build_visibility_table(points, refined, scene, settings, rng)
    point_of_pair = np.repeat(np.arange(len(points)), np.diff(table.node_indptr))
    triangle = table.node_triangles.astype(np.int64)
    centroid = refined.vertices[refined.faces].mean(axis=1)
    near = np.linalg.norm(centroid[triangle] - points[point_of_pair], axis=1) <= settings.redundancy_range_m
    # columns: every triangle seen (kept by one other track), then those seen from near (by k others)
    n_tris = table.triangle_count
    column = np.concatenate([triangle, n_tris + triangle[near]])
    row = np.concatenate([owner[point_of_pair], owner[point_of_pair[near]]])
    sees = sparse.csr_matrix((np.ones(len(row), np.int32), (row, column)), shape=(len(tracks), 2 * n_tris))
    sees.sum_duplicates()
    sees.data[:] = 1
    others_needed = np.concatenate([np.ones(n_tris, np.int64), np.full(n_tris, k, np.int64)])
    seen_count = np.diff(sees.indptr)
    seers = np.asarray(sees.sum(axis=0)).ravel().astype(np.int64)  # kept tracks seeing each column
    keep = np.ones(len(tracks), dtype=bool)
    for t in np.lexsort((tracks.length_m, seen_count)):
        seen = sees.indices[sees.indptr[t] : sees.indptr[t + 1]]
        if np.all(seers[seen] > others_needed[seen]):  # enough others besides t
            keep[t] = False
            seers[seen] -= 1
    new_index = np.full(len(tracks) + 1, -1, dtype=np.int64)
    new_index[np.flatnonzero(keep)] = np.arange(keep.sum())
    return Tracks(tracks.start_world[keep], tracks.end_world[keep], new_index[tracks.point_track])
