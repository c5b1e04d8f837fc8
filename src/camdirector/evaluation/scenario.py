"""Scenario files: a scene, how its targets and occluders move, lens, style, duration, frame rate.

A scenario is one JSON file (JSON rather than YAML: the standard library reads it, and JSON has
none of YAML's implicit typing). The same file replays with every visibility mode, so the modes
are compared on identical input. Frames as on the wire: right-handed, +Y up, metres, seconds;
angles in degrees wherever a key ends in `_deg`.

Top level (unknown keys are refused everywhere, so a typo is an error, not a silent default)::

    format          "camdirector.scenario/1"                      required
    name            string, letters digits _ - .                  required
    description     string or list of strings                     optional
    notes           string or list of strings (provenance, fidelity to a paper)   optional
    duration_s      > 0, at most 3600                             required
    frame_rate_hz   > 0, at most 1000; frames at t = i / rate, i = 0 .. round(duration * rate)
    seed            integer >= 0; seeds the session and the generators (default 0)
    lens            {vertical_fov_deg, aspect}                    optional (server defaults)
    style           {screen_a: [x, y], screen_b: [x, y], visibility: MODE, gaze_room_m,
                     preferred_theta_ratio, preferred_phi_deg, response_time_s,
                     max_speed_m_s, max_accel_m_s2}               optional; MODE is a
                    camdirector.v1.VisibilityMode name; a run may override it
    targets         list of 1 or 2 actors (below), with aim_offset  required
    objects         list of actors                                optional
    generators      list of scatter / spawn generators (below)    optional

Actor (a target or a scene object)::

    id          unique string
    shape       one of {"box": {"size": [x, y, z]}}, {"sphere": {"radius": r}},
                {"cylinder": {"radius": r, "height": h}}, {"capsule": {"radius": r, "height": h}},
                {"mesh": {"path": "level.obj", "scale": 1.0}}: primitives are centred on their
                local origin with their axis along +Y (camdirector.v1.Primitive); a mesh file is
                OBJ or GLB, its path relative to the scenario file, sent as Mesh.obj / Mesh.glb,
                and its uniform scale is folded into the transform's scale
    position    [x, y, z] at t = 0 (or the motion's start); default origin
    yaw_deg     turn about +Y (0 faces +Z, the glTF forward), or
    rotation    [qx, qy, qz, qw]; default identity
    scale       number or [sx, sy, sz]; default 1
    dynamic     objects only: false (default) is static for the whole session; true may move.
                Targets always may move.
    motion      keyframes (below); an object with motion must be dynamic
    spawn_s     dynamic objects only: the time it enters the scene (see "Spawning")
    aim_offset  targets only: framed point in the target's local frame, [x, y, z]

Motion::

    position_keys   [[t, x, y, z], ...], times strictly increasing, or
    waypoints       [[x, y, z], ...] with speed_m_s (> 0) and start_s (default 0): key times
                    follow the polyline's arc length at that speed
    interpolation   "linear" (default) or "catmull_rom" (cubic Hermite through every key with
                    tangents (p[k+1] - p[k-1]) / (t[k+1] - t[k-1]), one-sided at the ends)
    loop            false (default): before the first key and after the last the actor holds;
                    true: the motion repeats with period t_last - t_first, the last position must
                    equal the first, and Catmull-Rom tangents wrap around
    orientation, at most one of:
      yaw_keys       [[t, yaw_deg], ...], linear in the written numbers (350 -> 370 turns 20 deg)
      rotation_keys  [[t, qx, qy, qz, qw], ...], spherical linear interpolation
      orient         "path": faces the horizontal direction of travel (local +Z forward),
                     holding the last heading while it stands still
    without any of them the actor keeps its own yaw_deg / rotation.

Generators (procedural, deterministic from their seed; default seed: scenario seed + 1000 + index)::

    {"kind": "scatter", ...}  static objects placed at random, e.g. a forest:
        id_prefix, count, region {"x": [min, max], "z": [min, max]}, ground_y (default 0),
        parts [{"shape": SHAPE, "offset": [x, y, z]}], offset: from the item's ground point to
        the part's lowest point (before scaling); scale [min, max] (uniform factor per item,
        default [1, 1]); random_yaw (default true); min_spacing_m between item centres
        (default 0); clear_of_targets_m: gap kept between an item's footprint (its first part,
        e.g. the trunk under a crown) and every target's path centre line over the whole
        duration (default 0); exclude: list of regions where no item centre lands; seed.
        Ids: prefix + 3-digit index (+ "." + part index with several parts).
    {"kind": "spawn", ...}    dynamic objects entering over time, moving in straight lines in
        random horizontal directions and bouncing off the region's sides (the stress test):
        id_prefix, count, batch (objects per spawn event, default 1), start_s, end_s (spawn
        events spread evenly from start_s to end_s), region, ground_y (the shape's lowest point
        rests on it), shape, speed_m_s [min, max], clear_of_targets_m (distance from the targets
        at the moment of spawning, default 0), seed.

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

import json
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation, Slerp

from camdirector.geometry import meshes
from camdirector.geometry.meshes import MeshError, TriMesh
from camdirector.geometry.transforms import IDENTITY_QUAT, RigidTransform
from camdirector.v1 import director_pb2 as pb

FORMAT = "camdirector.scenario/1"
PARK_OFFSET_M = np.array([0.0, -1000.0, 0.0])  # where an object waits for its spawn_s, from its spawn place
MAX_DURATION_S = 3600.0
MAX_FRAME_RATE_HZ = 1000.0
PACKED_STRIDE = 10  # px, py, pz, qx, qy, qz, qw, sx, sy, sz per packed id (camdirector.v1.FrameUpdate)
_PATH_SAMPLE_HZ = 20.0  # how densely target paths are sampled for generator clearances
_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]+$")
_MAX_PLACEMENT_TRIES = 200  # per generated item, before the generator gives up


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names the file and the offending key."""


