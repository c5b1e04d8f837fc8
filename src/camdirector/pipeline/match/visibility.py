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

RIM_POINTS = 8  # points on each of a body's two rims: a capsule's width within 8% of its radius (1 - cos 22.5 deg)


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
        self.outline_count = samples_per_player + 2  # an outline's points, first in its silhouette
        # and its rims (`_rims`): its width, which a camera looking down on it sees on the screen's
        # vertical, for keeping it under the framing band's top (lens_width.py, step_back.py)
        self.silhouettes_local = [np.concatenate([o, _rims(m)]) for o, m in zip(self.outlines_local, player_meshes)]
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


def _rims(mesh: TriMesh) -> np.ndarray:
    """(2 * RIM_POINTS, 3) m: the mesh's vertices farthest from its vertical axis (the centre of its
    level bounds), at the lowest and at the highest height where they are, RIM_POINTS of each
    (evenly by bearing, repeated where fewer): a capsule's two equators, a box's eight corners.
    A camera above a player near it sees its width on the screen's vertical axis: on the real
    2on2 one looked down from 2.9 m on a player eval-match measured at 0.63 of the frame's
    height, the samples and the axis's ends at 0.47."""
    vertices = mesh.vertices
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2.0
    radial = np.hypot(vertices[:, 0] - centre[0], vertices[:, 2] - centre[2])
    widest = vertices[radial >= radial.max() * (1.0 - 1e-9)]
    rims = []
    for height in (widest[:, 1].min(), widest[:, 1].max()):
        ring = widest[np.abs(widest[:, 1] - height) <= 1e-9 * max(1.0, abs(height))]
        ring = ring[np.argsort(np.arctan2(ring[:, 2] - centre[2], ring[:, 0] - centre[0]))]
        rims.append(ring[np.arange(RIM_POINTS) * len(ring) // RIM_POINTS])
    return np.concatenate(rims)
