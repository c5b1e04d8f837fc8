"""Visibility of the framed players by ray casts through the session's RayScene.

Each player gets `samples_per_player` points on its mesh surface, drawn once per session from the
session's seeded generator (as toric/visibility.py does for the TORIC rig) and carried by the
player's transform at the moment asked about. Players do not occlude each other (they are not in
the RayScene); the level, the static objects and the dynamic objects at their newest transforms do.
"""

from __future__ import annotations

import numpy as np

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.toric.target_sampling import SurfaceSampler


class SubjectVisibility:
    def __init__(self, ray_scene: RayScene, player_meshes: list[TriMesh], samples_per_player: int, rng: np.random.Generator):
        self.ray_scene = ray_scene
        self.samples_local = [SurfaceSampler(m).sample(samples_per_player, rng) for m in player_meshes]
        # the samples and the mesh's lowest and highest vertices: a body's whole height (16 samples
        # fall short of the head and feet by 10-20%), for sizing it on screen (lens_width.py)
        self.outlines_local = [
            np.concatenate([samples, m.vertices[[np.argmin(m.vertices[:, 1]), np.argmax(m.vertices[:, 1])]]])
            for samples, m in zip(self.samples_local, player_meshes)
        ]  # (k + 2, 3) each
        self.k = samples_per_player

    def points_world(self, moment: Moment, subjects: tuple[int, ...]) -> np.ndarray:
        """(len(subjects) * k, 3) the subjects' sample points at the moment, subject after subject."""
        return np.concatenate([moment.transforms[i].apply(self.samples_local[i]) for i in subjects])

    def seen_points(
        self, cameras_world: np.ndarray, moment: Moment, subjects: tuple[int, ...], asked: np.ndarray | None = None
    ) -> np.ndarray:
        """(m, len(subjects), k) bool: which sample points each of (m, 3) camera places sees.
        asked: (m, len(subjects) * k) bool, the camera-point pairs to ray-cast (default all);
        the others are False (a place search asks only for the points inside each frame)."""
        cameras = np.atleast_2d(cameras_world)
        if not subjects:
            return np.ones((len(cameras), 0, self.k), dtype=bool)
        points = self.points_world(moment, subjects)
        m, p = len(cameras), len(points)
        if asked is None:
            hidden = self.ray_scene.occluded(np.repeat(cameras, p, axis=0), np.tile(points, (m, 1)))
            return ~hidden.reshape(m, len(subjects), self.k)
        rows, cols = np.nonzero(asked)
        seen = np.zeros((m, p), dtype=bool)
        seen[rows, cols] = ~self.ray_scene.occluded(cameras[rows], points[cols])
        return seen.reshape(m, len(subjects), self.k)

    def visible_share(self, cameras_world: np.ndarray, moment: Moment, subjects: tuple[int, ...]) -> np.ndarray:
        """(m, len(subjects)) share of each subject's points seen from each of (m, 3) camera places."""
        share: np.ndarray = self.seen_points(cameras_world, moment, subjects).mean(axis=2)
        return share
