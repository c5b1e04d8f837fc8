"""Our camera navigation graph against probabilistic roadmaps on the same level (Section 6.2).

For our graph and for PRMs (link distance `PRM_LINK_DISTANCE_M`): nodes, edges, coverage (the
share of the remeshed navmesh's area seen by at least one node, by the dual visibility table,
within the table's range: the same table builder, range and rays for both), and a run of the
same `GraphDirector` (long shot, dynamic with cuts) along one actor route, measured by
evaluation/tracks/measure.py: per-frame target-update time (cut check + target search) and
camera-update time, in ms, the share of frames that show the actor (`visible`: inside the frame
and unoccluded), the share with a clear line of sight to it (`line_of_sight`: rays only), the
share with the whole body inside the frame, cuts and the framing error. Our graph is also run in
every shot size (`ours_by_shot_size`: visible, line of sight, the share with the shot size's
framed extent inside the frame, cuts a minute).

The PRM "at equal coverage" is searched for, not read off a grid: the sparsest density whose
coverage, averaged over `PRM_SEEDS` random roadmaps, is at least ours (densities grow by
`_LADDER` from `PRM_MIN_DENSITY_PER_M2` until one reaches our coverage, then `_BISECTIONS`
geometric bisections). A coarse grid would credit the PRM with the nodes of the first grid point
past our coverage, more than it needs; one random roadmap would make the answer a coin toss.
We beat it when we have fewer nodes and fewer edges than its mean; where no PRM of up to
`PRM_MAX_NODES` nodes reaches our coverage (the route run on a denser one would take minutes),
the densest one tried, which falls short, is the bound we must beat. Every density tried is
listed (`coverage_search`): near full coverage the last fraction of a percent costs a PRM
many nodes, and the list shows how much the verdict rests on it. Rows at the reference
densities `PRM_DENSITIES_PER_M2` show the trend. The verdict also names, for information, the
sparsest reference PRM that shows the actor along the route (`visible`) at least as often as ours:
the paper's sense of a PRM dense enough "for a correct result".
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from camdirector.evaluation.tracks.measure import measure_route, measure_shot_sizes
from camdirector.evaluation.tracks.prm import build_prm
from camdirector.evaluation.tracks.route import ActorRoute
from camdirector.evaluation.tracks.topview import save_panels
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.artifact import LevelArtifact
from camdirector.precompute.tracks.navmesh import triangle_areas
from camdirector.precompute.tracks.visibility_table import build_visibility_table

PRM_DENSITIES_PER_M2 = (0.05, 0.1, 0.2, 0.5)
PRM_LINK_DISTANCE_M = 5.0
PRM_SEEDS = 3
PRM_MIN_DENSITY_PER_M2 = 0.002
PRM_MAX_DENSITY_PER_M2 = 2.0
PRM_MAX_NODES = 4000
_LADDER = 1.5
_BISECTIONS = 4


def coverage(artifact: LevelArtifact) -> float:
    """Share of the remeshed navmesh area seen by at least one node."""
    area = triangle_areas(artifact.refined_vertices, artifact.refined_faces)
    return float(area[artifact.visibility.seen_triangles()].sum() / max(area.sum(), 1e-12))


def _prm_artifact(
    artifact: LevelArtifact, navmesh: TriMesh, refined: TriMesh, scene: RayScene, density: float, rng: np.random.Generator
) -> LevelArtifact:
    """Our artifact with its graph and visibility table replaced by a PRM's."""
    graph = build_prm(navmesh, scene, artifact.settings, density, PRM_LINK_DISTANCE_M, rng)
    table = build_visibility_table(graph.nodes_world, refined, scene, artifact.settings, rng)
    return dataclasses.replace(
        artifact,
        nodes_world=graph.nodes_world,
        edges=graph.edges,
        edge_is_link=graph.edge_is_link,
        visibility=table,
        track_start=np.empty((0, 3)),
        track_end=np.empty((0, 3)),
    )


def prm_at_coverage(
    artifact: LevelArtifact,
    navmesh: TriMesh,
    refined: TriMesh,
    scene: RayScene,
    target: float,
    rng: np.random.Generator,
    trials: list[dict] | None = None,
) -> tuple[float, list[LevelArtifact]] | None:
    """The sparsest density (per m^2) whose PRMs' mean coverage reaches target, with its
    `PRM_SEEDS` roadmaps (module docstring); None when the search passes `PRM_MAX_DENSITY_PER_M2`
    or PRMs of `PRM_MAX_NODES` nodes without reaching it.
    trials, when given, receives every density tried with its mean coverage, nodes and edges."""

    def trial(density: float) -> tuple[float, list[LevelArtifact]]:
        prms = [_prm_artifact(artifact, navmesh, refined, scene, density, rng) for _ in range(PRM_SEEDS)]
        reached = float(np.mean([coverage(p) for p in prms]))
        if trials is not None:
            trials.append(
                {
                    "density_per_m2": density,
                    "mean_coverage": reached,
                    "mean_nodes": float(np.mean([len(p.nodes_world) for p in prms])),
                    "mean_edges": float(np.mean([len(p.edges) for p in prms])),
                }
            )
        return reached, prms

    low, density, found = None, PRM_MIN_DENSITY_PER_M2, None
    while density <= PRM_MAX_DENSITY_PER_M2 * (1.0 + 1e-9):
        reached, prms = trial(density)
        if reached >= target:
            found = (density, prms)
            break
        if np.mean([len(p.nodes_world) for p in prms]) > PRM_MAX_NODES:
            break
        low, density = density, density * _LADDER
    if found is None:
        return None
    for _ in range(_BISECTIONS if low is not None else 0):
        assert low is not None  # the range above is empty without it
        middle = float(np.sqrt(low * found[0]))
        reached, prms = trial(middle)
        if reached >= target:
            found = (middle, prms)
        else:
            low = middle
    return found


