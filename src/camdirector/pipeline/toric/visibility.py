"""VISIBILITY stage: the rig's own estimate of how much of the targets the camera sees.

Sample points are drawn once per session on each target's surface (area-weighted, from the
session's seeded generator), carried by the targets' transforms, and tested by ray casting from
the camera against the rest of the scene (targets do not occlude themselves or each other).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.toric.target_sampling import SurfaceSampler


@dataclass(frozen=True)
class VisibilitySettings:
    samples_per_target: int = 16  # surface points tested per target and frame. [1, 4096]


class VisibilityEstimate:
    def __init__(
        self,
        ray_scene: RayScene,
        target_meshes: list[TriMesh],
        rng: np.random.Generator,
        settings: VisibilitySettings = VisibilitySettings(),
    ):
        self.ray_scene = ray_scene
        self.samples_local = [SurfaceSampler(m).sample(settings.samples_per_target, rng) for m in target_meshes]

    def points_world(self, target_transforms: list[RigidTransform]) -> npt.NDArray[np.float64]:
        """(k, 3) the sample points carried by the targets' current RigidTransforms (target order)."""
        return np.concatenate([t.apply(s) for t, s in zip(target_transforms, self.samples_local)])

    def occluded_fraction(
        self, cameras_world: npt.NDArray[np.float64], points_world: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        """(n,) share of the points hidden from each of (n, 3) camera places, by ray casting."""
        n, k = len(cameras_world), len(points_world)
        hidden = self.ray_scene.occluded(np.repeat(cameras_world, k, axis=0), np.tile(points_world, (n, 1)))
        fraction: npt.NDArray[np.float64] = hidden.reshape(n, k).mean(axis=1)
        return fraction

    def run(self, state: FrameState, target_transforms: list[RigidTransform]) -> None:
        if state.pose is None:
            return
        points = self.points_world(target_transforms)
        state.visibility = float(1.0 - self.occluded_fraction(state.pose.position_world[None], points)[0])