# --------------------------------------------------------------------------------------------
# Reading JSON values with a path for every message


class _Fields:
    """The keys of one JSON object; `done()` refuses the keys nobody asked for."""

    def __init__(self, value: Any, where: str, ctx: _Ctx):
        if not isinstance(value, dict):
            raise ctx.error(where or "(top level)", f"must be an object, got {_kind(value)}")
        self.value, self.where, self.ctx = value, where, ctx
        self.used: set[str] = set()

    def has(self, key: str) -> bool:
        return key in self.value

    def at(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def get(self, key: str, read, default: Any = ..., **kwargs) -> Any:
        self.used.add(key)
        if key not in self.value:
            if default is ...:
                raise self.ctx.error(self.where or "(top level)", f"missing required key {key!r}")
            return default
        return read(self.value[key], self.at(key), self.ctx, **kwargs)

    def done(self) -> None:
        extra = sorted(set(self.value) - self.used)
        if extra:
            raise self.ctx.error(self.where or "(top level)", f"unknown key {extra[0]!r}; expected one of "
                                 + ", ".join(sorted(self.used)))


@dataclass
class _Ctx:
    source: str      # file name for messages
    base_dir: Path   # mesh paths are relative to it

    def error(self, where: str, problem: str) -> ScenarioError:
        return ScenarioError(f"{self.source}: {where}: {problem}")


def _kind(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean",
            type(None): "null"}.get(type(value), "a number")


def _number(value, where, ctx, low=None, high=None, low_open=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ctx.error(where, f"must be a finite number, got {value!r}")
    if low is not None and (value < low or (low_open and value == low)):
        raise ctx.error(where, f"must be {'>' if low_open else '>='} {low:g}, got {value!r}")
    if high is not None and value > high:
        raise ctx.error(where, f"must be <= {high:g}, got {value!r}")
    return float(value)


def _positive(value, where, ctx) -> float:
    return _number(value, where, ctx, low=0.0, low_open=True)


def _integer(value, where, ctx, low=None, high=None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ctx.error(where, f"must be an integer, got {value!r}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise ctx.error(where, f"must be in [{low}, {high}], got {value}")
    return int(value)


def _string(value, where, ctx) -> str:
    if not isinstance(value, str) or not value:
        raise ctx.error(where, f"must be a non-empty string, got {value!r}")
    return value


def _text(value, where, ctx) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return "\n".join(value)
    raise ctx.error(where, "must be a string or a list of strings")


def _boolean(value, where, ctx) -> bool:
    if not isinstance(value, bool):
        raise ctx.error(where, f"must be true or false, got {value!r}")
    return value


def _vector(value, where, ctx, n=3) -> np.ndarray:
    if not isinstance(value, list) or len(value) != n:
        raise ctx.error(where, f"must be a list of {n} numbers, got {value!r}")
    return np.array([_number(v, f"{where}[{i}]", ctx) for i, v in enumerate(value)])


def _range(value, where, ctx, positive=False) -> tuple[float, float]:
    lo, hi = _vector(value, where, ctx, 2)
    if lo > hi:
        raise ctx.error(where, f"must be [min, max] with min <= max, got {value!r}")
    if positive and lo <= 0.0:
        raise ctx.error(where, f"must be positive, got {value!r}")
    return float(lo), float(hi)


def _list(value, where, ctx) -> list:
    if not isinstance(value, list):
        raise ctx.error(where, f"must be a list, got {_kind(value)}")
    return value


def _keys(value, where, ctx, width: int) -> np.ndarray:
    """[[t, v1, ... v_width-1], ...] -> (k, width), times strictly increasing."""
    rows = _list(value, where, ctx)
    if not rows:
        raise ctx.error(where, "must hold at least one key")
    out = np.array([_vector(r, f"{where}[{i}]", ctx, width) for i, r in enumerate(rows)])
    if np.any(np.diff(out[:, 0]) <= 0.0):
        i = int(np.argmax(np.diff(out[:, 0]) <= 0.0)) + 1
        raise ctx.error(f"{where}[{i}]", f"key times must be strictly increasing ({out[i - 1, 0]:g} then {out[i, 0]:g})")
    return out


# --------------------------------------------------------------------------------------------
# Shapes


@dataclass(eq=False)
class Shape:
    """An actor's geometry in its local frame; `mesh` is decoded as the server decodes it."""

    kind: str                      # box | sphere | cylinder | capsule | mesh
    params: dict[str, Any]         # box: size (3,); sphere: radius; cylinder, capsule: radius, height
    mesh: TriMesh                  # local frame, unscaled
    file_bytes: bytes | None = None  # mesh files: the raw OBJ / GLB
    file_path: Path | None = None
    file_scale: float = 1.0        # mesh files: uniform scale, folded into the actor's scale

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
        if self.file_path.suffix.lower() == ".glb":
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


_SHAPE_KINDS = ("box", "sphere", "cylinder", "capsule", "mesh")
_MESH_CACHE: dict[tuple[Path, float], tuple[bytes, TriMesh]] = {}  # (path, mtime) -> file, decoded


def _shape(value, where, ctx) -> Shape:
    if not isinstance(value, dict) or len(value) != 1:
        raise ctx.error(where, "must be an object with exactly one of " + ", ".join(_SHAPE_KINDS))
    kind, spec = next(iter(value.items()))
    if kind not in _SHAPE_KINDS:
        raise ctx.error(where, f"unknown shape {kind!r}; expected one of " + ", ".join(_SHAPE_KINDS))
    f = _Fields(spec, f"{where}.{kind}", ctx)
    try:
        if kind == "box":
            size = f.get("size", _vector)
            if np.any(size <= 0):
                raise ctx.error(f.at("size"), f"must be positive, got {size.tolist()}")
            f.done()
            return Shape(kind, {"size": tuple(size.tolist())}, meshes.box(size))
        if kind == "sphere":
            r = f.get("radius", _positive)
            f.done()
            return Shape(kind, {"radius": r}, meshes.sphere(r))
        if kind in ("cylinder", "capsule"):
            r, h = f.get("radius", _positive), f.get("height", _positive)
            f.done()
            build = meshes.cylinder if kind == "cylinder" else meshes.capsule
            return Shape(kind, {"radius": r, "height": h}, build(r, h))
        rel = f.get("path", _string)
        scale = f.get("scale", _positive, 1.0)
        f.done()
    except MeshError as exc:
        raise ctx.error(where, str(exc)) from None
    path = (ctx.base_dir / rel).resolve()
    suffix = path.suffix.lower()
    if suffix not in (".obj", ".glb"):
        raise ctx.error(f"{where}.mesh.path", f"{rel!r} is not an .obj or .glb file")
    key = (path, path.stat().st_mtime) if path.is_file() else None
    if key is None:
        raise ctx.error(f"{where}.mesh.path", f"{rel!r} does not exist (resolved to {path})")
    if key not in _MESH_CACHE:
        data = path.read_bytes()
        try:
            mesh = meshes.from_glb(data) if suffix == ".glb" else meshes.from_obj(data)
        except MeshError as exc:
            raise ctx.error(f"{where}.mesh.path", f"{rel!r}: {exc}") from None
        _MESH_CACHE[key] = (data, mesh)
    data, mesh = _MESH_CACHE[key]
    return Shape("mesh", {"path": rel, "scale": scale}, mesh, data, path, scale)


# --------------------------------------------------------------------------------------------
# Motion


def _yaw_quat(yaw_rad: np.ndarray) -> np.ndarray:
    """(n,) yaw about +Y -> (n, 4) xyzw quaternions."""
    yaw_rad = np.asarray(yaw_rad, dtype=np.float64)
    q = np.zeros(yaw_rad.shape + (4,))
    q[..., 1], q[..., 3] = np.sin(yaw_rad / 2.0), np.cos(yaw_rad / 2.0)
    return q


@dataclass(eq=False)
class KeyframedMotion:
    """Position keys (times (k,), positions (k, 3)) and an optional orientation track."""

    times: np.ndarray
    positions: np.ndarray
    interpolation: str = "linear"         # linear | catmull_rom
    loop: bool = False
    yaw_keys: np.ndarray | None = None    # (k, 2) t, yaw_rad
    rotation_keys: np.ndarray | None = None  # (k, 5) t, qx, qy, qz, qw
    orient_path: bool = False

    def _wrap(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        t0, t1 = self.times[0], self.times[-1]
        if self.loop and t1 > t0:
            return t0 + np.mod(t - t0, t1 - t0)
        return np.clip(t, t0, t1)

    def _tangents(self) -> np.ndarray:
        p, t = self.positions, self.times
        k = len(t)
        m = np.zeros_like(p)
        if k < 2:
            return m
        m[1:-1] = (p[2:] - p[:-2]) / (t[2:] - t[:-2])[:, None]
        if self.loop and k > 2:
            end = (p[1] - p[-2]) / ((t[1] - t[0]) + (t[-1] - t[-2]))
            m[0] = m[-1] = end
        else:
            m[0] = (p[1] - p[0]) / (t[1] - t[0])
            m[-1] = (p[-1] - p[-2]) / (t[-1] - t[-2])
        return m

    def positions_at(self, times_s: np.ndarray) -> np.ndarray:
        """(n,) times -> (n, 3) positions, m."""
        t = self._wrap(times_s)
        p, keys = self.positions, self.times
        if len(keys) == 1:
            return np.repeat(p[:1], len(t), axis=0)
        j = np.clip(np.searchsorted(keys, t, side="right") - 1, 0, len(keys) - 2)
        h = keys[j + 1] - keys[j]
        u = ((t - keys[j]) / h)[:, None]
        if self.interpolation == "linear":
            return p[j] + u * (p[j + 1] - p[j])
        m = self._tangents()
        u2, u3 = u * u, u * u * u
        return ((2 * u3 - 3 * u2 + 1) * p[j] + (u3 - 2 * u2 + u) * h[:, None] * m[j]
                + (-2 * u3 + 3 * u2) * p[j + 1] + (u3 - u2) * h[:, None] * m[j + 1])

    def rotations_at(self, times_s: np.ndarray, base_xyzw: np.ndarray) -> np.ndarray:
        """(n,) times, sorted -> (n, 4) xyzw quaternions."""
        times_s = np.asarray(times_s, dtype=np.float64)
        if self.yaw_keys is not None:
            t = self._wrap(times_s)
            return _yaw_quat(np.interp(t, self.yaw_keys[:, 0], self.yaw_keys[:, 1]))
        if self.rotation_keys is not None:
            if len(self.rotation_keys) == 1:
                return np.repeat(self.rotation_keys[:1, 1:], len(times_s), axis=0)
            keys = self.rotation_keys
            t = np.clip(self._wrap(times_s), keys[0, 0], keys[-1, 0])
            return Slerp(keys[:, 0], Rotation.from_quat(keys[:, 1:]))(t).as_quat()
        if self.orient_path:
            return _yaw_quat(self._path_yaw(times_s, base_xyzw))
        return np.repeat(np.asarray(base_xyzw, dtype=np.float64)[None, :], len(times_s), axis=0)

    def _path_yaw(self, times_s: np.ndarray, base_xyzw: np.ndarray) -> np.ndarray:
        h = 1e-3
        d = self.positions_at(times_s + h) - self.positions_at(times_s - h)
        moving = np.hypot(d[:, 0], d[:, 2]) > 1e-6  # 0.5 mm/s
        yaw = np.arctan2(d[:, 0], d[:, 2])
        if not moving.any():
            fwd = Rotation.from_quat(base_xyzw).apply([0.0, 0.0, 1.0])
            return np.full(len(times_s), math.atan2(fwd[0], fwd[2]))
        # hold the last heading while standing; before the first motion, the first heading
        idx = np.where(moving, np.arange(len(yaw)), -1)
        idx = np.maximum.accumulate(idx)
        idx[idx < 0] = int(np.argmax(moving))
        return yaw[idx]


@dataclass(eq=False)
class BounceMotion:
    """Straight line from `origin` at `velocity`, folded back into the region (a bounce off each side)."""

    origin: np.ndarray    # (3,) m, at start_s
    velocity: np.ndarray  # (3,) m/s, horizontal
    start_s: float
    x_range: tuple[float, float]  # allowed range of the centre, m
    z_range: tuple[float, float]

    def positions_at(self, times_s: np.ndarray) -> np.ndarray:
        t = np.maximum(np.asarray(times_s, dtype=np.float64) - self.start_s, 0.0)
        p = self.origin[None, :] + t[:, None] * self.velocity[None, :]
        p[:, 0] = _fold(p[:, 0], *self.x_range)
        p[:, 2] = _fold(p[:, 2], *self.z_range)
        return p

    def rotations_at(self, times_s: np.ndarray, base_xyzw: np.ndarray) -> np.ndarray:
        return np.repeat(np.asarray(base_xyzw, dtype=np.float64)[None, :], len(times_s), axis=0)


def _fold(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Reflect x into [lo, hi] (a triangle wave): the path of a point bouncing between two walls."""
    span = hi - lo
    if span <= 0.0:
        return np.full_like(x, lo)
    u = np.mod(x - lo, 2.0 * span)
    return lo + np.where(u <= span, u, 2.0 * span - u)


def _motion(value, where, ctx) -> KeyframedMotion:
    f = _Fields(value, where, ctx)
    if f.has("position_keys") == f.has("waypoints"):
        raise ctx.error(where, "give exactly one of 'position_keys' and 'waypoints'")
    if f.has("position_keys"):
        keys = f.get("position_keys", _keys, width=4)
        times, positions = keys[:, 0], keys[:, 1:]
    else:
        rows = f.get("waypoints", _list)
        if len(rows) < 2:
            raise ctx.error(f.at("waypoints"), "must hold at least two points")
        positions = np.array([_vector(r, f"{f.at('waypoints')}[{i}]", ctx) for i, r in enumerate(rows)])
        step = np.linalg.norm(np.diff(positions, axis=0), axis=1)
        if np.any(step <= 0.0):
            i = int(np.argmax(step <= 0.0)) + 1
            raise ctx.error(f"{f.at('waypoints')}[{i}]", "repeats the previous waypoint")
        speed = f.get("speed_m_s", _positive)
        start = f.get("start_s", _number, 0.0)
        times = start + np.concatenate([[0.0], np.cumsum(step)]) / speed
    if not f.has("waypoints"):
        for key in ("speed_m_s", "start_s"):
            if f.has(key):
                raise ctx.error(f.at(key), "only goes with 'waypoints'")
    interpolation = f.get("interpolation", _string, "linear")
    if interpolation not in ("linear", "catmull_rom"):
        raise ctx.error(f.at("interpolation"), f"must be 'linear' or 'catmull_rom', got {interpolation!r}")
    loop = f.get("loop", _boolean, False)
    if loop:
        if len(times) < 3:
            raise ctx.error(f.at("loop"), "a looping motion needs at least three keys")
        if np.linalg.norm(positions[-1] - positions[0]) > 1e-6:
            raise ctx.error(f.at("loop"), "a looping motion must end where it starts (last key == first key)")
    given = [k for k in ("yaw_keys", "rotation_keys", "orient") if f.has(k)]
    if len(given) > 1:
        raise ctx.error(where, f"give at most one of yaw_keys, rotation_keys, orient (got {', '.join(given)})")
    yaw_keys = rotation_keys = None
    orient_path = False
    if f.has("yaw_keys"):
        yaw_keys = f.get("yaw_keys", _keys, width=2)
        yaw_keys[:, 1] = np.radians(yaw_keys[:, 1])
    if f.has("rotation_keys"):
        rotation_keys = f.get("rotation_keys", _keys, width=5)
        norms = np.linalg.norm(rotation_keys[:, 1:], axis=1)
        if np.any(norms < 1e-6):
            raise ctx.error(f.at("rotation_keys"), "holds a zero-length quaternion")
        rotation_keys[:, 1:] /= norms[:, None]
    if f.has("orient"):
        if f.get("orient", _string) != "path":
            raise ctx.error(f.at("orient"), "must be 'path'")
        orient_path = True
    f.done()
    return KeyframedMotion(times, positions, interpolation, loop, yaw_keys, rotation_keys, orient_path)


# --------------------------------------------------------------------------------------------
# Actors, generators, scenario


@dataclass(eq=False)
class Actor:
    """A target or a scene object. position/rotation/scale: the transform when nothing moves it."""

    id: str
    role: str                       # "target" | "object"
    shape: Shape
    position: np.ndarray            # (3,) m
    rotation: np.ndarray            # (4,) xyzw
    scale: np.ndarray               # (3,), the mesh file's scale included
    dynamic: bool                   # targets: True
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
        return pb.Transform(position=pb.Vec3(x=position[0], y=position[1], z=position[2]),
                            rotation=pb.Quat(x=rotation[0], y=rotation[1], z=rotation[2], w=rotation[3]),
                            scale=pb.Vec3(x=self.scale[0], y=self.scale[1], z=self.scale[2]))


def _actor(value, where, ctx, role: str) -> Actor:
    f = _Fields(value, where, ctx)
    actor_id = f.get("id", _string)
    shape = f.get("shape", _shape)
    position = f.get("position", _vector, np.zeros(3))
    if f.has("yaw_deg") and f.has("rotation"):
        raise ctx.error(where, "give at most one of 'yaw_deg' and 'rotation'")
    rotation = IDENTITY_QUAT.copy()
    if f.has("yaw_deg"):
        rotation = _yaw_quat(math.radians(f.get("yaw_deg", _number)))
    if f.has("rotation"):
        rotation = f.get("rotation", _vector, n=4)
        if np.linalg.norm(rotation) < 1e-6:
            raise ctx.error(f.at("rotation"), "is a zero-length quaternion")
        rotation = rotation / np.linalg.norm(rotation)
    scale = _scale(f.get("scale", lambda v, w, c: v, 1.0), f.at("scale"), ctx) * shape.file_scale
    motion = f.get("motion", _motion, None)
    if role == "target":
        dynamic = True
        aim = f.get("aim_offset", _vector, np.zeros(3))
        spawn_s = None
    else:
        dynamic = f.get("dynamic", _boolean, False)
        aim = np.zeros(3)
        spawn_s = f.get("spawn_s", _number, None, low=0.0)
        if motion is not None and not dynamic:
            raise ctx.error(f.at("motion"), "a static object cannot move; set \"dynamic\": true")
        if spawn_s is not None and not dynamic:
            raise ctx.error(f.at("spawn_s"), "only a dynamic object can spawn; set \"dynamic\": true")
    f.done()
    if motion is not None and isinstance(motion, KeyframedMotion):
        position = motion.positions_at(np.array([motion.times[0]]))[0]
    return Actor(actor_id, role, shape, position, rotation, scale, dynamic, motion, spawn_s, aim)


def _scale(value, where, ctx) -> np.ndarray:
    if isinstance(value, list):
        s = _vector(value, where, ctx)
    else:
        s = np.full(3, _number(value, where, ctx))
    if np.any(s <= 0.0):
        raise ctx.error(where, f"must be positive, got {value!r}")
    return s


def _region(value, where, ctx) -> tuple[tuple[float, float], tuple[float, float]]:
    f = _Fields(value, where, ctx)
    x, z = f.get("x", _range), f.get("z", _range)
    f.done()
    return x, z


def _in_region(xz: np.ndarray, region) -> bool:
    (x0, x1), (z0, z1) = region
    return x0 <= xz[0] <= x1 and z0 <= xz[1] <= z1


def _target_paths_xz(targets: list[Actor], duration_s: float) -> cKDTree | None:
    if not targets:
        return None
    times = np.linspace(0.0, duration_s, max(2, int(duration_s * _PATH_SAMPLE_HZ) + 1))
    return cKDTree(np.concatenate([a.transforms_at(times)[0][:, [0, 2]] for a in targets]))


def _scatter(f: _Fields, ctx: _Ctx, seed: int, targets: list[Actor], duration_s: float) -> list[Actor]:
    prefix = f.get("id_prefix", _string)
    count = f.get("count", _integer, low=1, high=100_000)
    region = f.get("region", _region)
    ground_y = f.get("ground_y", _number, 0.0)
    parts = []
    for i, p in enumerate(f.get("parts", _list)):
        pf = _Fields(p, f"{f.at('parts')}[{i}]", ctx)
        parts.append((pf.get("shape", _shape), pf.get("offset", _vector, np.zeros(3))))
        pf.done()
    if not parts:
        raise ctx.error(f.at("parts"), "must hold at least one part")
    scale_lo, scale_hi = f.get("scale", _range, (1.0, 1.0), positive=True)
    random_yaw = f.get("random_yaw", _boolean, True)
    spacing = f.get("min_spacing_m", _number, 0.0, low=0.0)
    clearance = f.get("clear_of_targets_m", _number, 0.0, low=0.0)
    excluded = [_region(v, f"{f.at('exclude')}[{i}]", ctx) for i, v in enumerate(f.get("exclude", _list, []))]
    f.done()
    rng = np.random.default_rng(seed)
    paths = _target_paths_xz(targets, duration_s) if clearance > 0.0 else None
    footprint, offset = parts[0]  # the first part stands on the ground (a trunk under its crown)
    reach = footprint.horizontal_radius + float(np.hypot(offset[0], offset[2]))  # at scale 1, m
    placed: list[np.ndarray] = []
    out: list[Actor] = []
    tries = 0
    while len(placed) < count:
        tries += 1
        if tries > _MAX_PLACEMENT_TRIES * count:
            raise ctx.error(f.where, f"placed only {len(placed)} of {count} items; lower count, "
                            "min_spacing_m or clear_of_targets_m, or widen the region")
        xz = np.array([rng.uniform(*region[0]), rng.uniform(*region[1])])
        scale = rng.uniform(scale_lo, scale_hi)
        yaw = rng.uniform(-math.pi, math.pi) if random_yaw else 0.0
        if any(_in_region(xz, r) for r in excluded):
            continue
        if placed and np.min(np.linalg.norm(np.array(placed) - xz, axis=1)) < spacing:
            continue
        if paths is not None and paths.query(xz)[0] < clearance + reach * scale:
            continue
        placed.append(xz)
        rot = _yaw_quat(yaw)
        r = Rotation.from_quat(rot)
        index = len(placed) - 1
        for j, (shape, offset) in enumerate(parts):
            local = offset * scale
            local[1] -= shape.lowest_y * scale  # offset is to the part's lowest point
            pos = np.array([xz[0], ground_y, xz[1]]) + r.apply(local)
            part_id = f"{prefix}{index:03d}" + (f".{j}" if len(parts) > 1 else "")
            out.append(Actor(part_id, "object", shape, pos, rot.copy(),
                             np.full(3, scale * shape.file_scale), dynamic=False))
    return out


def _spawn(f: _Fields, ctx: _Ctx, seed: int, targets: list[Actor]) -> list[Actor]:
    prefix = f.get("id_prefix", _string)
    count = f.get("count", _integer, low=1, high=100_000)
    batch = f.get("batch", _integer, 1, low=1, high=100_000)
    start_s = f.get("start_s", _number, 0.0, low=0.0)
    end_s = f.get("end_s", _number, start_s, low=start_s)
    region = f.get("region", _region)
    ground_y = f.get("ground_y", _number, 0.0)
    shape = f.get("shape", _shape)
    speed_lo, speed_hi = f.get("speed_m_s", _range, positive=True)
    clearance = f.get("clear_of_targets_m", _number, 0.0, low=0.0)
    f.done()
    rng = np.random.default_rng(seed)
    radius = shape.horizontal_radius
    x_range = (region[0][0] + radius, region[0][1] - radius)
    z_range = (region[1][0] + radius, region[1][1] - radius)
    if x_range[0] > x_range[1] or z_range[0] > z_range[1]:
        raise ctx.error(f.at("region"), "is narrower than the shape")
    events = -(-count // batch)
    out = []
    for i in range(count):
        t = start_s + (end_s - start_s) * ((i // batch) / (events - 1) if events > 1 else 0.0)
        near = [a.transforms_at(np.array([t]))[0][0, [0, 2]] for a in targets]
        for _ in range(_MAX_PLACEMENT_TRIES):
            xz = np.array([rng.uniform(*x_range), rng.uniform(*z_range)])
            if all(np.linalg.norm(xz - p) >= clearance + radius for p in near):
                break
        else:
            raise ctx.error(f.where, f"cannot place {prefix}{i:03d} {clearance:g} m clear of the targets at "
                            f"t = {t:g} s; lower clear_of_targets_m or widen the region")
        heading = rng.uniform(-math.pi, math.pi)
        speed = rng.uniform(speed_lo, speed_hi)
        origin = np.array([xz[0], ground_y - shape.lowest_y, xz[1]])
        velocity = speed * np.array([math.sin(heading), 0.0, math.cos(heading)])
        motion = BounceMotion(origin, velocity, t, x_range, z_range)
        out.append(Actor(f"{prefix}{i:03d}", "object", shape, origin, IDENTITY_QUAT.copy(),
                         np.full(3, shape.file_scale), dynamic=True, motion=motion, spawn_s=t))
    return out


def _lens(value, where, ctx) -> dict[str, float]:
    f = _Fields(value, where, ctx)
    out = {}
    if f.has("vertical_fov_deg"):
        out["vertical_fov_deg"] = f.get("vertical_fov_deg", _number, low=1.0, high=170.0)
    if f.has("aspect"):
        out["aspect"] = f.get("aspect", _number, low=0.1, high=10.0)
    f.done()
    return out


_STYLE_NUMBERS = ("gaze_room_m", "preferred_theta_ratio", "preferred_phi_deg", "response_time_s",
                  "max_speed_m_s", "max_accel_m_s2")


def visibility_mode(name: str) -> int:
    """camdirector.v1.VisibilityMode value of a name ("ANTICIPATION", ...); ValueError if unknown."""
    try:
        return pb.VisibilityMode.Value(name.upper())
    except ValueError:
        names = [n for n in pb.VisibilityMode.keys() if n != "VISIBILITY_MODE_UNSPECIFIED"]
        raise ValueError(f"unknown visibility mode {name!r}; expected one of {', '.join(names)}") from None


def _style(value, where, ctx) -> dict[str, Any]:
    f = _Fields(value, where, ctx)
    out: dict[str, Any] = {}
    for name in ("screen_a", "screen_b"):
        if f.has(name):
            x, y = f.get(name, _vector, n=2)
            if not (-1.0 <= x <= 1.0 and -1.0 <= y <= 1.0):
                raise ctx.error(f.at(name), f"must have x and y in [-1, 1], got {[x, y]}")
            out[name] = (float(x), float(y))
    if f.has("visibility"):
        name = f.get("visibility", _string)
        try:
            out["visibility"] = visibility_mode(name)
        except ValueError as exc:
            raise ctx.error(f.at("visibility"), str(exc)) from None
    for name in _STYLE_NUMBERS:
        if f.has(name):
            out[name] = f.get(name, _number)
    f.done()
    return out


@dataclass(eq=False)
class Timeline:
    """Every movable actor's transform at every frame time (what the frames send and measure uses)."""

    time_s: np.ndarray                         # (n,) s
    frame: np.ndarray                          # (n,) frame numbers, from 1
    position: dict[str, np.ndarray]            # id -> (n, 3) m
    rotation: dict[str, np.ndarray]            # id -> (n, 4) xyzw

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
    objects: list[Actor]      # hand-written and generated, in file order

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

    def create_session_request(self, visibility: int | str | None = None, *, record: bool = False,
                               timeline: Timeline | None = None) -> pb.CreateSessionRequest:
        """The CreateSessionRequest: every actor at its frame-1 transform; `visibility` overrides
        the file's style mode (a VisibilityMode value or name)."""
        tl = timeline if timeline is not None else self.timeline(0.0)
        objects = []
        for a in self.objects:
            p, q = (tl.position[a.id][0], tl.rotation[a.id][0]) if a.dynamic else (a.position, a.rotation)
            objects.append(pb.SceneObject(id=a.id, mesh=a.shape.mesh_msg(), transform=a.transform_msg(p, q),
                                          dynamic=a.dynamic))
        targets = [pb.Target(id=a.id, mesh=a.shape.mesh_msg(),
                             transform=a.transform_msg(tl.position[a.id][0], tl.rotation[a.id][0]),
                             aim_offset=pb.Vec3(x=a.aim_offset[0], y=a.aim_offset[1], z=a.aim_offset[2]))
                   for a in self.targets]
        style = dict(self.style)
        if visibility is not None:
            style["visibility"] = visibility_mode(visibility) if isinstance(visibility, str) else int(visibility)
        style_msg = pb.Style(visibility=style.get("visibility", pb.FRAMING_ONLY))
        for name in ("screen_a", "screen_b"):
            if name in style:
                getattr(style_msg, name).CopyFrom(pb.ScreenPoint(x=style[name][0], y=style[name][1]))
        for name in _STYLE_NUMBERS:
            if name in style:
                setattr(style_msg, name, style[name])
        return pb.CreateSessionRequest(objects=objects, targets=targets, lens=pb.Lens(**self.lens),
                                       style=style_msg, seed=self.seed, record=record)

    def frame_updates(self, session_id: str, timeline: Timeline | None = None) -> Iterator[pb.FrameUpdate]:
        """One FrameUpdate per frame of the timeline, lazily; see "Frames" in the module doc."""
        tl = timeline if timeline is not None else self.timeline()
        movable = self.movable
        ids = [a.id for a in movable]
        scale = np.array([a.scale for a in movable])                              # (m, 3)
        packed = np.empty((len(tl), len(movable), PACKED_STRIDE))
        packed[:, :, 0:3] = np.stack([tl.position[i] for i in ids], axis=1)
        packed[:, :, 3:7] = np.stack([tl.rotation[i] for i in ids], axis=1)
        packed[:, :, 7:10] = scale[None, :, :]
        changed = np.ones((len(tl), len(movable)), dtype=bool)
        changed[1:] = np.any(packed[1:] != packed[:-1], axis=2)
        for i in range(len(tl)):
            sel = np.flatnonzero(changed[i])
            yield pb.FrameUpdate(session_id=session_id, frame=int(tl.frame[i]), time_s=float(tl.time_s[i]),
                                 packed_ids=[ids[k] for k in sel], packed_transforms=packed[i, sel].ravel().tolist())


def parse_scenario(data: Any, *, source: str = "<scenario>", base_dir: Path | str = ".") -> Scenario:
    """A Scenario from parsed JSON; mesh paths resolve against base_dir. Raises ScenarioError."""
    ctx = _Ctx(source, Path(base_dir))
    f = _Fields(data, "", ctx)
    fmt = f.get("format", _string)
    if fmt != FORMAT:
        raise ctx.error("format", f"must be {FORMAT!r}, got {fmt!r}")
    name = f.get("name", _string)
    if not _NAME_RE.match(name):
        raise ctx.error("name", f"may hold only letters, digits, '_', '-' and '.', got {name!r}")
    description = f.get("description", _text, "")
    notes = f.get("notes", _text, "")
    duration_s = f.get("duration_s", _number, low=0.0, low_open=True, high=MAX_DURATION_S)
    rate = f.get("frame_rate_hz", _number, low=0.0, low_open=True, high=MAX_FRAME_RATE_HZ)
    seed = f.get("seed", _integer, 0, low=0, high=2**63 - 1)
    lens = f.get("lens", _lens, {})
    style = f.get("style", _style, {})
    targets = [_actor(v, f"targets[{i}]", ctx, "target") for i, v in enumerate(f.get("targets", _list))]
    if not 1 <= len(targets) <= 2:
        raise ctx.error("targets", f"a session frames one or two targets, got {len(targets)}")
    objects = [_actor(v, f"objects[{i}]", ctx, "object") for i, v in enumerate(f.get("objects", _list, []))]
    for i, value in enumerate(f.get("generators", _list, [])):
        where = f"generators[{i}]"
        g = _Fields(value, where, ctx)
        kind = g.get("kind", _string)
        gseed = g.get("seed", _integer, seed + 1000 + i, low=0, high=2**63 - 1)
        if kind == "scatter":
            objects += _scatter(g, ctx, gseed, targets, duration_s)
        elif kind == "spawn":
            objects += _spawn(g, ctx, gseed, targets)
        else:
            raise ctx.error(f"{where}.kind", f"must be 'scatter' or 'spawn', got {kind!r}")
    f.done()
    seen: set[str] = set()
    for a in [*objects, *targets]:
        if a.id in seen:
            raise ctx.error("objects" if a.role == "object" else "targets", f"id {a.id!r} is used twice")
        seen.add(a.id)
    return Scenario(name, description, notes, None, duration_s, rate, seed, lens, style, targets, objects)


def load_scenario(path: Path | str) -> Scenario:
    """Reads and validates a scenario file. Raises ScenarioError naming the file and key."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ScenarioError(f"{path.name}: not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    scenario = parse_scenario(data, source=path.name, base_dir=path.resolve().parent)
    scenario.path = path
    return scenario


SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"


def shipped_scenarios() -> dict[str, Path]:
    """name (file stem) -> path of every scenario shipped in evaluation/scenarios/."""
    return {p.stem: p for p in sorted(SCENARIO_DIR.glob("*.json"))}


def transform_at(timeline: Timeline, actor: Actor, index: int) -> RigidTransform:
    """The actor's RigidTransform at frame `index` of the timeline (static actors: their own)."""
    if actor.id in timeline.position:
        return RigidTransform(timeline.position[actor.id][index], timeline.rotation[actor.id][index], actor.scale)
    return RigidTransform(actor.position, actor.rotation, actor.scale)
