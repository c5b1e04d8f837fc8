"""Camera-tracks benchmark: every shared level precomputed, loaded, and directed along a route, against PRMs.

    python -m load_tests.tracks_bench [--data-dir ../shared/data] [--levels NAME...] [--seed 0] --json FILE

The issue's targets: every shared level precomputes in under 30 s on this machine, and the
per-frame target update takes under 2 ms median. Per level: `level add` into a temporary registry
(wall time and the stage timings the artifact records), the artifact's load time, then
`eval-graph`'s comparison (precompute/tracks/compare.py) along the same route `eval-graph` walks:
the baseline, measured in the same run, is the PRM at our coverage (or, where none reaches it,
the densest one tried), and the ratios are ours against it. Prints JSON (and writes it to --json);
asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from camdirector.precompute.tracks.cli import route_for
from camdirector.precompute.tracks.compare import compare_with_prm
from camdirector.precompute.tracks.registry import LevelRegistry
from load_tests.report import SHARED_DATA_DIR, emit, shared_subfolder

# name -> (path under levels/, metres per level unit: SOURCES.md; zdm2's player is ~15 units tall)
LEVELS = {
    "dungeon": ("recast/dungeon.obj", 1.0),
    "nav_test": ("recast/nav_test.obj", 1.0),
    "undulating": ("recast/undulating.obj", 1.0),
    "zdm2": ("sauerbraten/zdm2.obj", 0.12),
}
_ROUTE_KEYS = ("target_update_ms_median", "target_update_ms_mean", "camera_update_ms_median", "visible_frames", "cuts")


def _ratio(a: float, b: float) -> float | None:
    return round(a / b, 3) if b else None


def bench_level(registry: LevelRegistry, name: str, path: Path, scale: float, seed: int) -> dict:
    start = time.perf_counter()
    record = registry.add_level(name, path, scale=scale, seed=seed)
    precompute_s = time.perf_counter() - start
    start = time.perf_counter()
    artifact = registry.load(name)
    load_ms = (time.perf_counter() - start) * 1e3
    rng = np.random.default_rng(seed)
    result = compare_with_prm(artifact, route_for(artifact, record, rng), rng)
    rows = {row["graph"]: row for row in result["rows"]}
    ours, verdict = rows["ours"], result["verdict"]
    baseline = rows.get("prm_equal_coverage")
    compared = verdict["compared_with"] or {}
    out = {"precompute_s": round(precompute_s, 2), "under_30_s": precompute_s < 30.0,
           "stage_ms": {k: round(v, 1) for k, v in record.timings_ms.items()},
           "artifact_load_ms": round(load_ms, 1),
           "ours": {"nodes": ours["nodes"], "edges": ours["edges"], "coverage": round(ours["coverage"], 4),
                    **{k: ours[k] for k in _ROUTE_KEYS}},
           "target_update_under_2_ms": ours["target_update_ms_median"] < 2.0,
           "prm_reached_our_coverage": verdict["prm_reached_our_coverage"],
           "prm_compared": {"density_per_m2": compared.get("density_per_m2"), "mean_nodes": compared.get("mean_nodes"),
                            "mean_edges": compared.get("mean_edges"), "mean_coverage": compared.get("mean_coverage")},
           "fewer_nodes": verdict["fewer_nodes"], "fewer_edges": verdict["fewer_edges"],
           "ratio_nodes_vs_prm": _ratio(ours["nodes"], compared.get("mean_nodes") or 0.0),
           "ratio_edges_vs_prm": _ratio(ours["edges"], compared.get("mean_edges") or 0.0),
           "route_frames": result["route_frames"]}
    if baseline is not None:
        out["prm_equal_coverage_route"] = {k: baseline[k] for k in _ROUTE_KEYS}
        out["ratio_target_update_vs_prm"] = _ratio(ours["target_update_ms_median"], baseline["target_update_ms_median"])
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", type=Path, default=SHARED_DATA_DIR)
    parser.add_argument("--levels", nargs="+", choices=sorted(LEVELS), default=list(LEVELS))
    parser.add_argument("--seed", type=int, default=0)
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
            out["levels"][name] = bench_level(registry, name, folder / relative, scale, args.seed)
            print(f"tracks_bench: {name} done", file=sys.stderr)
    emit(out, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
