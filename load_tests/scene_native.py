"""The compiled twin of RayScene (camdirector._native.Scene) against RayScene, on the TORIC
VISIBILITY stage's query.

    python -m load_tests.scene_native --json FILE [--passes N]

The demo scene (build_demo_scene(): ground, columns, its moving obstacles) in both engines; two
targets, the avatar and a second avatar one second behind it on its path, 16 surface samples
each (VisibilitySettings' default), seen from a camera 6 m off the avatar's side and 2 m up.
Every frame (30 a second over the walk, `passes` times over) the obstacles are moved in both
engines (untimed), then each call is timed alone: RayScene.occluded as
VisibilityEstimate.occluded_fraction makes it (the camera repeated, 32 segments),
Scene.occluded with the same arrays, and Scene.visible_share (the camera and the 32 points).
The floor is an empty call (no segments) of each engine's occluded on an empty scene
(RayScene with moving objects refuses no segments), timed the same way in the same run.
Reported per call: median and p99 in microseconds, the median less its floor, and ratios
(RayScene's time over the Scene's: above 1, the Scene is faster). Prints JSON (and writes it to
--json). No timing is asserted anywhere.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt

from camdirector._native import Scene
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.toric.target_sampling import SurfaceSampler
from load_tests.report import emit

FPS = 30.0
SAMPLES_PER_TARGET = 16
CAMERA_OFFSET_M = np.array([6.0, 2.0, 0.0])  # in the avatar's frame: beside it, above its head
EMPTY = np.zeros((0, 3))


def _microseconds(call: Callable[[], object]) -> float:
    start = time.perf_counter_ns()
    call()
    return (time.perf_counter_ns() - start) / 1e3


def _summary(samples_us: list[float]) -> dict:
    return {"median_us": round(float(np.median(samples_us)), 3), "p99_us": round(float(np.percentile(samples_us, 99)), 3)}


def run(passes: int) -> dict:
    demo = build_demo_scene()
    static = [TriMesh(o.transform.apply(o.vertices), o.faces) for o in demo.static_objects]
    ray_scene, scene = RayScene(static), Scene(static)
    empty_ray_scene, empty_scene = RayScene([]), Scene([])  # the floors: RayScene refuses no segments once it has moving objects
    for o in demo.dynamic_objects:
        for engine in (ray_scene, scene):
            engine.add_dynamic(o.id, TriMesh(o.vertices, o.faces), o.transform)
    samples_local = SurfaceSampler(TriMesh(demo.avatar.vertices, demo.avatar.faces)).sample(
        SAMPLES_PER_TARGET, np.random.default_rng(0)
    )
    times: dict[str, list[float]] = {"ray_scene": [], "scene": [], "visible_share": [], "ray_scene_floor": [], "scene_floor": []}
    hidden_shares = []
    for _ in range(passes):
        for time_s in np.arange(0.0, demo.duration_s, 1.0 / FPS):
            transforms = demo.transforms_at(float(time_s))
            for object_id, transform in transforms.items():
                if object_id != demo.avatar.id:
                    ray_scene.set_transform(object_id, transform)
                    scene.set_transform(object_id, transform)
            avatar = transforms[demo.avatar.id]
            behind = demo.transforms_at(float(time_s) - 1.0)[demo.avatar.id]
            points: npt.NDArray[np.float64] = np.concatenate([avatar.apply(samples_local), behind.apply(samples_local)])
            camera = avatar.apply(CAMERA_OFFSET_M[None])[0]
            cameras = np.repeat(camera[None], len(points), axis=0)  # as VisibilityEstimate.occluded_fraction
            times["ray_scene"].append(_microseconds(functools.partial(ray_scene.occluded, cameras, points)))
            times["scene"].append(_microseconds(functools.partial(scene.occluded, cameras, points)))
            times["visible_share"].append(_microseconds(functools.partial(scene.visible_share, camera, points)))
            times["ray_scene_floor"].append(_microseconds(lambda: empty_ray_scene.occluded(EMPTY, EMPTY)))
            times["scene_floor"].append(_microseconds(lambda: empty_scene.occluded(EMPTY, EMPTY)))
            hidden_shares.append(1.0 - scene.visible_share(camera, points))
    result: dict = {name: _summary(samples) for name, samples in times.items()}
    for name, floor in (("ray_scene", "ray_scene_floor"), ("scene", "scene_floor"), ("visible_share", "scene_floor")):
        result[name]["net_median_us"] = round(result[name]["median_us"] - result[floor]["median_us"], 3)
    result["ray_scene_over_scene"] = round(result["ray_scene"]["median_us"] / result["scene"]["median_us"], 3)
    result["ray_scene_over_visible_share"] = round(result["ray_scene"]["median_us"] / result["visible_share"]["median_us"], 3)
    result["net_ray_scene_over_scene"] = round(result["ray_scene"]["net_median_us"] / result["scene"]["net_median_us"], 3)
    result["calls_each"] = len(times["scene"])
    result["segments_per_call"] = 2 * SAMPLES_PER_TARGET
    result["moving_obstacles"] = len(demo.dynamic_objects)
    result["mean_hidden_share"] = round(float(np.mean(hidden_shares)), 4)  # the sample means something if > 0
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="also write the result here")
    parser.add_argument("--passes", type=int, default=5, help="times over the walk's frames")
    args = parser.parse_args(argv)
    result = {"machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]}, **run(args.passes)}
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
