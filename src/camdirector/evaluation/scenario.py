"""A scenario in memory, and what it sends a session: the CreateSessionRequest and its frames.

A scenario (read from its file by evaluation/scenario_file.py, whose format
evaluation/scenario_schema.py documents) is a scene, how its targets and occluders move, lens,
style, duration and frame rate. The same scenario replays with every visibility mode, so the modes
are compared on identical input. Frames as on the wire: right-handed, +Y up, metres, seconds.

Spawning. The server's scene is fixed at CreateSession, so every object that will ever appear is
declared there, dynamic. Before its spawn_s an object is parked at its spawn place moved by
`PARK_OFFSET_M` (1 km below), where it hides nothing; at the first frame with time_s >= spawn_s
it is sent at its spawn place, a one-frame teleport, which is how a game engine that enables an
object looks on the wire. (A method estimating occluder velocities by finite differences sees that
one teleport; a spawn is a discontinuity in any engine.)

Frames. Frame i (i = 0, 1, ...) has frame number i + 1 and time_s = i / frame_rate_hz. Its
FrameUpdate carries, packed (FrameUpdate.packed_ids / packed_transforms), the transforms of the
targets and dynamic objects that changed since the previous frame (all of them in frame 1).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from camdirector.evaluation.scenario_motion import BounceMotion, KeyframedMotion
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.transforms import RigidTransform
from camdirector.v1 import director_pb2 as pb

PARK_OFFSET_M = np.array([0.0, -1000.0, 0.0])  # where an object waits for its spawn_s, from its spawn place
PACKED_STRIDE = 10  # px, py, pz, qx, qy, qz, qw, sx, sy, sz per packed id (camdirector.v1.FrameUpdate)
STYLE_NUMBERS = (
    "gaze_room_m",
    "preferred_theta_ratio",
    "preferred_phi_deg",
    "response_time_s",
    "max_speed_m_s",
    "max_accel_m_s2",
)


@dataclass(eq=False)
class Shape:
    """An actor's geometry in its local frame; `mesh` is decoded as the server decodes it."""

    kind: str  # box | sphere | cylinder | capsule | mesh
    params: dict[str, Any]  # box: size (3,); sphere: radius; cylinder, capsule: radius, height
    mesh: TriMesh  # local frame, unscaled
    file_bytes: bytes | None = None  # mesh files: the raw OBJ / GLB
    file_path: Path | None = None
    file_scale: float = 1.0  # mesh files: uniform scale, folded into the actor's scale

    def mesh_msg(self) -> pb.Mesh:
        if self.kind == "box":
            sx, sy, sz = self.params["size"]
            return pb.Mesh(primitive=pb.Primitive(box=pb.Primitive.Box(size=pb.Vec3(x=sx, y=sy, z=sz))))
        if self.kind == "sphere":
            return pb.Mesh(primitive=pb.Primitive(sphere=pb.Primitive.Sphere(radius=self.params["radius"])))
        if self.kind == "cylinder":
            return pb.Mesh(primitive=pb.Primitive(cylinder=pb.Primitive.Cylinder(**self.params)))
        if self.kind == "capsule":
            return pb.Mesh(primitive=pb.Primitive(capsule=pb.Primitive.Capsule(**self.params)))
        if self.file_path is not None and self.file_path.suffix.lower() == ".glb":
            return pb.Mesh(glb=self.file_bytes)
        return pb.Mesh(obj=self.file_bytes)

    @property
    def lowest_y(self) -> float:
        """Lowest local y of the (scaled) mesh, m."""
        return float(self.mesh.vertices[:, 1].min()) * self.file_scale

    @property
    def horizontal_radius(self) -> float:
        """Largest horizontal distance of a (scaled) vertex from the local origin, m."""
        return float(np.hypot(self.mesh.vertices[:, 0], self.mesh.vertices[:, 2]).max()) * self.file_scale


@dataclass(eq=False)
class Actor:
    """A target or a scene object. position/rotation/scale: the transform when nothing moves it."""

    id: str
    role: str  # "target" | "object"
    shape: Shape
    position: np.ndarray  # (3,) m
    rotation: np.ndarray  # (4,) xyzw
    scale: np.ndarray  # (3,), the mesh file's scale included
    dynamic: bool  # targets: True
    motion: KeyframedMotion | BounceMotion | None = None
    spawn_s: float | None = None
    aim_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))  # targets, local frame

    def transforms_at(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n,) sorted times -> positions (n, 3), rotations (n, 4) xyzw."""
        times_s = np.asarray(times_s, dtype=np.float64)
        if self.motion is None:
            pos = np.repeat(self.position[None, :], len(times_s), axis=0)
            rot = np.repeat(self.rotation[None, :], len(times_s), axis=0)
        else:
            pos = self.motion.positions_at(times_s)
            rot = self.motion.rotations_at(times_s, self.rotation)
        if self.spawn_s is not None:
            waiting = times_s < self.spawn_s
            if waiting.any():
                first = self.motion.positions_at(np.array([self.spawn_s]))[0] if self.motion else self.position
                pos[waiting] = first + PARK_OFFSET_M
        return pos, rot

    def transform_msg(self, position: np.ndarray, rotation: np.ndarray) -> pb.Transform:
        return pb.Transform(
            position=pb.Vec3(x=position[0], y=position[1], z=position[2]),
            rotation=pb.Quat(x=rotation[0], y=rotation[1], z=rotation[2], w=rotation[3]),
            scale=pb.Vec3(x=self.scale[0], y=self.scale[1], z=self.scale[2]),
        )


def visibility_mode(name: str) -> int:
    """camdirector.v1.VisibilityMode value of a name ("ANTICIPATION", ...); ValueError if unknown."""
    try:
        return pb.VisibilityMode.Value(name.upper())
    except ValueError:
        names = [n for n in pb.VisibilityMode.keys() if n != "VISIBILITY_MODE_UNSPECIFIED"]
        raise ValueError(f"unknown visibility mode {name!r}; expected one of {', '.join(names)}") from None


@dataclass(eq=False)
class Timeline:
    """Every movable actor's transform at every frame time (what the frames send and measure uses)."""

    time_s: np.ndarray  # (n,) s
    frame: np.ndarray  # (n,) frame numbers, from 1
    position: dict[str, np.ndarray]  # id -> (n, 3) m
    rotation: dict[str, np.ndarray]  # id -> (n, 4) xyzw

    def __len__(self) -> int:
        return len(self.time_s)


