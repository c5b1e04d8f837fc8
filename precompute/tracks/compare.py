"""Our camera navigation graph against probabilistic roadmaps on the same level (Section 6.2).

For our graph and for a PRM at each density of `PRM_DENSITIES_PER_M2` (link distance
`PRM_LINK_DISTANCE_M`): nodes, edges, coverage (the share of the remeshed navmesh's area seen by
at least one node, by the dual visibility table, within the table's range), and a run of the same
`GraphDirector` (long shot, dynamic with cuts) along one actor route: per-frame target-update
time (cut check + target search) and camera-update time, in ms, and the actor's visibility (the
share of frames where at least half the actor's sample points are seen from the camera). The
PRM "at equal coverage" is the sparsest one whose coverage is at least ours; we beat it when we
have fewer nodes and fewer edges.
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.artifact import LevelArtifact
from camdirector.precompute.tracks.director import DirectorStyle, GraphDirector
from camdirector.precompute.tracks.navmesh import triangle_areas
from camdirector.precompute.tracks.prm import build_prm
from camdirector.precompute.tracks.route import ActorRoute
from camdirector.precompute.tracks.settings import DirectorSettings
from camdirector.precompute.tracks.topview import save_panels
from camdirector.precompute.tracks.visibility_table import build_visibility_table

PRM_DENSITIES_PER_M2 = (0.05, 0.1, 0.2, 0.5, 1.0)
PRM_LINK_DISTANCE_M = 5.0
VISIBLE_FRACTION = 0.5


def coverage(artifact: LevelArtifact) -> float:
    """Share of the remeshed navmesh area seen by at least one node."""
    area = triangle_areas(artifact.refined_vertices, artifact.refined_faces)
    return float(area[artifact.visibility.seen_triangles()].sum() / max(area.sum(), 1e-12))


def run_route(artifact: LevelArtifact, route: ActorRoute, scene: RayScene, settings: DirectorSettings,
              rng: np.random.Generator, style: DirectorStyle = DirectorStyle()) -> dict:
    """Director along the route: timings (ms), visibility, cuts, and the camera path (F, 3)."""
    director = GraphDirector(artifact, settings, rng, style)
    target_ms, camera_ms, visible, cuts, path = [], [], [], 0, []
    for t, p, f in zip(route.time_s, route.position_world, route.forward_world):
        shot = director.step(float(t), p, f, scene)
        target_ms.append(shot.timings_ms["cut_check"] + shot.timings_ms["target_update"])
        camera_ms.append(shot.timings_ms["camera_update"])
        visible.append(shot.visible_fraction)
        cuts += shot.cut
        path.append(shot.position_world)
    target_ms, camera_ms, visible = np.array(target_ms), np.array(camera_ms), np.array(visible)
    return {"frames": len(visible), "target_update_ms_median": float(np.median(target_ms)),
            "target_update_ms_mean": float(target_ms.mean()), "target_update_ms_std": float(target_ms.std()),
            "camera_update_ms_median": float(np.median(camera_ms)), "camera_update_ms_mean": float(camera_ms.mean()),
            "camera_update_ms_std": float(camera_ms.std()),
            "visible_frames": float((visible >= VISIBLE_FRACTION).mean()), "cuts": int(cuts),
            "camera_path": np.asarray(path)}


def compare_with_prm(artifact: LevelArtifact, route: ActorRoute, rng: np.random.Generator,
                     densities_per_m2: tuple[float, ...] = PRM_DENSITIES_PER_M2,
                     plot_path: Path | None = None) -> dict:
    """The comparison table of the module docstring, as a JSON-ready dict."""
    level = TriMesh(artifact.level_vertices, artifact.level_faces)
    scene = RayScene([level])
    navmesh = TriMesh(artifact.navmesh_vertices, artifact.navmesh_faces)
    refined = TriMesh(artifact.refined_vertices, artifact.refined_faces)
    settings = DirectorSettings()
    rows = []
    ours = run_route(artifact, route, scene, settings, np.random.default_rng(rng.integers(1 << 32)))
    rows.append({"graph": "ours", "nodes": len(artifact.nodes_world), "edges": len(artifact.edges),
                 "coverage": coverage(artifact), "build_s": sum(artifact.timings_ms.values()) / 1e3,
                 **{k: v for k, v in ours.items() if k != "camera_path"}})
    paths = {"ours": (artifact, ours["camera_path"])}
    for density in densities_per_m2:
        clock = time.perf_counter()
        graph = build_prm(navmesh, scene, artifact.settings, density, PRM_LINK_DISTANCE_M, rng)
        table = build_visibility_table(graph.nodes_world, refined, scene, artifact.settings, rng)
        build_s = time.perf_counter() - clock
        prm = dataclasses.replace(artifact, nodes_world=graph.nodes_world, edges=graph.edges,
                                  edge_is_link=graph.edge_is_link, visibility=table,
                                  track_start=np.empty((0, 3)), track_end=np.empty((0, 3)))
        run = run_route(prm, route, scene, settings, np.random.default_rng(rng.integers(1 << 32)))
        name = f"prm_{density:g}"
        rows.append({"graph": name, "density_per_m2": density, "nodes": len(graph.nodes_world),
                     "edges": len(graph.edges), "coverage": coverage(prm), "build_s": build_s,
                     **{k: v for k, v in run.items() if k != "camera_path"}})
        paths[name] = (prm, run["camera_path"])
    equal = next((r for r in rows[1:] if r["coverage"] >= rows[0]["coverage"]), None)
    verdict = {"prm_at_equal_coverage": equal["graph"] if equal else None,
               "fewer_nodes": bool(equal and rows[0]["nodes"] < equal["nodes"]),
               "fewer_edges": bool(equal and rows[0]["edges"] < equal["edges"])}
    if plot_path is not None:
        shown = ["ours"] + ([equal["graph"]] if equal else [rows[-1]["graph"]])
        save_panels(Path(plot_path), [
            dict(navmesh_vertices=artifact.navmesh_vertices, navmesh_faces=artifact.navmesh_faces,
                 nodes_world=paths[name][0].nodes_world, edges=paths[name][0].edges,
                 title=f"{name}: {len(paths[name][0].nodes_world)} nodes, {len(paths[name][0].edges)} edges",
                 skeleton_segments=artifact.skeleton_segments if name == "ours" else None,
                 route_world=route.position_world, camera_world=paths[name][1]) for name in shown])
    return {"rows": rows, "verdict": verdict, "route_frames": len(route.time_s),
            "route_length_m": float(np.linalg.norm(np.diff(route.position_world, axis=0), axis=1).sum())}
