"""The pipeline's input types: a validated scene and a validated frame, as the session codec
(server/sessions/codec.py) makes them from the wire. Nothing here knows protobuf."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.transforms import RigidTransform
from camdirector.precompute.tracks.artifact import LevelArtifact
from camdirector.server.pipeline.style import Style


@dataclass(frozen=True)
class LoadedLevel:
    """A level as sessions use it: the artifact and its geometry as one world-frame mesh."""

    name: str
    artifact: LevelArtifact
    mesh_world: TriMesh


@dataclass
class ObjectSpec:
    id: str
    mesh: TriMesh          # local frame
    transform: RigidTransform
    dynamic: bool


@dataclass
class TargetSpec:
    id: str
    mesh: TriMesh          # local frame
    transform: RigidTransform
    aim_offset_local: np.ndarray  # (3,)


@dataclass
class SceneSpec:
    """A validated CreateSessionRequest."""

    objects: list[ObjectSpec]
    targets: list[TargetSpec]
    lens: Lens
    style: Style
    seed: int
    level: LoadedLevel | None = None  # the TRACKS rig's level


@dataclass
class FrameInput:
    """A validated FrameUpdate: states as (id, transform) in arrival order."""

    session_id: str
    frame: int
    time_s: float
    states: list[tuple[str, RigidTransform]]
