"""The rigs there are, as data, and the one choice of rig: which implementation of the rig
contract (pipeline/camera_rig.py) a session created from a scene gets, for its whole life.

`RIGS` holds one `RigEntry` per rig: its `Rig` value (pipeline/style.py, the wire's numbers), its
name, how it is made from a session's scene, how its compiled twin is made where it has one
(the server's `frame_path`, server_settings.py), and a line saying what it is. `make_rig` chooses
through it and nothing else does; code that lists the rigs (the codec's table of the wire's
values) reads it. A new rig is its folder and one entry here (docs/architecture.md, "where a change goes").
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.camera_rig import CameraRig
from camdirector.pipeline.inputs import DynamicObjects, SceneSpec
from camdirector.pipeline.match.rig import MatchRig
from camdirector.pipeline.style import Rig
from camdirector.pipeline.toric.compiled_rig import CompiledToricRig
from camdirector.pipeline.toric.rig import ToricRig
from camdirector.pipeline.tracks.rig import TracksRig


class MakeRig(Protocol):
    """Makes a session's rig from its scene and what the session keeps (`make_rig`'s arguments)."""

    def __call__(
        self,
        scene: SceneSpec,
        ray_scene: RayScene,
        static_meshes_world: list[TriMesh],
        dynamic: DynamicObjects,
        rng: np.random.Generator,
        clock: Callable[[], float],
        /,
    ) -> CameraRig: ...


@dataclass(frozen=True)
class RigEntry:
    """One rig: `make` makes it for a session whose `style.rig` is `rig`."""

    rig: Rig
    name: str  # lower case, as the rig's folder under pipeline/
    make: MakeRig
    description: str  # one line: what the rig does
    make_compiled: MakeRig | None = None  # its compiled twin (`make_rig`'s compiled); None: Python only


def _make_tracks(
    scene: SceneSpec,
    ray_scene: RayScene,
    static_meshes_world: list[TriMesh],
    dynamic: DynamicObjects,
    rng: np.random.Generator,
    clock: Callable[[], float],
    /,
) -> CameraRig:
    if scene.level is None:  # worker/codec.py gives every TRACKS scene its level
        raise ValueError("the TRACKS rig needs the scene's level")
    return TracksRig(scene.level, scene.lens, scene.style, ray_scene, rng, clock)


RIGS: tuple[RigEntry, ...] = (
    RigEntry(
        Rig.TORIC,
        "toric",
        lambda scene, ray_scene, static, dynamic, rng, clock: ToricRig(scene, ray_scene, static, dynamic, rng, clock),
        "frames one or two targets on the Toric manifold, moving by the style's visibility mode",
        lambda scene, ray_scene, static, dynamic, rng, clock: CompiledToricRig(scene, ray_scene, static, dynamic, rng, clock),
    ),
    RigEntry(
        Rig.TRACKS,
        "tracks",
        _make_tracks,
        "follows one actor on a precomputed level's camera tracks, cutting by the graph director",
    ),
    RigEntry(
        Rig.MATCH,
        "match",
        lambda scene, ray_scene, static, dynamic, rng, clock: MatchRig(scene, ray_scene, rng, clock),
        "directs a match among its players behind a broadcast delay, by the style's match director",
    ),
)
_BY_RIG = {entry.rig: entry for entry in RIGS}


def make_rig(
    scene: SceneSpec,
    ray_scene: RayScene,
    static_meshes_world: list[TriMesh],
    dynamic: DynamicObjects,
    rng: np.random.Generator,
    clock: Callable[[], float] = time.perf_counter,
    compiled: bool = False,
) -> CameraRig:
    """The rig of a session created from `scene`, for its whole life (worker/codec.py refuses a
    change of rig): the entry of `scene.style.rig` makes it (the codec gives a level to a TRACKS
    scene always, to a MATCH scene optionally, to no other). ray_scene, static_meshes_world and
    dynamic are the session's, which INGEST keeps current; rng its seeded generator, clock what
    the stages are timed on; `compiled` makes the rig's compiled twin where it has one (the
    server's frame path, server_settings.py), else the rig itself."""
    entry = _BY_RIG[scene.style.rig]
    make = entry.make_compiled if compiled and entry.make_compiled is not None else entry.make
    return make(scene, ray_scene, static_meshes_world, dynamic, rng, clock)


def runs_compiled(rig: Rig, compiled: bool) -> bool:
    """Whether a session of `rig` on the compiled frame path (`compiled`) gets its compiled twin
    (`make_rig`'s choice); a rig without one runs in Python on either path, its bits the same."""
    return compiled and _BY_RIG[rig].make_compiled is not None
