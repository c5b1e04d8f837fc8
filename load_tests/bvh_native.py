"""The compiled frame path's BVH (camdirector._native.Bvh) against Embree (RayScene, static meshes).

    python -m load_tests.bvh_native --json FILE [--data-dir DIR] [--repeats N] [--quick]

Scenes: the demo scene's static meshes (build_demo_scene(): the ground and its columns, world
frame) and the largest shared level (../shared/data/levels, by triangle count). Timed per scene and
engine: the build (median of `repeats`), then per query and batch size (occluded segments in
batches of 64 and 4096, first_hit rays in batches of 64 and 4096, random in the scene's box,
fixed seed) the median over `repeats` of the seconds per call, each repeat the mean of as many
calls as fill about REPEAT_S. The floor is an empty call (no rays) of the same API measured the
same way in the same run; rays_per_s counts the whole call, net_rays_per_s the call less its
floor. Ratios are Embree's time over the BVH's (above 1: the BVH is faster). Prints JSON (and
writes it to --json). No timing is asserted anywhere.
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt

from camdirector._native import Bvh
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.level_mesh import load_level_mesh
from load_tests.report import SHARED_DATA_DIR, emit, shared_subfolder

BATCHES = (64, 4096)  # rays per call: a frame's visibility samples, and a map's worth
REPEAT_S = 0.02  # seconds of calls per repeat (at least one call)
EMPTY = np.zeros((0, 3))


def _merged(meshes: list[TriMesh]) -> TriMesh:
    """One mesh of all: the BVH takes one mesh, RayScene a list (the same triangles)."""
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return TriMesh(
        np.concatenate([m.vertices for m in meshes]),
        np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]).astype(np.int32),
    )


def demo_meshes() -> list[TriMesh]:
    """The demo scene's static meshes in the world frame."""
    scene = build_demo_scene()
    return [TriMesh(o.transform.apply(o.vertices), o.faces.astype(np.int32)) for o in scene.static_objects]


def largest_level(data_dir: Path) -> tuple[str, TriMesh] | None:
    folder = shared_subfolder(data_dir, "levels", "bvh_native")
    if folder is None:
        return None
    meshes = [(path.stem, load_level_mesh(path)) for path in sorted(folder.rglob("*.obj"))]
    return max(meshes, key=lambda named: named[1].triangle_count)


def _seconds_per_call(call: Callable[[], object], repeats: int) -> float:
    """Median over repeats of the mean seconds per call, each repeat about REPEAT_S long."""
    start = time.perf_counter()
    call()
    calls = max(1, int(REPEAT_S / max(time.perf_counter() - start, 1e-7)))
    means = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            call()
        means.append((time.perf_counter() - start) / calls)
    return statistics.median(means)


def _rays(mesh: TriMesh, count: int, rng: np.random.Generator) -> tuple[npt.NDArray[np.float64], ...]:
    """Origins, segment targets and ray directions (count, 3), random in the mesh's box."""
    low, high = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    return (rng.uniform(low, high, (count, 3)), rng.uniform(low, high, (count, 3)), rng.normal(size=(count, 3)))


def bench_scene(meshes: list[TriMesh], repeats: int) -> dict:
    """Build times and query rates of both engines on one scene."""
    merged = _merged(meshes)
    builds = {
        "bvh": lambda: Bvh(merged.vertices, merged.faces),
        "embree": lambda: RayScene(meshes),
    }
    engines = {name: build() for name, build in builds.items()}
    result: dict = {
        "triangles": merged.triangle_count,
        "build_ms": {name: round(_seconds_per_call(build, repeats) * 1e3, 3) for name, build in builds.items()},
    }
    rng = np.random.default_rng(0)
    for query in ("occluded", "first_hit"):
        floors = {
            name: _seconds_per_call(functools.partial(getattr(engine, query), EMPTY, EMPTY), repeats)
            for name, engine in engines.items()
        }
        rows: dict = {"floor_us": {name: round(s * 1e6, 3) for name, s in floors.items()}}
        for batch in BATCHES:
            origins, targets, directions = _rays(merged, batch, rng)
            second = targets if query == "occluded" else directions
            row: dict = {}
            for name, engine in engines.items():
                s = _seconds_per_call(functools.partial(getattr(engine, query), origins, second), repeats)
                net = s - floors[name]
                row[name] = {
                    "us_per_call": round(s * 1e6, 3),
                    "rays_per_s": round(batch / s),
                    "net_rays_per_s": round(batch / net) if net > 0 else None,
                }
            row["embree_over_bvh"] = round(row["embree"]["us_per_call"] / row["bvh"]["us_per_call"], 3)
            rows[str(batch)] = row
        result[query] = rows
    result["build_embree_over_bvh"] = round(result["build_ms"]["embree"] / result["build_ms"]["bvh"], 3)
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="also write the result here")
    parser.add_argument("--data-dir", type=Path, default=SHARED_DATA_DIR, help="the shared data (levels/)")
    parser.add_argument("--repeats", type=int, default=9, help="repeats per timing (the median is reported)")
    parser.add_argument("--quick", action="store_true", help="the demo scene alone, 3 repeats (a smoke run)")
    args = parser.parse_args(argv)
    repeats = 3 if args.quick else args.repeats
    result: dict = {
        "machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]},
        "repeats": repeats,
        "demo": bench_scene(demo_meshes(), repeats),
    }
    if not args.quick:
        level = largest_level(args.data_dir)
        if level is None:
            return 2
        name, mesh = level
        result["level"] = {"name": name, **bench_scene([mesh], repeats)}
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
