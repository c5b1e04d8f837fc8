"""A scenario file read into a Scenario, and the scenarios shipped in evaluation/scenarios/.

The file's format and its checks are evaluation/scenario_schema.py's; what they cannot check is
checked here, as the scenario is built: mesh files (relative to the scenario file, decoded as the
server decodes them), primitives the mesh builders refuse, generated items that cannot be placed,
ids used twice. Every refusal is a ScenarioError naming the file and the offending key.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from camdirector.evaluation.scenario import Actor, Scenario, Shape, visibility_mode
from camdirector.evaluation.scenario_generators import PlacementError, scatter, spawn
from camdirector.evaluation.scenario_motion import KeyframedMotion, yaw_quat
from camdirector.evaluation.scenario_schema import (
    ActorSpec,
    MotionSpec,
    ObjectSpec,
    ScatterSpec,
    ScenarioSpec,
    ShapeSpec,
    TargetSpec,
    problem,
)
from camdirector.geometry import meshes
from camdirector.geometry.meshes import MeshError, TriMesh
from camdirector.geometry.transforms import IDENTITY_QUAT

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
_MESH_CACHE: dict[tuple[Path, float], tuple[bytes, TriMesh]] = {}  # (path, mtime) -> file, decoded


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names the file and the offending key."""


class _Refusal(Exception):
    """A problem found while building, at a key of the file."""

    def __init__(self, where: str, problem: str):
        super().__init__(problem)
        self.where, self.problem = where, problem


def _shape(spec: ShapeSpec, where: str, base_dir: Path) -> Shape:
    kind = spec.kind
    try:
        if spec.box is not None:
            size = np.array(spec.box.size)
            return Shape(kind, {"size": tuple(size.tolist())}, meshes.box(size))
        if spec.sphere is not None:
            r = spec.sphere.radius
            return Shape(kind, {"radius": r}, meshes.sphere(r))
        cylinder = spec.cylinder if spec.cylinder is not None else spec.capsule
        if cylinder is not None:
            r, h = cylinder.radius, cylinder.height
            build = meshes.cylinder if kind == "cylinder" else meshes.capsule
            return Shape(kind, {"radius": r, "height": h}, build(r, h))
    except MeshError as exc:
        raise _Refusal(where, str(exc)) from None
    assert spec.mesh is not None
    rel, scale = spec.mesh.path, spec.mesh.scale
    path = (base_dir / rel).resolve()
    suffix = path.suffix.lower()
    if suffix not in (".obj", ".glb"):
        raise _Refusal(f"{where}.mesh.path", f"{rel!r} is not an .obj or .glb file")
    if not path.is_file():
        raise _Refusal(f"{where}.mesh.path", f"{rel!r} does not exist (resolved to {path})")
    key = (path, path.stat().st_mtime)
    if key not in _MESH_CACHE:
        data = path.read_bytes()
        try:
            mesh = meshes.from_glb(data) if suffix == ".glb" else meshes.from_obj(data)
        except MeshError as exc:
            raise _Refusal(f"{where}.mesh.path", f"{rel!r}: {exc}") from None
        _MESH_CACHE[key] = (data, mesh)
    data, mesh = _MESH_CACHE[key]
    return Shape("mesh", {"path": rel, "scale": scale}, mesh, data, path, scale)


def _motion(spec: MotionSpec) -> KeyframedMotion:
    if spec.position_keys is not None:
        keys = np.array(spec.position_keys)
        times, positions = keys[:, 0], keys[:, 1:]
    else:
        assert spec.waypoints is not None and spec.speed_m_s is not None
        positions = np.array(spec.waypoints)
        step = np.linalg.norm(np.diff(positions, axis=0), axis=1)
        start = 0.0 if spec.start_s is None else spec.start_s
        times = start + np.concatenate([[0.0], np.cumsum(step)]) / spec.speed_m_s
    yaw_keys = rotation_keys = None
    if spec.yaw_keys is not None:
        yaw_keys = np.array(spec.yaw_keys)
        yaw_keys[:, 1] = np.radians(yaw_keys[:, 1])
    if spec.rotation_keys is not None:
        rotation_keys = np.array(spec.rotation_keys)
        rotation_keys[:, 1:] /= np.linalg.norm(rotation_keys[:, 1:], axis=1)[:, None]
    return KeyframedMotion(times, positions, spec.interpolation, spec.loop, yaw_keys, rotation_keys, spec.orient == "path")


