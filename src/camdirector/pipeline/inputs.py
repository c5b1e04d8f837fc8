"""The pipeline's input types: a validated scene and a validated frame, as the session codec
(worker/codec.py) makes them from the wire. Nothing here knows protobuf."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.style import Style
from camdirector.precompute.tracks.artifact import LevelArtifact

# A session's dynamic objects as INGEST keeps them: object id -> (mesh in its local frame, latest
# transform); the rigs that ray-cast or map the scene read them (pipeline/rigs.py `make_rig`).
DynamicObjects = dict[str, tuple[TriMesh, RigidTransform]]


@dataclass(frozen=True)
class LoadedLevel:
    """A level as sessions use it: the artifact and its geometry as one world-frame mesh."""

    name: str
    artifact: LevelArtifact
    mesh_world: TriMesh


@dataclass
class ObjectSpec:
    id: str
    mesh: TriMesh  # local frame
    transform: RigidTransform
    dynamic: bool


@dataclass
class TargetSpec:
    id: str
    mesh: TriMesh  # local frame
    transform: RigidTransform
    aim_offset_local: npt.NDArray[np.float64]  # (3,)
    team: int = 0  # MATCH: the player's team; players of different teams are opponents
    # Shown to people only (dashboard, monitor labels), never an identity: "" shows the id instead
    display_name: str = ""
    team_name: str = ""  # MATCH: the team's name, "" when the game gives none


@dataclass
class SceneSpec:
    """A validated CreateSessionRequest."""

    objects: list[ObjectSpec]
    targets: list[TargetSpec]
    lens: Lens
    style: Style
    seed: int
    level: LoadedLevel | None = None  # the TRACKS rig's level (MATCH: optional, its graph nodes and geometry)
    delay_s: float = 0.0  # MATCH: the broadcast delay, s. [0, 300]; the codec validates it


@dataclass
class FrameInput:
    """A validated FrameUpdate: states as (id, transform) in arrival order."""

    session_id: str
    frame: int
    time_s: float
    states: list[tuple[str, RigidTransform]]
    events: list[GameEvent] = field(default_factory=list)  # MATCH: the game's events since the last frame
    player_stats: list[PlayerStats] = field(default_factory=list)  # MATCH: the players whose stats changed
    # The compiled decoder's (ids, rows (n, 10) float64) that `states` was made of, in its order
    # (codec.frame_from_wire): the compiled rig moves its Scene by them in one call. None: decoded in Python.
    packed: tuple[list[str], npt.NDArray[np.float64]] | None = None


class EventKind(enum.IntEnum):
    """Same numbers as camdirector.v1.EventKind."""

    UNSPECIFIED = 0
    KILL = 1
    DAMAGE = 2
    OBJECTIVE = 3
    CUSTOM = 4


@dataclass
class GameEvent:
    """One game event of a MATCH session. For a KILL, actor_id is the attacker and other_actor_id
    the victim (both player ids, or "" when there is none)."""

    kind: EventKind
    actor_id: str
    other_actor_id: str
    priority: int  # [0, 15]; 0 = the kind's default (match/settings.py)
    time_s: float  # game time, s (the codec fills the frame's time for 0)
    label: str
    position_world: npt.NDArray[np.float64] | None = None  # (3,) metres, where it happened, if the game says


@dataclass(frozen=True)
class PlayerStats:
    """One player's scoreboard values in a MATCH session, as the game last sent them."""

    id: str
    health: int
    armor: int  # armor points
    items: int  # the game's own item bitmask (QuakeWorld: its IT_* bits; match/autotrack.py reads them)
    frags: int
