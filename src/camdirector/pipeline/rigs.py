"""The one choice of rig: which implementation of the rig contract (pipeline/camera_rig.py) a session
created from a scene gets, for its whole life."""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.camera_rig import CameraRig
from camdirector.pipeline.inputs import SceneSpec
from camdirector.pipeline.match.rig import MatchRig
from camdirector.pipeline.style import Rig
from camdirector.pipeline.toric.rig import ToricRig
from camdirector.pipeline.tracks.rig import TracksRig


def make_rig(scene: SceneSpec, ray_scene: RayScene, static_meshes_world: list[TriMesh], dynamic: dict,
             rng: np.random.Generator, clock: Callable[[], float] = time.perf_counter) -> CameraRig:
    """The rig of a session created from `scene`, for its whole life (worker/codec.py refuses a
    change of rig): MATCH when the style says so, TRACKS for a scene on a level (the codec gives
    a level only to those two), else TORIC. ray_scene, static_meshes_world and dynamic (object id
    -> (mesh, latest transform)) are the session's, which INGEST keeps current; rng its seeded
    generator, clock what the stages are timed on."""
    if scene.style.rig == Rig.MATCH:
        return MatchRig(scene, ray_scene, rng, clock)
    if scene.level is not None:
        return TracksRig(scene.level, scene.lens, scene.style, ray_scene, rng, clock)
    return ToricRig(scene, ray_scene, static_meshes_world, dynamic, rng, clock)
