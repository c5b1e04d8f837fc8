"""Navmesh, skeleton, sampling, RANSAC, filters, graph and visibility table on tiny hand-built levels."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.filters import filter_tracks, refit, remove_collisions, remove_empty, remove_hidden_points
from camdirector.precompute.tracks.graph import build_graph, insert_tracks
from camdirector.precompute.tracks.navmesh import derive_navmesh, triangle_areas
from camdirector.precompute.tracks.pipeline import Stage, precompute_level
from camdirector.precompute.tracks.ransac import Tracks, cluster_tracks
from camdirector.precompute.tracks.sampling import sample_cameras
from camdirector.precompute.tracks.skeleton import extract_skeleton
from camdirector.precompute.tracks.track_settings import TrackSettings
from camdirector.precompute.tracks.visibility_table import build_visibility_table, remesh

from .tiny_levels import boxes, corridor, l_room, two_floors

SETTINGS = TrackSettings()


def _directions(segments):
    d = segments[:, 1] - segments[:, 0]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_corridor_navmesh_is_the_floor_eroded_by_the_agent_radius():
    level = corridor()
    nav = derive_navmesh(level, RayScene([level]), SETTINGS)
    assert np.allclose(nav.vertices[:, 1], 0.0)
    z = nav.vertices[:, 2]
    assert z.min() >= SETTINGS.agent_radius_m - SETTINGS.navmesh_cell_m and z.max() <= 4.0 - 0.3
    assert 0.5 * 30 * 4 < triangle_areas(nav.vertices, nav.faces).sum() <= 30 * 4


def test_corridor_gives_one_skeleton_line_and_tracks_parallel_to_it():
    level = corridor()
    scene = RayScene([level])
    nav = derive_navmesh(level, scene, SETTINGS)
    skeleton = extract_skeleton(nav, SETTINGS)
    seg = skeleton.segments_world
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    along = np.abs(_directions(seg)[:, 0]) > 0.999
    main = int(np.argmax(length))
    assert skeleton.layer_count == 1
    assert along[main] and length[main] > 0.8 * 30.0, "one skeleton line runs down the corridor"
    assert np.allclose(seg[main, :, 2], 2.0, atol=0.1), "on the centre line (within the outline simplification)"
    assert length[along].sum() > 0.9 * length.sum(), "only short spurs at the two ends besides it"
    samples = sample_cameras(skeleton, scene, SETTINGS)
    tracks = cluster_tracks(samples.position_world, samples.group, SETTINGS, np.random.default_rng(0))
    long = tracks.length_m > 5.0
    assert long.sum() >= 4
    assert np.all(np.abs(_directions(np.stack([tracks.start_world, tracks.end_world], 1)[long])[:, 0]) > 0.99)


def test_corridor_gives_one_long_track_per_direction_not_many_short_ones():
    level = corridor()
    scene = RayScene([level])
    skeleton = extract_skeleton(derive_navmesh(level, scene, SETTINGS), SETTINGS)
    samples = sample_cameras(skeleton, scene, SETTINGS)
    rng = np.random.default_rng(0)
    tracks = filter_tracks(
        cluster_tracks(samples.position_world, samples.group, SETTINGS, rng), samples.position_world, scene, SETTINGS, rng
    )
    groups = len(np.unique(samples.group))
    assert len(tracks) <= groups, "at most one track per sampling direction and side"
    assert np.all(tracks.length_m > 0.8 * skeleton.length_m), "each runs the corridor's length"
    graph = build_graph(tracks, scene, SETTINGS)
    pieces = int(np.ceil(tracks.length_m.max() / SETTINGS.max_edge_length_m))
    assert len(graph.nodes_world) <= groups * (pieces + 1)


def _corridor_with_niches(depth=1.5):
    """The 30 x 4 corridor with three 2 m wide niches `depth` deep in its z = 0 wall."""
    parts = [((0, -0.2, -depth - 0.1), (30, 0, 4)), ((0, 0, 4), (30, 3, 4.1))]
    xs = [0, 6, 8, 14, 16, 22, 24, 30]
    parts += [((a, 0, -0.1), (b, 3, 0)) for a, b in zip(xs[0::2], xs[1::2])]
    for a, b in zip(xs[1::2], xs[2::2]):
        parts += [((a, 0, -depth - 0.1), (b, 3, -depth)), ((a - 0.1, 0, -depth), (a, 3, 0)), ((b, 0, -depth), (b + 0.1, 3, 0))]
    return boxes(*parts)


def test_skeleton_prunes_spokes_into_wall_niches_but_keeps_the_corridor():
    level = _corridor_with_niches(depth=1.0)
    nav = derive_navmesh(level, RayScene([level]), SETTINGS)
    skeleton = extract_skeleton(nav, SETTINGS)
    length = np.linalg.norm(skeleton.segments_world[:, 1] - skeleton.segments_world[:, 0], axis=1)
    assert length.max() > 0.8 * 30.0 and np.abs(_directions(skeleton.segments_world)[np.argmax(length), 0]) > 0.99
    assert len(length) <= 3, "one line down the corridor, no branch into each niche"
    unpruned = extract_skeleton(nav, TrackSettings(skeleton_prune_m=0.0, skeleton_line_tolerance_m=0.0))
    assert len(unpruned.segments_world) > 3


def test_skeleton_fills_sliver_holes():
    room = shapely.Polygon([(0, 0), (20, 0), (20, 6), (0, 6)], [[(10, 2.95), (10.1, 2.95), (10.1, 3.05), (10, 3.05)]])
    xz = np.asarray([np.asarray(t.exterior.coords)[:3] for t in shapely.constrained_delaunay_triangles(room).geoms])
    vertices = np.insert(xz.reshape(-1, 2), 1, 0.0, axis=1)
    nav = TriMesh(vertices, np.arange(len(vertices)).reshape(-1, 3).astype(np.int32))
    skeleton = extract_skeleton(nav, SETTINGS)
    assert len(skeleton.segments_world) == 1 and np.isclose(skeleton.length_m, 14.0, atol=0.1), "the room's centre line"
    ringed = extract_skeleton(nav, TrackSettings(skeleton_min_hole_m2=0.0))
    assert ringed.length_m > skeleton.length_m + 1.0, "kept, the 1 cm^2 hole rings the skeleton with a loop"


def test_l_room_skeleton_has_both_arms():
    level = l_room()
    nav = derive_navmesh(level, RayScene([level]), SETTINGS)
    d = _directions(extract_skeleton(nav, SETTINGS).segments_world)
    assert (np.abs(d[:, 0]) > 0.99).any() and (np.abs(d[:, 2]) > 0.99).any()


def test_two_overlapping_floors_keep_their_heights():
    level = two_floors()
    nav = derive_navmesh(level, RayScene([level]), SETTINGS)
    heights = np.unique(np.round(nav.vertices[:, 1], 1))
    assert set(heights.tolist()) == {0.0, 4.0}
    skeleton = extract_skeleton(nav, SETTINGS)
    assert skeleton.layer_count >= 2
    y = skeleton.segments_world[:, :, 1]
    assert np.all(np.isclose(y, 0.0, atol=1e-6) | np.isclose(y, 4.0, atol=1e-6))
    assert np.isclose(y, 4.0).any() and np.isclose(y, 0.0).any()


def test_ransac_finds_two_synthetic_lines():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 10, 40)
    a = np.stack([t, np.zeros_like(t), np.zeros_like(t)], 1)
    b = np.stack([np.zeros_like(t) + 5, t, np.zeros_like(t) + 5], 1)
    pts = np.vstack([a, b]) + rng.normal(0, 0.02, (80, 3))
    tracks = cluster_tracks(pts, np.zeros(80, int), SETTINGS, np.random.default_rng(0))
    assert len(tracks) == 2
    assert np.all(tracks.point_track >= 0)
    assert set(tracks.point_track[:40]) != set(tracks.point_track[40:])
    assert np.allclose(sorted(tracks.length_m), [10, 10], atol=0.2)


def test_ransac_takes_the_longest_track_first_and_does_not_bridge_gaps():
    rng = np.random.default_rng(4)
    along = np.stack([np.arange(0.0, 30.0, 1.5), np.zeros(20), np.zeros(20)], 1)  # a corridor's line
    across = np.stack([np.full(5, 9.0), np.zeros(5), np.arange(-3.0, 4.5, 1.5)], 1)  # a short chord over it
    far = np.stack([np.arange(50.0, 56.0, 1.5), np.zeros(4), np.zeros(4)], 1)  # collinear, 20 m further
    pts = np.vstack([along, across, far]) + rng.normal(0, 0.02, (29, 3))
    tracks = cluster_tracks(pts, np.zeros(len(pts), int), SETTINGS, np.random.default_rng(0))
    longest = int(np.argmax(tracks.length_m))
    assert np.isclose(tracks.length_m[longest], 28.5, atol=0.2), "the corridor's line is one track"
    assert set(np.flatnonzero(tracks.point_track == longest)) >= set(range(20)) - {6}  # the chord crosses at x = 9
    assert tracks.length_m.max() < 40.0, "no track bridges the 20 m gap to the far points"


def test_filters_cut_collisions_drop_hidden_points_and_empty_tracks():
    wall = boxes(((4.9, -5, -5), (5.1, 5, 5)))
    scene = RayScene([wall])
    pts = np.stack([np.linspace(0, 10, 21), np.zeros(21), np.zeros(21)], 1)
    tracks = Tracks(np.array([[0.0, 0, 0]]), np.array([[10.0, 0, 0]]), np.zeros(21, int))
    cut = remove_collisions(tracks, pts, scene, SETTINGS)
    assert len(cut) == 2
    assert not scene.occluded(cut.start_world, cut.end_world).any()
    assert cut.point_track[10] == -1  # at the wall
    off = np.array([[2.0, 0, 1.0], [8.0, 0, 1.0]])
    behind = Tracks(np.array([[4.0, 0, -1.0]]), np.array([[6.0, 0, -1.0]]), np.array([0, 0]))
    hidden = remove_hidden_points(Tracks(np.array([[0.0, 0, 0]]), np.array([[4.0, 0, 0]]), np.array([0, 0])), off, scene)
    assert hidden.point_track.tolist() == [0, -1]
    assert len(remove_empty(Tracks(behind.start_world, behind.end_world, np.array([-1, -1])), SETTINGS)) == 0
    noisy = np.vstack([pts[:8], [[3.0, 0, 2.0]]])
    refitted = refit(
        Tracks(np.array([[0.0, 0, 0]]), np.array([[3.0, 0, 2.0]]), np.zeros(9, int)), noisy, SETTINGS, np.random.default_rng(0)
    )
    assert refitted.point_track[-1] == -1
    assert np.allclose(refitted.end_world[0, 1:], 0.0, atol=1e-6)


def test_graph_joins_crossing_tracks_splits_and_links():
    tracks = Tracks(
        np.array([[0.0, 2, 5], [5, 2, 0], [20, 2, 0]]), np.array([[10.0, 2, 5], [5, 2, 10], [20, 2, 10]]), np.zeros(0, int)
    )
    nodes, edges = insert_tracks(tracks, SETTINGS)
    assert len(nodes) == 7 and len(edges) == 5  # the cross shares its centre node
    graph = build_graph(
        tracks, RayScene([boxes(((100, 0, 100), (101, 1, 101)))]), TrackSettings(max_edge_length_m=2.0, link_distance_m=12.0)
    )
    assert graph.edge_length_m[~graph.edge_is_link].max() <= 2.0 + 1e-9
    adjacency = sparse.coo_matrix((np.ones(len(graph.edges)), tuple(graph.edges.T)), shape=(len(graph.nodes_world),) * 2)
    assert connected_components(adjacency, directed=False)[0] == 1
    assert graph.edge_is_link.any()


def test_graph_does_not_link_through_a_wall():
    tracks = Tracks(np.array([[0.0, 1, 0], [2, 1, 0]]), np.array([[0.0, 1, 10], [2, 1, 10]]), np.zeros(0, int))
    wall = boxes(((0.9, -5, -5), (1.1, 5, 15)))
    graph = build_graph(tracks, RayScene([wall]), SETTINGS)
    adjacency = sparse.coo_matrix((np.ones(len(graph.edges)), tuple(graph.edges.T)), shape=(len(graph.nodes_world),) * 2)
    assert connected_components(adjacency, directed=False)[0] == 2


def test_visibility_table_agrees_with_direct_ray_casts():
    level = boxes(((0, -0.2, 0), (20, 0, 20)), ((9.8, 0, 0), (10.2, 6, 20)))  # a floor halved by a high wall
    scene = RayScene([level])
    nav = derive_navmesh(level, scene, SETTINGS)
    skeleton = extract_skeleton(nav, SETTINGS)
    refined = remesh(nav, skeleton, SETTINGS)
    assert triangle_areas(refined.vertices, refined.faces).max() <= SETTINGS.max_triangle_area_m2 + 1e-9
    nodes = np.array([[5.0, 2.0, 10.0], [15.0, 2.0, 10.0]])
    table = build_visibility_table(nodes, refined, scene, SETTINGS, np.random.default_rng(0))
    lift = SETTINGS.visibility_target_height_fraction * 2.0 * np.array([0, 1, 0])
    centroid = refined.vertices[refined.faces].mean(axis=1) + lift
    for node in range(2):
        row = slice(table.node_indptr[node], table.node_indptr[node + 1])
        seen = set(table.node_triangles[row].tolist())
        in_range = np.linalg.norm(centroid - nodes[node], axis=1) <= SETTINGS.visibility_range_m
        direct = ~scene.occluded(nodes[node], centroid) & in_range
        clear_side = (
            (refined.vertices[refined.faces][:, :, 0] < 9.5).all(1)
            if node == 0
            else (refined.vertices[refined.faces][:, :, 0] > 10.5).all(1)
        )
        assert set(np.flatnonzero(direct & clear_side)) <= seen
        assert not (seen & set(np.flatnonzero(~direct & ~clear_side & in_range)))
    # both directions of the table hold the same pairs
    by_tri = sparse.csc_matrix(
        (table.triangle_degree, table.triangle_nodes, table.triangle_indptr), shape=(2, table.triangle_count)
    )
    by_node = sparse.csr_matrix((table.node_degree, table.node_triangles, table.node_indptr), shape=(2, table.triangle_count))
    assert (by_tri != by_node).nnz == 0


def test_pipeline_times_every_stage_and_reports_progress():
    seen = []
    artifact = precompute_level(corridor(), SETTINGS, np.random.default_rng(0), progress=seen.append)
    assert list(artifact.timings_ms) == [s.value for s in Stage]
    assert seen == sorted(seen) and seen[-1] == 1.0
    assert artifact.counts["nodes"] == len(artifact.nodes_world) > 0


def test_settings_refuse_out_of_range_values():
    with pytest.raises(ValueError, match="agent_height_m"):
        TrackSettings(agent_height_m=0.0)
    with pytest.raises(ValueError, match="filter_sequence"):
        TrackSettings(filter_sequence=(5,))