def compare_with_prm(
    artifact: LevelArtifact,
    route: ActorRoute,
    rng: np.random.Generator,
    densities_per_m2: tuple[float, ...] = PRM_DENSITIES_PER_M2,
    plot_path: Path | None = None,
) -> dict:
    """The comparison table of the module docstring, as a JSON-ready dict."""
    level = TriMesh(artifact.level_vertices, artifact.level_faces)
    scene = RayScene([level])
    navmesh = TriMesh(artifact.navmesh_vertices, artifact.navmesh_faces)
    refined = TriMesh(artifact.refined_vertices, artifact.refined_faces)
    rows = []
    ours = measure_route(artifact, route, scene, np.random.default_rng(rng.integers(1 << 32)))
    rows.append(
        {
            "graph": "ours",
            "nodes": len(artifact.nodes_world),
            "edges": len(artifact.edges),
            "coverage": coverage(artifact),
            "build_s": sum(artifact.timings_ms.values()) / 1e3,
            **{k: v for k, v in ours.items() if k != "camera_path"},
        }
    )
    paths = {"ours": (artifact, ours["camera_path"])}
    # our graph in every shot size (dynamic with cuts), the rows above being the long shot
    by_size = {
        size: {k: run[k] for k in ("visible", "line_of_sight", "framed_in_frame", "cuts_per_min")}
        for size, run in measure_shot_sizes(artifact, route, scene, lambda: np.random.default_rng(rng.integers(1 << 32))).items()
    }

    def prm_row(name: str, density: float, prms: list[LevelArtifact], build_s: float) -> dict:
        run = measure_route(prms[0], route, scene, np.random.default_rng(rng.integers(1 << 32)))
        paths[name] = (prms[0], run["camera_path"])
        return {
            "graph": name,
            "density_per_m2": density,
            "nodes": len(prms[0].nodes_world),
            "edges": len(prms[0].edges),
            "coverage": coverage(prms[0]),
            "mean_nodes": float(np.mean([len(p.nodes_world) for p in prms])),
            "mean_edges": float(np.mean([len(p.edges) for p in prms])),
            "mean_coverage": float(np.mean([coverage(p) for p in prms])),
            "build_s": build_s,
            **{k: v for k, v in run.items() if k != "camera_path"},
        }

    for density in densities_per_m2:
        clock = time.perf_counter()
        prm = _prm_artifact(artifact, navmesh, refined, scene, density, rng)
        rows.append(prm_row(f"prm_{density:g}", density, [prm], time.perf_counter() - clock))
    clock = time.perf_counter()
    trials: list[dict] = []
    searched = prm_at_coverage(artifact, navmesh, refined, scene, rows[0]["coverage"], rng, trials)
    equal = None
    if searched is not None:
        equal = prm_row("prm_equal_coverage", searched[0], searched[1], time.perf_counter() - clock)
        rows.append(equal)
    visible_as_often = next((r for r in rows[1 : len(densities_per_m2) + 1] if r["visible"] >= rows[0]["visible"]), None)
    # where no PRM reached our coverage, the densest one tried bounds the one that would from below
    bound = (
        {k: equal[k] for k in ("density_per_m2", "mean_coverage", "mean_nodes", "mean_edges")}
        if equal
        else (trials[-1] if trials else None)
    )
    verdict = {
        "prm_at_equal_coverage": equal["graph"] if equal else None,
        "prm_reached_our_coverage": equal is not None,
        "compared_with": bound,
        "fewer_nodes": bool(bound and rows[0]["nodes"] < bound["mean_nodes"]),
        "fewer_edges": bool(bound and rows[0]["edges"] < bound["mean_edges"]),
        "prm_at_equal_route_visibility": visible_as_often["graph"] if visible_as_often else None,
    }
    if plot_path is not None:
        shown = ["ours"] + ([equal["graph"]] if equal else [rows[-1]["graph"]])
        save_panels(
            Path(plot_path),
            [
                dict(
                    navmesh_vertices=artifact.navmesh_vertices,
                    navmesh_faces=artifact.navmesh_faces,
                    nodes_world=paths[name][0].nodes_world,
                    edges=paths[name][0].edges,
                    title=f"{name}: {len(paths[name][0].nodes_world)} nodes, {len(paths[name][0].edges)} edges",
                    skeleton_segments=artifact.skeleton_segments if name == "ours" else None,
                    route_world=route.position_world,
                    camera_world=paths[name][1],
                )
                for name in shown
            ],
        )
    return {
        "rows": rows,
        "ours_by_shot_size": by_size,
        "verdict": verdict,
        "coverage_search": sorted(trials, key=lambda t: t["density_per_m2"]),
        "route_frames": len(route.time_s),
        "route_length_m": float(np.linalg.norm(np.diff(route.position_world, axis=0), axis=1).sum()),
    }