def _actor(spec: ActorSpec, where: str, base_dir: Path) -> Actor:
    shape = _shape(spec.shape, f"{where}.shape", base_dir)
    position = np.array(spec.position)
    rotation = IDENTITY_QUAT.copy()
    if spec.yaw_deg is not None:
        rotation = yaw_quat(math.radians(spec.yaw_deg))
    if spec.rotation is not None:
        rotation = np.array(spec.rotation)
        rotation = rotation / np.linalg.norm(rotation)
    scale = np.array(spec.scale) * shape.file_scale
    motion = _motion(spec.motion) if spec.motion is not None else None
    if motion is not None:
        position = motion.positions_at(np.array([motion.times[0]]))[0]
    if isinstance(spec, TargetSpec):
        return Actor(spec.id, "target", shape, position, rotation, scale, True, motion, None, np.array(spec.aim_offset))
    assert isinstance(spec, ObjectSpec)
    return Actor(spec.id, "object", shape, position, rotation, scale, spec.dynamic, motion, spec.spawn_s, np.zeros(3))


def _build(spec: ScenarioSpec, base_dir: Path) -> Scenario:
    targets = [_actor(t, f"targets[{i}]", base_dir) for i, t in enumerate(spec.targets)]
    objects = [_actor(o, f"objects[{i}]", base_dir) for i, o in enumerate(spec.objects)]
    for i, g in enumerate(spec.generators):
        where = f"generators[{i}]"
        seed = spec.seed + 1000 + i if g.seed is None else g.seed
        try:
            if isinstance(g, ScatterSpec):
                parts = [
                    (_shape(p.shape, f"{where}.parts[{j}].shape", base_dir), np.array(p.offset)) for j, p in enumerate(g.parts)
                ]
                objects += scatter(g, parts, seed, targets, spec.duration_s)
            else:
                objects += spawn(g, _shape(g.shape, f"{where}.shape", base_dir), seed, targets)
        except PlacementError as exc:
            raise _Refusal(f"{where}.{exc.key}" if exc.key else where, str(exc)) from None
    seen: set[str] = set()
    for a in [*objects, *targets]:
        if a.id in seen:
            raise _Refusal("objects" if a.role == "object" else "targets", f"id {a.id!r} is used twice")
        seen.add(a.id)
    lens = spec.lens.model_dump(exclude_none=True)
    style: dict[str, Any] = {}
    for name, value in spec.style.model_dump(exclude_none=True).items():
        style[name] = visibility_mode(value) if name == "visibility" else tuple(value) if isinstance(value, list) else value
    return Scenario(
        spec.name,
        spec.description,
        spec.notes,
        None,
        spec.duration_s,
        spec.frame_rate_hz,
        spec.seed,
        lens,
        style,
        targets,
        objects,
    )


def parse_scenario(data: Any, *, source: str = "<scenario>", base_dir: Path | str = ".") -> Scenario:
    """A Scenario from parsed JSON; mesh paths resolve against base_dir. Raises ScenarioError."""
    try:
        return _build(ScenarioSpec.model_validate(data), Path(base_dir))
    except ValidationError as exc:
        where, what = problem(exc.errors()[0])
    except _Refusal as exc:
        where, what = exc.where, exc.problem
    raise ScenarioError(f"{source}: {where}: {what}")


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


def shipped_scenarios() -> dict[str, Path]:
    """name (file stem) -> path of every scenario shipped in evaluation/scenarios/."""
    return {p.stem: p for p in sorted(SCENARIO_DIR.glob("*.json"))}
