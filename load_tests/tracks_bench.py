"""Camera-tracks benchmark: every shared level precomputed, loaded, and directed along routes, against PRMs.

    python -m load_tests.tracks_bench [--data-dir ../shared/data] [--levels NAME...] [--seed 0] [--no-prm] --json FILE

The issue's targets: every shared level precomputes in under 30 s on this machine, and the
per-frame target update takes under 2 ms median. Per level: `level add` into a temporary registry
(wall time and the stage timings the artifact records), the artifact's load time, then
`eval-graph`'s comparison (evaluation/tracks/compare.py) along the same route `eval-graph` walks,
in the long shot: the baseline, measured in the same run, is the PRM at our coverage (or, where
none reaches it, the densest one tried), and the ratios are ours against it (--no-prm leaves the
comparison out: one level then runs in well under a minute).

Then `routes`: our director (dynamic with cuts) in each shot size along three routes, measured
frame by frame by evaluation/tracks/measure.py (what the frame shows: `visible` inside the frame
and unoccluded, `line_of_sight` rays only, `framed_in_frame` the shot size's framed extent all
inside the frame; cuts after the first frame; target update ms; framing error): `default`, the
route `eval-graph` walks, and `tightest` and `open`, about 20 m through the level's tightest
corridor and its most open place, walked there and back (evaluation/tracks/route.py says how
they are picked; `half_width_m` is half the narrowest width between walls there, `length_m` the
distance walked). Prints JSON (and writes it to --json); asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from camdirector.evaluation.tracks.cli import route_for
from camdirector.evaluation.tracks.compare import compare_with_prm
from camdirector.evaluation.tracks.measure import measure_shot_sizes
from camdirector.evaluation.tracks.route import ActorRoute, NavmeshPaths, corridor_and_open_routes, there_and_back
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.registry import LevelRegistry
from load_tests.report import SHARED_DATA_DIR, emit, shared_subfolder

# name -> (path under levels/, metres per level unit: SOURCES.md; zdm2's player is ~15 units tall)
LEVELS = {
    "dungeon": ("recast/dungeon.obj", 1.0),
    "nav_test": ("recast/nav_test.obj", 1.0),
    "undulating": ("recast/undulating.obj", 1.0),
    "zdm2": ("sauerbraten/zdm2.obj", 0.12),
}
_ROUTE_KEYS = (
    "target_update_ms_median",
    "target_update_ms_mean",
    "camera_update_ms_median",
    "visible",
    "line_of_sight",
    "framed_in_frame",
    "cuts",
)
_MEASURED_KEYS = (
    "frames",
    "visible",
    "line_of_sight",
    "framed_in_frame",
    "cuts",
    "cuts_per_min",
    "target_update_ms_median",
    "framing_error_median",
)


def _ratio(a: float, b: float) -> float | None:
    return round(a / b, 3) if b else None


def _rounded(value):
    return round(value, 4) if isinstance(value, float) else value


def _route_length_m(route: ActorRoute) -> float:
    return round(float(np.linalg.norm(np.diff(route.position_world, axis=0), axis=1).sum()), 1)


def bench_routes(artifact, record, seed: int) -> dict:
    """route name -> its length, frames and, per shot size, the measured numbers (module docstring)."""
    scene = RayScene([TriMesh(artifact.level_vertices, artifact.level_faces)])
    paths = NavmeshPaths(TriMesh(artifact.navmesh_vertices, artifact.navmesh_faces), artifact.settings)
    places = corridor_and_open_routes(paths, artifact.skeleton_segments, scene, artifact.agent_height_m)
    routes = {"default": (route_for(artifact, record, np.random.default_rng(seed)), {})}
    for name, place in places.items():
        routes[name] = (
            there_and_back(place.polyline_world),
            {"place_world": np.round(place.place_world, 2).tolist(), "half_width_m": round(place.half_width_m, 2)},
        )
    out = {}
    for name, (route, about) in routes.items():
        runs = measure_shot_sizes(artifact, route, scene, lambda: np.random.default_rng(seed))
        sizes = {size: {k: _rounded(run[k]) for k in _MEASURED_KEYS} for size, run in runs.items()}
        out[name] = {**about, "length_m": _route_length_m(route), "shot_sizes": sizes}
    return out


def bench_level(registry: LevelRegistry, name: str, path: Path, scale: float, seed: int, prm: bool = True) -> dict:
    start = time.perf_counter()
    record = registry.add_level(name, path, scale=scale, seed=seed)
    precompute_s = time.perf_counter() - start
    start = time.perf_counter()
    artifact = registry.load(name)
    load_ms = (time.perf_counter() - start) * 1e3
    out = {
        "precompute_s": round(precompute_s, 2),
        "under_30_s": precompute_s < 30.0,
        "stage_ms": {k: round(v, 1) for k, v in record.timings_ms.items()},
        "artifact_load_ms": round(load_ms, 1),
        "nodes": len(artifact.nodes_world),
        "edges": len(artifact.edges),
    }
    if prm:
        out.update(_prm_comparison(artifact, record, seed))
    out["routes"] = bench_routes(artifact, record, seed)
    return out


def _prm_comparison(artifact, record, seed: int) -> dict:
    """`eval-graph`'s comparison along its route: ours, the PRM it is compared with, the ratios."""
    rng = np.random.default_rng(seed)
    result = compare_with_prm(artifact, route_for(artifact, record, rng), rng)
    rows = {row["graph"]: row for row in result["rows"]}
    ours, verdict = rows["ours"], result["verdict"]
    baseline = rows.get("prm_equal_coverage")
    compared = verdict["compared_with"] or {}
    out = {
        "ours": {
            "nodes": ours["nodes"],
            "edges": ours["edges"],
            "coverage": round(ours["coverage"], 4),
            **{k: ours[k] for k in _ROUTE_KEYS},
        },
        "target_update_under_2_ms": ours["target_update_ms_median"] < 2.0,
        "prm_reached_our_coverage": verdict["prm_reached_our_coverage"],
        "prm_compared": {
            "density_per_m2": compared.get("density_per_m2"),
            "mean_nodes": compared.get("mean_nodes"),
            "mean_edges": compared.get("mean_edges"),
            "mean_coverage": compared.get("mean_coverage"),
        },
        "fewer_nodes": verdict["fewer_nodes"],
        "fewer_edges": verdict["fewer_edges"],
        "ratio_nodes_vs_prm": _ratio(ours["nodes"], compared.get("mean_nodes") or 0.0),
        "ratio_edges_vs_prm": _ratio(ours["edges"], compared.get("mean_edges") or 0.0),
        "route_frames": result["route_frames"],
    }
    if baseline is not None:
        out["prm_equal_coverage_route"] = {k: baseline[k] for k in _ROUTE_KEYS}
        out["ratio_target_update_vs_prm"] = _ratio(ours["target_update_ms_median"], baseline["target_update_ms_median"])
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", type=Path, default=SHARED_DATA_DIR)
    parser.add_argument("--levels", nargs="+", choices=sorted(LEVELS), default=list(LEVELS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--no-prm",
        dest="prm",
        action="store_false",
        help="leave out the comparison with PRMs (the routes only: a level in well under a minute)",
    )
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    folder = shared_subfolder(args.data_dir, "levels", "tracks_bench")
    if folder is None:
        return 2
    out = {"benchmark": "tracks_levels", "seed": args.seed, "levels": {}}
    with tempfile.TemporaryDirectory() as registry_dir:
        registry = LevelRegistry(Path(registry_dir))
        for name in args.levels:
            relative, scale = LEVELS[name]
            out["levels"][name] = bench_level(registry, name, folder / relative, scale, args.seed, args.prm)
            print(f"tracks_bench: {name} done", file=sys.stderr)
    emit(out, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