@dataclass(eq=False)
class Scenario:
    name: str
    description: str
    notes: str
    path: Path | None
    duration_s: float
    frame_rate_hz: float
    seed: int
    lens: dict[str, float]
    style: dict[str, Any]
    targets: list[Actor]
    objects: list[Actor]  # hand-written and generated, in file order

    @property
    def actors(self) -> list[Actor]:
        return [*self.objects, *self.targets]

    @property
    def movable(self) -> list[Actor]:
        """Targets and dynamic objects: the actors a frame may carry."""
        return [a for a in self.actors if a.dynamic]

    def frame_times(self, duration_s: float | None = None) -> np.ndarray:
        """(n,) frame times t = i / frame_rate_hz up to duration_s (default: the scenario's), s."""
        d = self.duration_s if duration_s is None else min(duration_s, self.duration_s)
        return np.arange(int(round(d * self.frame_rate_hz)) + 1) / self.frame_rate_hz

    def timeline(self, duration_s: float | None = None) -> Timeline:
        times = self.frame_times(duration_s)
        pos, rot = {}, {}
        for a in self.movable:
            pos[a.id], rot[a.id] = a.transforms_at(times)
        return Timeline(times, np.arange(1, len(times) + 1, dtype=np.uint64), pos, rot)

    def create_session_request(
        self, visibility: int | str | None = None, *, record: bool = False, timeline: Timeline | None = None
    ) -> pb.CreateSessionRequest:
        """The CreateSessionRequest: every actor at its frame-1 transform; `visibility` overrides
        the file's style mode (a VisibilityMode value or name)."""
        tl = timeline if timeline is not None else self.timeline(0.0)
        objects = []
        for a in self.objects:
            p, q = (tl.position[a.id][0], tl.rotation[a.id][0]) if a.dynamic else (a.position, a.rotation)
            objects.append(pb.SceneObject(id=a.id, mesh=a.shape.mesh_msg(), transform=a.transform_msg(p, q), dynamic=a.dynamic))
        targets = [
            pb.Target(
                id=a.id,
                mesh=a.shape.mesh_msg(),
                transform=a.transform_msg(tl.position[a.id][0], tl.rotation[a.id][0]),
                aim_offset=pb.Vec3(x=a.aim_offset[0], y=a.aim_offset[1], z=a.aim_offset[2]),
            )
            for a in self.targets
        ]
        style = dict(self.style)
        if visibility is not None:
            style["visibility"] = visibility_mode(visibility) if isinstance(visibility, str) else int(visibility)
        style_msg = pb.Style(visibility=style.get("visibility", pb.FRAMING_ONLY))
        for name in ("screen_a", "screen_b"):
            if name in style:
                getattr(style_msg, name).CopyFrom(pb.ScreenPoint(x=style[name][0], y=style[name][1]))
        for name in STYLE_NUMBERS:
            if name in style:
                setattr(style_msg, name, style[name])
        return pb.CreateSessionRequest(
            objects=objects, targets=targets, lens=pb.Lens(**self.lens), style=style_msg, seed=self.seed, record=record
        )

    def frame_updates(self, session_id: str, timeline: Timeline | None = None) -> Iterator[pb.FrameUpdate]:
        """One FrameUpdate per frame of the timeline, lazily; see "Frames" in the module doc."""
        tl = timeline if timeline is not None else self.timeline()
        movable = self.movable
        ids = [a.id for a in movable]
        scale = np.array([a.scale for a in movable])  # (m, 3)
        packed = np.empty((len(tl), len(movable), PACKED_STRIDE))
        packed[:, :, 0:3] = np.stack([tl.position[i] for i in ids], axis=1)
        packed[:, :, 3:7] = np.stack([tl.rotation[i] for i in ids], axis=1)
        packed[:, :, 7:10] = scale[None, :, :]
        changed = np.ones((len(tl), len(movable)), dtype=bool)
        changed[1:] = np.any(packed[1:] != packed[:-1], axis=2)
        for i in range(len(tl)):
            sel = np.flatnonzero(changed[i])
            yield pb.FrameUpdate(
                session_id=session_id,
                frame=int(tl.frame[i]),
                time_s=float(tl.time_s[i]),
                packed_ids=[ids[k] for k in sel],
                packed_transforms=packed[i, sel].ravel().tolist(),
            )


def transform_at(timeline: Timeline, actor: Actor, index: int) -> RigidTransform:
    """The actor's RigidTransform at frame `index` of the timeline (static actors: their own)."""
    if actor.id in timeline.position:
        return RigidTransform(timeline.position[actor.id][index], timeline.rotation[actor.id][index], actor.scale)
    return RigidTransform(actor.position, actor.rotation, actor.scale)
