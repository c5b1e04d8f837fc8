"""Camera tracks of a level: the paper's precompute stages in order (Section 4, Figure 2a), one
module each, each timed.

    Stage.RAY_SCENE    geometry/raycast.py     Embree scene of the level (built once)
    Stage.NAVMESH      navmesh.py              the given navmesh, or one derived from the level
    Stage.SKELETON     skeleton.py             straight skeletons of the navmesh's floor layers
    Stage.SAMPLING     sampling.py             ray-cast camera samples orthogonal to the skeleton
    Stage.CLUSTERING   ransac.py               sequential RANSAC lines -> camera tracks (+ static cameras)
    Stage.FILTERING    filters.py              the four filters
    Stage.REMESHING    visibility_table.py     navmesh refined to a maximum triangle area
    Stage.REDUNDANCY   redundancy.py           tracks whose view others repeat are dropped (ours)
    Stage.GRAPH        graph.py                the camera navigation graph
    Stage.VISIBILITY   visibility_table.py     the dual node/triangle visibility table

Order (our deviation, documented): the paper estimates visibility before it builds the graph;
we build the graph first so the table is kept for the graph's final nodes (edge splitting adds
nodes the tracks did not have). Between the filters and the graph, our redundancy stage (no
counterpart in the paper) drops tracks whose view of the remeshed navmesh enough other tracks
repeat, so it needs the remeshing first.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import Enum

import numpy as np

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.infra.stage_clock import StageClock
from camdirector.precompute.tracks.artifact import LevelArtifact
from camdirector.precompute.tracks.filters import filter_tracks
from camdirector.precompute.tracks.graph import build_graph
from camdirector.precompute.tracks.navmesh import derive_navmesh
from camdirector.precompute.tracks.ransac import add_static_cameras, cluster_tracks
from camdirector.precompute.tracks.redundancy import prune_redundant_tracks
from camdirector.precompute.tracks.sampling import sample_cameras
from camdirector.precompute.tracks.skeleton import extract_skeleton, segment_components
from camdirector.precompute.tracks.track_settings import TrackSettings
from camdirector.precompute.tracks.visibility_table import build_visibility_table, remesh


class Stage(Enum):
    """Pipeline order; values are the keys of `LevelArtifact.timings_ms`."""

    RAY_SCENE = "ray_scene"
    NAVMESH = "navmesh"
    SKELETON = "skeleton"
    SAMPLING = "raycast_sampling"
    CLUSTERING = "clustering"
    FILTERING = "filtering"
    REMESHING = "remeshing"
    REDUNDANCY = "redundancy"
    GRAPH = "graph"
    VISIBILITY = "visibility"


_PROGRESS_AFTER: dict[Enum, float] = {
    Stage.RAY_SCENE: 0.02,
    Stage.NAVMESH: 0.1,
    Stage.SKELETON: 0.25,
    Stage.SAMPLING: 0.27,
    Stage.CLUSTERING: 0.45,
    Stage.FILTERING: 0.5,
    Stage.REMESHING: 0.55,
    Stage.REDUNDANCY: 0.65,
    Stage.GRAPH: 0.7,
    Stage.VISIBILITY: 1.0,
}


def precompute_level(
    mesh: TriMesh,
    settings: TrackSettings,
    rng: np.random.Generator,
    *,
    navmesh: TriMesh | None = None,
    m_per_unit: float = 1.0,
    progress: Callable[[float], None] | None = None,
) -> LevelArtifact:
    """Camera navigation graph and dual visibility table of a level.

    mesh: the level in metres, world frame, +Y up (level.load_level_mesh applies the scale);
    navmesh: its navigation mesh in the same frame, or None to derive one (navmesh.py);
    m_per_unit: recorded in the artifact; progress: called with the fraction done (0..1] after
    each stage. Raises MeshError when no walkable surface is found.
    """
    stage_clock = StageClock(progress, _PROGRESS_AFTER)
    done = stage_clock.done
    timings = stage_clock.timings_ms

    scene = RayScene([mesh])
    done(Stage.RAY_SCENE)
    nav = navmesh if navmesh is not None else derive_navmesh(mesh, scene, settings)
    done(Stage.NAVMESH)
    skeleton = extract_skeleton(nav, settings)
    done(Stage.SKELETON)
    samples = sample_cameras(skeleton, scene, settings, nav)
    done(Stage.SAMPLING)
    clustered = cluster_tracks(samples.position_world, samples.group, settings, rng)
    clustered = add_static_cameras(
        clustered, samples.position_world, samples.origin_world, segment_components(skeleton.segments_world)[samples.segment]
    )
    done(Stage.CLUSTERING)
    tracks = filter_tracks(clustered, samples.position_world, scene, settings, rng)
    done(Stage.FILTERING)
    refined = remesh(nav, skeleton, settings)
    done(Stage.REMESHING)
    filtered_count = len(tracks)
    tracks = prune_redundant_tracks(tracks, refined, scene, settings, rng)
    done(Stage.REDUNDANCY)
    graph = build_graph(tracks, scene, settings)
    done(Stage.GRAPH)
    table = build_visibility_table(graph.nodes_world, refined, scene, settings, rng)
    done(Stage.VISIBILITY)
    counts = {
        "level_triangles": mesh.triangle_count,
        "navmesh_triangles": nav.triangle_count,
        "skeleton_layers": skeleton.layer_count,
        "skeleton_segments": len(skeleton.segments_world),
        "camera_samples": len(samples),
        "clustered_tracks": len(clustered),
        "filtered_tracks": filtered_count,
        "tracks": len(tracks),
        "nodes": len(graph.nodes_world),
        "edges": len(graph.edges),
        "link_edges": int(graph.edge_is_link.sum()),
        "refined_triangles": refined.triangle_count,
        "visibility_pairs": int(len(table.node_triangles)),
    }
    return LevelArtifact(
        level_vertices=mesh.vertices,
        level_faces=mesh.faces,
        navmesh_vertices=nav.vertices,
        navmesh_faces=nav.faces.astype(np.int32),
        skeleton_segments=skeleton.segments_world,
        track_start=tracks.start_world,
        track_end=tracks.end_world,
        nodes_world=graph.nodes_world,
        edges=graph.edges.astype(np.int64),
        edge_is_link=graph.edge_is_link,
        refined_vertices=refined.vertices,
        refined_faces=refined.faces,
        visibility=table,
        m_per_unit=m_per_unit,
        settings=settings,
        timings_ms=timings,
        counts=counts,
    )
