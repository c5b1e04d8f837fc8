"""nav_test.obj (RecastDemo) end to end: the precompute, the route of Recast's test cases, and the
comparison with PRMs (one precompute for the module). Times are measured, not asserted:
`python -m load_tests.tracks_bench` (under 30 s per level, target update under 2 ms)."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.evaluation.tracks.compare import PRM_MAX_DENSITY_PER_M2, PRM_MAX_NODES, compare_with_prm
from camdirector.evaluation.tracks.route import NavmeshPaths, read_recast_queries, walk
from camdirector.geometry.meshes import TriMesh
from camdirector.precompute.tracks.level_mesh import load_level_mesh
from camdirector.precompute.tracks.pipeline import Stage, precompute_level
from camdirector.precompute.tracks.track_settings import TrackSettings


@pytest.fixture(scope="module")
def nav_test(shared_data):
    mesh = load_level_mesh(shared_data / "levels" / "recast" / "nav_test.obj", 1.0)
    artifact = precompute_level(mesh, TrackSettings(), np.random.default_rng(0))
    return artifact, shared_data


@pytest.mark.shared_data
def test_nav_test_precomputes_a_layered_graph_with_every_stage_timed(nav_test):
    artifact, _ = nav_test
    assert set(artifact.timings_ms) == {stage.value for stage in Stage}
    assert artifact.counts["nodes"] > 100 and artifact.counts["skeleton_layers"] > 1


@pytest.mark.shared_data
def test_nav_test_tracks_are_long_not_many_short_ones(nav_test):
    artifact, _ = nav_test
    length = np.linalg.norm(artifact.track_end - artifact.track_start, axis=1)
    assert np.median(length) > 5.0, "RANSAC lines run along the corridors"
    skeleton_m = np.linalg.norm(artifact.skeleton_segments[:, 1] - artifact.skeleton_segments[:, 0], axis=1).sum()
    assert len(length) < skeleton_m / 2.0, "a few tracks per metre of corridor, not one per sample"


@pytest.mark.shared_data
def test_prm_comparison_along_a_recast_route(nav_test, tmp_path):
    artifact, shared = nav_test
    queries = read_recast_queries(shared / "levels" / "recast" / "TestCases" / "nav_mesh_test.txt")
    assert len(queries) == 21
    paths = NavmeshPaths(TriMesh(artifact.navmesh_vertices, artifact.navmesh_faces), artifact.settings)
    polyline = paths.path(*queries[0])
    assert polyline is not None
    route = walk(polyline, 1.4, 30.0)
    result = compare_with_prm(
        artifact, route, np.random.default_rng(0), densities_per_m2=(0.1, 0.5), plot_path=tmp_path / "top.png"
    )
    rows = {row["graph"]: row for row in result["rows"]}
    ours, prm_sparse, prm_dense = rows["ours"], rows["prm_0.1"], rows["prm_0.5"]
    assert (tmp_path / "top.png").stat().st_size > 0
    verdict, tried = result["verdict"], result["coverage_search"]
    reached = [t for t in tried if t["mean_coverage"] >= ours["coverage"]]
    if verdict["prm_reached_our_coverage"]:
        equal = rows["prm_equal_coverage"]
        assert equal["mean_coverage"] >= ours["coverage"] and equal["density_per_m2"] == min(t["density_per_m2"] for t in reached)
    else:
        assert not reached and verdict["compared_with"] == tried[-1]
        assert tried[-1]["mean_nodes"] > PRM_MAX_NODES or tried[-1]["density_per_m2"] > PRM_MAX_DENSITY_PER_M2 / 1.5
    assert verdict["fewer_nodes"] == (ours["nodes"] < verdict["compared_with"]["mean_nodes"])
    assert verdict["fewer_edges"] == (ours["edges"] < verdict["compared_with"]["mean_edges"])
    assert ours["visible"] >= 0.9, "the actor inside the frame and unoccluded (evaluation/tracks/measure.py)"
    assert ours["line_of_sight"] >= ours["visible"], "a frame that shows the actor has it in sight"
    assert ours["target_update_ms_median"] > 0.0
    assert prm_dense["nodes"] > prm_sparse["nodes"] and prm_dense["edges"] > prm_sparse["edges"]
    assert 0.0 < ours["coverage"] <= 1.0
    # every shot size keeps its framed extent in the frame (the whole body; the waist up in medium)
    assert set(result["ours_by_shot_size"]) == {"medium", "long", "extreme_long"}
    for size, measured in result["ours_by_shot_size"].items():
        assert measured["framed_in_frame"] >= 0.95 and measured["visible"] >= 0.9, (size, measured)
