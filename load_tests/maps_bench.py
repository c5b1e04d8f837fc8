"""Visibility-map benchmark: the backends, map resolutions 64-512, the A-map update, the backend rule.

    python -m load_tests.maps_bench --json FILE [--quick]

Scene: a forest, as in the paper's stress test (section 6, Figure 11): 100 cylinders of 12 sections
(4,800 triangles), 30 of them moving in random directions at 1 m/s, around two targets walking +X
at 1.5 m/s; the camera at the default style's place on the torus (theta at 0.35 of its range,
phi = 70 deg). Timed per backend (Embree, GL, and the compiled frame path's native one) and
resolution: computing all 2r = 10 maps (the paper's
per-update cost without amortization) and the 2 maps of one amortized update (section 6); then the
A-map update of an amortized step (predict 2 maps, aggregate 10, apply a mask); then a sweep of
scene sizes at 64 x 64 that locates where ray casting overtakes GL on this machine, which is the
constant of geometry.toric_maps.choose_backend. Prints JSON (and writes it to --json).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import TriMesh, capsule, cylinder, sphere
from camdirector.geometry.toric import composition_angle, make_torus, theta_max
from camdirector.geometry.toric_maps import (
    GL_MAX_TRIANGLES_ON_CPU,
    MapWindow,
    OccluderScene,
    WindowSettings,
    choose_backend,
    make_backend,
    probe_gl_renderer,
)
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.style import MaskKind
from camdirector.pipeline.toric.anticipation_map import AnticipationMap
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.style_masks import StyleMaskSettings
from camdirector.pipeline.toric.target_sampling import TargetSampler, TargetSamplingSettings
from load_tests.report import emit, summary

RESOLUTIONS = (64, 128, 256, 512)
SAMPLES_PER_TARGET = 5
TARGET_SPEED_M_S = 1.5
FRAME_S = 1.0 / 60.0


class Forest:
    """Cylinders around two targets; `step` advances the moving ones and the targets by one frame."""

    def __init__(self, trees: int = 100, sections: int = 12, moving: int = 30, seed: int = 0, moving_sections: int | None = None):
        rng = np.random.default_rng(seed)
        spots = []
        while len(spots) < trees:
            p = rng.uniform([-12.0, 0.0, -12.0], [14.0, 0.0, 12.0])
            # Keep the targets' corridor (z near 0) clear, as a path through the trees.
            if abs(p[2]) > 1.0 and all(np.hypot(*(p - q)[[0, 2]]) > 0.8 for q in spots):
                spots.append(p)
        trunk = cylinder(0.2, 5.0, sections)
        static = [TriMesh(trunk.vertices + s + [0.0, 2.5, 0.0], trunk.faces) for s in spots[moving:]]
        trunk = cylinder(0.2, 5.0, moving_sections or sections)
        self.scene = OccluderScene(static)
        self.moving = []
        for i, s in enumerate(spots[:moving]):
            heading = rng.uniform(0.0, math.tau)
            velocity = np.array([math.cos(heading), 0.0, math.sin(heading)])  # 1 m/s
            self.scene.add_dynamic(f"tree{i}", trunk, RigidTransform(position_world=s + [0.0, 2.5, 0.0]), velocity)
            self.moving.append((f"tree{i}", s + [0.0, 2.5, 0.0], velocity))
        self.target_meshes = [sphere(0.3), capsule(0.25, 1.7)]
        self.scene.add_dynamic("a", self.target_meshes[0], RigidTransform(position_world=np.array([0.0, 1.0, 0.0])))
        self.scene.add_dynamic("b", self.target_meshes[1], RigidTransform(position_world=np.array([2.5, 0.85, 0.0])))
        self.alpha = composition_angle((-1.0 / 3.0, 0.0), (1.0 / 3.0, 0.0), Lens())
        self.time_s = 0.0
        self.torus = self.previous_torus = None
        self.step()

    def step(self) -> None:
        self.time_s += FRAME_S
        walked = np.array([TARGET_SPEED_M_S * self.time_s, 0.0, 0.0])
        for object_id, start, velocity in self.moving:
            self.scene.set_motion(object_id, RigidTransform(position_world=start + velocity * self.time_s), velocity)
        a, b = np.array([0.0, 1.0, 0.0]) + walked, np.array([2.5, 1.0, 0.0]) + walked
        self.scene.set_motion("a", RigidTransform(position_world=a), (TARGET_SPEED_M_S, 0.0, 0.0))
        self.scene.set_motion("b", RigidTransform(position_world=b - [0.0, 0.15, 0.0]), (TARGET_SPEED_M_S, 0.0, 0.0))
        self.previous_torus = self.torus
        self.torus = make_torus(a, b, self.alpha)

    @property
    def camera_rad(self) -> tuple[float, float]:
        return 0.35 * theta_max(self.alpha), math.radians(70.0)

    def samples(self, count: int, rng: np.random.Generator) -> tuple[np.ndarray, list[str]]:
        """count fresh points on the targets' surfaces (alternating targets), world frame, and their owners."""
        sampler = TargetSampler(self.target_meshes, rng, TargetSamplingSettings(samples_per_target=(count + 1) // 2))
        slots = [(i % 2) * sampler.settings.samples_per_target + i // 2 for i in range(count)]
        transforms = [self.scene.dynamic[t].transform for t in ("a", "b")]
        return sampler.points_world(transforms, slots), ["ab"[sampler.target_of(s)] for s in slots]


def _time_maps(backend, forest: Forest, resolution: int, count: int, reps: int, rng) -> dict:
    theta, phi = forest.camera_rad
    times = []
    for rep in range(reps + 1):
        forest.step()
        window = MapWindow.around(forest.torus, theta, phi, WindowSettings(resolution=resolution))
        points, owners = forest.samples(count, rng)
        t0 = time.perf_counter()
        backend.compute(forest.torus, window, points, exclude_ids=owners, previous_torus=forest.previous_torus, dt_s=FRAME_S)
        if rep:  # the first call builds scenes and atlases
            times.append(time.perf_counter() - t0)
    return summary(times, 1e3)


def _reps(resolution: int, quick: bool) -> int:
    base = {64: 60, 128: 20, 256: 8, 512: 4}[resolution]
    return max(2, base // 4) if quick else base


def bench_maps(quick: bool) -> dict:
    rng = np.random.default_rng(1)
    out = {}
    for name in ("embree", "gl", "native"):
        forest = Forest()
        backend = make_backend(name, forest.scene)
        try:
            per_res = {}
            for resolution in RESOLUTIONS:
                reps = _reps(resolution, quick)
                per_res[str(resolution)] = {
                    "all_2r_maps_ms": _time_maps(backend, forest, resolution, 2 * SAMPLES_PER_TARGET, reps, rng),
                    "amortized_2_maps_ms": _time_maps(backend, forest, resolution, 2, reps, rng),
                }
            out[name] = per_res
        finally:
            backend.close()
    return out


def bench_agreement(resolution: int = 64) -> dict:
    """S-map agreement and V-map direction agreement of the two backends on the forest."""
    forest = Forest()
    forest.step()  # a previous torus: the targets' motion shows in the V-maps
    theta, phi = forest.camera_rad
    window = MapWindow.around(forest.torus, theta, phi, WindowSettings(resolution=resolution))
    points, owners = forest.samples(2 * SAMPLES_PER_TARGET, np.random.default_rng(2))
    maps = {}
    for name in ("embree", "gl"):
        backend = make_backend(name, forest.scene)
        maps[name] = backend.compute(
            forest.torus, window, points, exclude_ids=owners, previous_torus=forest.previous_torus, dt_s=FRAME_S
        )
        backend.close()
    ray, gl = maps["embree"], maps["gl"]
    both = (ray.shadow > 0) & (gl.shadow > 0) & (np.linalg.norm(ray.velocity_rad_s, axis=-1) > 1e-3)
    v1, v2 = ray.velocity_rad_s[both], gl.velocity_rad_s[both]
    cos = np.einsum("ij,ij->i", v1, v2) / (np.linalg.norm(v1, axis=1) * np.linalg.norm(v2, axis=1) + 1e-12)
    return {
        "resolution": resolution,
        "occluded_share": round(float(ray.shadow.mean()), 4),
        "shadow_agreement": round(float(np.mean(ray.shadow == gl.shadow)), 4),
        "velocity_cos_over_0.9_share": round(float(np.mean(cos > 0.9)), 4),
    }


def bench_anticipation(quick: bool) -> dict:
    """One amortized A-map update (2 fresh maps predicted, 10 aggregated, a mask) from ray-cast maps."""
    out = {}
    for resolution in RESOLUTIONS:
        settings = AnticipationSettings(window=WindowSettings(resolution=resolution))
        forest = Forest()
        backend = make_backend("embree", forest.scene)
        amap = AnticipationMap(2, settings, StyleMaskSettings(kind=MaskKind.AVOID_BEHIND_TOP_BOTTOM))
        amap.bank.warm()
        theta, phi = forest.camera_rad
        rng = np.random.default_rng(3)
        times, predict, occluded = [], [], []
        reps = _reps(resolution, quick)
        for rep in range(reps + 2):
            forest.step()
            slots = amap.next_slots()
            window = MapWindow.around(forest.torus, theta, phi, settings.window, lattice=amap.window)
            points, owners = forest.samples(len(slots), rng)
            maps = backend.compute(
                forest.torus, window, points, exclude_ids=owners, previous_torus=forest.previous_torus, dt_s=FRAME_S
            )
            t0 = time.perf_counter()  # AnticipationMap.refresh, its steps timed apart
            amap.schedule(forest.time_s, slots)
            t_predict = time.perf_counter()
            predicted = amap.predict(maps)
            t_predicted = time.perf_counter()
            amap.store(forest.time_s, slots, predicted, maps.window, forest.torus)
            if rep >= 2:  # after the first fill of all 10 slots
                times.append(time.perf_counter() - t0)
                predict.append(t_predicted - t_predict)
                occluded.append(float(maps.shadow.mean()))
        backend.close()
        out[str(resolution)] = {
            "update_ms": summary(times, 1e3),
            "predict_2_maps_ms": summary(predict, 1e3),
            "occluded_share": round(float(np.mean(occluded)), 4),
        }
    return out


def bench_backend_rule(quick: bool) -> dict:
    """Cost against scene size at 64 and 128, 2 maps (an amortized update) and 10 (a full refresh).

    The static trees' tessellation grows while the 30 moving trees stay at 12 sections (1,440
    moving triangles), so the sweep measures scene size, not the moving objects' handling.
    """
    sizes = {
        64: [(10, 3), (25, 4), (100, 3), (100, 6), (100, 12), (100, 24), (100, 32), (100, 48), (100, 64), (100, 96), (100, 192)],
        128: [(100, 12), (100, 48), (100, 96), (100, 192), (100, 384)],
    }
    rng = np.random.default_rng(4)
    out = {}
    for resolution, scenes in sizes.items():
        rows = []
        for trees, sections in scenes[::2] if quick else scenes:
            row = {}
            for name in ("embree", "gl"):
                forest = Forest(trees=trees, sections=sections, moving=min(30, trees // 3), moving_sections=12)
                row["triangles"] = forest.scene.triangle_count
                backend = make_backend(name, forest.scene)
                reps = (8 if quick else 40) * 64 // resolution
                row[f"{name}_2_maps_ms"] = _time_maps(backend, forest, resolution, 2, reps, rng)["median"]
                row[f"{name}_10_maps_ms"] = _time_maps(backend, forest, resolution, 10, max(2, reps // 3), rng)["median"]
                backend.close()
            rows.append(row)
        out[str(resolution)] = {
            "sweep": rows,
            "crossover_triangles_2_maps": _crossover(rows, "2_maps_ms"),
            "crossover_triangles_10_maps": _crossover(rows, "10_maps_ms"),
        }
    renderer = probe_gl_renderer()
    forest_triangles = Forest().scene.triangle_count
    return {
        **out,
        "GL_MAX_TRIANGLES_ON_CPU": GL_MAX_TRIANGLES_ON_CPU,
        "rule": "no EGL -> embree; hardware GPU -> gl; software GL (llvmpipe) -> gl up to "
        "GL_MAX_TRIANGLES_ON_CPU * (resolution / 64)^2 triangles, embree above",
        "renderer": renderer,
        "chosen_for_forest": {str(r): choose_backend(forest_triangles, renderer, r) for r in RESOLUTIONS},
    }


def _crossover(rows: list[dict], key: str):
    """The smallest scene (triangles) from which ray casting stays faster, None if it never does."""
    for row in rows:
        if all(r[f"embree_{key}"] < r[f"gl_{key}"] for r in rows if r["triangles"] >= row["triangles"]):
            return row["triangles"]
    return None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="also write the result here")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (a smoke run)")
    args = parser.parse_args(argv)
    forest = Forest()
    result = {
        "machine": {"cpus": os.cpu_count(), "gl_renderer": probe_gl_renderer(), "python": sys.version.split()[0]},
        "scene": {
            "triangles": forest.scene.triangle_count,
            "cylinders": 100,
            "moving_cylinders": 30,
            "samples_per_target": SAMPLES_PER_TARGET,
            "targets": 2,
        },
        "maps": bench_maps(args.quick),
        "agreement": bench_agreement(),
        "anticipation": bench_anticipation(args.quick),
        "backend_rule": bench_backend_rule(args.quick),
    }
    update64 = result["anticipation"]["64"]["update_ms"]["median"]
    updates_per_frame = FRAME_S / AnticipationSettings().update_period_s
    summary = {}
    for name in ("embree", "gl"):
        maps64 = result["maps"][name]["64"]["amortized_2_maps_ms"]["median"]
        summary[name] = {
            "maps_ms": maps64,
            "a_map_ms": update64,
            "update_total_ms": round(maps64 + update64, 3),
            "per_frame_average_ms_at_60fps": round((maps64 + update64) * updates_per_frame, 3),
        }
    result["amortized_update_64"] = summary
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
