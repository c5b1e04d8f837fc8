"""Scenario files: what one may say, as pydantic models, and a refusal's message.

A scenario is one JSON file (JSON rather than YAML: the standard library reads it, and JSON has
none of YAML's implicit typing). Frames as on the wire: right-handed, +Y up, metres, seconds;
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
    spawn_s     dynamic objects only: the time it enters the scene (see "Spawning" in
                evaluation/scenario.py)
    aim_offset  targets only: framed point in the target's local frame, [x, y, z]

Motion (evaluation/scenario_motion.py)::

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

Generators (procedural, deterministic from their seed; default seed: scenario seed + 1000 + index;
evaluation/scenario_generators.py)::

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

A refusal names the offending key by its path and says what is wrong with it (`problem`): the
models check types, ranges and which keys go together; what needs the files beside the scenario
or the placement of generated items is checked when the scenario is built
(evaluation/scenario_file.py).
"""

from __future__ import annotations

import re
import types
from typing import Annotated, Any, Literal, Union, cast, get_args, get_origin

import numpy as np
from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, Strict, model_validator
from pydantic_core import ErrorDetails, PydanticCustomError

from camdirector.evaluation.scenario import visibility_mode

FORMAT = "camdirector.scenario/1"
MAX_DURATION_S = 3600.0
MAX_FRAME_RATE_HZ = 1000.0
MAX_GENERATED = 100_000  # items of one generator
_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]+$")


def _refuse(problem: str, at: tuple[str | int, ...] = ()) -> PydanticCustomError:
    """A refusal saying `problem`; `at`: where inside the validated value it lies (a key, an index)."""
    return PydanticCustomError("scenario", "{problem}", {"problem": problem, "at": at})


def _kind(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean", type(None): "null"}.get(
        type(value), "a number"
    )


# --------------------------------------------------------------------------------------------
# Values


def _vector_of(n: int) -> BeforeValidator:
    def check(value: Any) -> Any:
        if not isinstance(value, list) or len(value) != n:
            raise _refuse(f"must be a list of {n} numbers, got {value!r}")
        return value

    return BeforeValidator(check)


def _positive_vector(value: list[float]) -> list[float]:
    if any(v <= 0.0 for v in value):
        raise _refuse(f"must be positive, got {value}")
    return value


def _ordered(value: list[float]) -> list[float]:
    if value[0] > value[1]:
        raise _refuse(f"must be [min, max] with min <= max, got {value!r}")
    return value


def _positive_range(value: list[float]) -> list[float]:
    if value[0] <= 0.0:
        raise _refuse(f"must be positive, got {value!r}")
    return value


def _text(value: Any) -> Any:
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return "\n".join(value)
    if not isinstance(value, str):
        raise _refuse("must be a string or a list of strings")
    return value


def _name(value: str) -> str:
    if not _NAME_RE.match(value):
        raise _refuse(f"may hold only letters, digits, '_', '-' and '.', got {value!r}")
    return value


def _keys_of(width: int) -> AfterValidator:
    """[[t, v1, ... v_width-1], ...]: at least one key, times strictly increasing."""

    def check(rows: list[list[float]]) -> list[list[float]]:
        if not rows:
            raise _refuse("must hold at least one key")
        for i in range(1, len(rows)):
            if rows[i][0] <= rows[i - 1][0]:
                raise _refuse(f"key times must be strictly increasing ({rows[i - 1][0]:g} then {rows[i][0]:g})", (i,))
        return rows

    return AfterValidator(check)


def _unit_quaternions(rows: list[list[float]]) -> list[list[float]]:
    if any(np.linalg.norm(r[1:]) < 1e-6 for r in rows):
        raise _refuse("holds a zero-length quaternion")
    return rows


def _nonzero_quaternion(value: list[float]) -> list[float]:
    if np.linalg.norm(value) < 1e-6:
        raise _refuse("is a zero-length quaternion")
    return value


def _scale(value: Any) -> Any:
    """A number is a uniform scale."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [value, value, value]
    if not isinstance(value, list):
        raise _refuse(f"must be a finite number, got {value!r}")
    if len(value) != 3:
        raise _refuse(f"must be a list of 3 numbers, got {value!r}")
    return value


def _screen_point(value: list[float]) -> list[float]:
    x, y = value
    if not (-1.0 <= x <= 1.0 and -1.0 <= y <= 1.0):
        raise _refuse(f"must have x and y in [-1, 1], got {value}")
    return value


def _mode(name: str) -> str:
    try:
        visibility_mode(name)
    except ValueError as exc:
        raise _refuse(str(exc)) from None
    return name


def _at_least(n: int, what: str) -> AfterValidator:
    def check(items: list[Any]) -> list[Any]:
        if len(items) < n:
            raise _refuse(f"must hold at least {what}")
        return items

    return AfterValidator(check)


def _distinct_waypoints(points: list[list[float]]) -> list[list[float]]:
    for i in range(1, len(points)):
        if np.linalg.norm(np.subtract(points[i], points[i - 1])) <= 0.0:
            raise _refuse("repeats the previous waypoint", (i,))
    return points


Number = Annotated[float, Strict(), Field(allow_inf_nan=False)]
NonNegative = Annotated[Number, Field(ge=0.0)]
Positive = Annotated[Number, Field(gt=0.0)]
Integer = Annotated[int, Strict()]
Seed = Annotated[Integer, Field(ge=0, le=2**63 - 1)]
Count = Annotated[Integer, Field(ge=1, le=MAX_GENERATED)]
Boolean = Annotated[bool, Strict()]
String = Annotated[str, Strict(), Field(min_length=1)]
Text = Annotated[str, BeforeValidator(_text)]
Vector2 = Annotated[list[Number], _vector_of(2)]
Vector3 = Annotated[list[Number], _vector_of(3)]
Vector4 = Annotated[list[Number], _vector_of(4)]
Range = Annotated[Vector2, AfterValidator(_ordered)]
PositiveRange = Annotated[Range, AfterValidator(_positive_range)]
ScreenPoint = Annotated[Vector2, AfterValidator(_screen_point)]
PositionKeys = Annotated[list[Vector4], _keys_of(4)]
YawKeys = Annotated[list[Vector2], _keys_of(2)]
RotationKeys = Annotated[list[Annotated[list[Number], _vector_of(5)]], _keys_of(5), AfterValidator(_unit_quaternions)]


class Spec(BaseModel):
    """A JSON object of the file: every key named, none other accepted."""

    model_config = ConfigDict(extra="forbid", frozen=True)


# --------------------------------------------------------------------------------------------
# Shapes


class BoxSpec(Spec):
    size: Annotated[Vector3, AfterValidator(_positive_vector)]


class SphereSpec(Spec):
    radius: Positive


class CylinderSpec(Spec):
    radius: Positive
    height: Positive


class MeshFileSpec(Spec):
    path: String
    scale: Positive = 1.0


SHAPE_KINDS = ("box", "sphere", "cylinder", "capsule", "mesh")


class ShapeSpec(Spec):
    """Exactly one of its keys."""

    box: BoxSpec | None = None
    sphere: SphereSpec | None = None
    cylinder: CylinderSpec | None = None
    capsule: CylinderSpec | None = None
    mesh: MeshFileSpec | None = None

    @model_validator(mode="before")
    @classmethod
    def _one_kind(cls, value: Any) -> Any:
        if not isinstance(value, dict) or len(value) != 1:
            raise _refuse("must be an object with exactly one of " + ", ".join(SHAPE_KINDS))
        kind = next(iter(value))
        if kind not in SHAPE_KINDS:
            raise _refuse(f"unknown shape {kind!r}; expected one of " + ", ".join(SHAPE_KINDS))
        return value

    @property
    def kind(self) -> str:
        return next(k for k in SHAPE_KINDS if getattr(self, k) is not None)


# --------------------------------------------------------------------------------------------
# Motion and actors


class MotionSpec(Spec):
    position_keys: PositionKeys | None = None
    waypoints: Annotated[list[Vector3], _at_least(2, "two points"), AfterValidator(_distinct_waypoints)] | None = None
    speed_m_s: Positive | None = None
    start_s: Number | None = None
    interpolation: Literal["linear", "catmull_rom"] = "linear"
    loop: Boolean = False
    yaw_keys: YawKeys | None = None
    rotation_keys: RotationKeys | None = None
    orient: Literal["path"] | None = None

    @model_validator(mode="after")
    def _consistent(self) -> MotionSpec:
        if (self.position_keys is None) == (self.waypoints is None):
            raise _refuse("give exactly one of 'position_keys' and 'waypoints'")
        if self.waypoints is not None and self.speed_m_s is None:
            raise _refuse("missing required key 'speed_m_s'")
        if self.waypoints is None:
            for key in ("speed_m_s", "start_s"):
                if getattr(self, key) is not None:
                    raise _refuse("only goes with 'waypoints'", (key,))
        if self.loop:
            points = self.waypoints if self.waypoints is not None else [k[1:] for k in self.position_keys or []]
            if len(points) < 3:
                raise _refuse("a looping motion needs at least three keys", ("loop",))
            if np.linalg.norm(np.subtract(points[-1], points[0])) > 1e-6:
                raise _refuse("a looping motion must end where it starts (last key == first key)", ("loop",))
        given = [k for k in ("yaw_keys", "rotation_keys", "orient") if getattr(self, k) is not None]
        if len(given) > 1:
            raise _refuse(f"give at most one of yaw_keys, rotation_keys, orient (got {', '.join(given)})")
        return self


class ActorSpec(Spec):
    id: String
    shape: ShapeSpec
    position: Vector3 = [0.0, 0.0, 0.0]
    yaw_deg: Number | None = None
    rotation: Annotated[Vector4, AfterValidator(_nonzero_quaternion)] | None = None
    scale: Annotated[list[Number], BeforeValidator(_scale), AfterValidator(_positive_vector)] = [1.0, 1.0, 1.0]
    motion: MotionSpec | None = None

    @model_validator(mode="after")
    def _one_orientation(self) -> ActorSpec:
        if self.yaw_deg is not None and self.rotation is not None:
            raise _refuse("give at most one of 'yaw_deg' and 'rotation'")
        return self


class TargetSpec(ActorSpec):
    aim_offset: Vector3 = [0.0, 0.0, 0.0]


class ObjectSpec(ActorSpec):
    dynamic: Boolean = False
    spawn_s: NonNegative | None = None

    @model_validator(mode="after")
    def _moves_only_if_dynamic(self) -> ObjectSpec:
        if self.motion is not None and not self.dynamic:
            raise _refuse('a static object cannot move; set "dynamic": true', ("motion",))
        if self.spawn_s is not None and not self.dynamic:
            raise _refuse('only a dynamic object can spawn; set "dynamic": true', ("spawn_s",))
        return self


# --------------------------------------------------------------------------------------------
# Generators


class RegionSpec(Spec):
    x: Range
    z: Range


class PartSpec(Spec):
    shape: ShapeSpec
    offset: Vector3 = [0.0, 0.0, 0.0]


class ScatterSpec(Spec):
    kind: Literal["scatter"]
    id_prefix: String
    count: Count
    region: RegionSpec
    ground_y: Number = 0.0
    parts: Annotated[list[PartSpec], _at_least(1, "one part")]
    scale: PositiveRange = [1.0, 1.0]
    random_yaw: Boolean = True
    min_spacing_m: NonNegative = 0.0
    clear_of_targets_m: NonNegative = 0.0
    exclude: list[RegionSpec] = []
    seed: Seed | None = None


class SpawnSpec(Spec):
    kind: Literal["spawn"]
    id_prefix: String
    count: Count
    batch: Count = 1
    start_s: NonNegative = 0.0
    end_s: Number | None = None  # default start_s
    region: RegionSpec
    ground_y: Number = 0.0
    shape: ShapeSpec
    speed_m_s: PositiveRange
    clear_of_targets_m: NonNegative = 0.0
    seed: Seed | None = None

    @model_validator(mode="after")
    def _ends_after_start(self) -> SpawnSpec:
        if self.end_s is not None and self.end_s < self.start_s:
            raise _refuse(f"must be >= {self.start_s:g}, got {self.end_s!r}", ("end_s",))
        return self


# --------------------------------------------------------------------------------------------
# The file


class LensSpec(Spec):
    vertical_fov_deg: Annotated[Number, Field(ge=1.0, le=170.0)] | None = None
    aspect: Annotated[Number, Field(ge=0.1, le=10.0)] | None = None


class StyleSpec(Spec):
    screen_a: ScreenPoint | None = None
    screen_b: ScreenPoint | None = None
    visibility: Annotated[String, AfterValidator(_mode)] | None = None
    gaze_room_m: Number | None = None
    preferred_theta_ratio: Number | None = None
    preferred_phi_deg: Number | None = None
    response_time_s: Number | None = None
    max_speed_m_s: Number | None = None
    max_accel_m_s2: Number | None = None


def _one_or_two_targets(targets: list[TargetSpec]) -> list[TargetSpec]:
    if not 1 <= len(targets) <= 2:
        raise _refuse(f"a session frames one or two targets, got {len(targets)}")
    return targets


class ScenarioSpec(Spec):
    format: Literal["camdirector.scenario/1"]
    name: Annotated[String, AfterValidator(_name)]
    description: Text = ""
    notes: Text = ""
    duration_s: Annotated[Positive, Field(le=MAX_DURATION_S)]
    frame_rate_hz: Annotated[Positive, Field(le=MAX_FRAME_RATE_HZ)]
    seed: Seed = 0
    lens: LensSpec = LensSpec()
    style: StyleSpec = StyleSpec()
    targets: Annotated[list[TargetSpec], AfterValidator(_one_or_two_targets)]
    objects: list[ObjectSpec] = []
    generators: list[Annotated[ScatterSpec | SpawnSpec, Field(discriminator="kind")]] = []


# --------------------------------------------------------------------------------------------
# Messages


def problem(error: ErrorDetails) -> tuple[str, str]:
    """(path of the offending key, what is wrong) of one of pydantic's errors on a ScenarioSpec, in
    the file's own terms: `targets[0].shape.sphere.radius`, "must be > 0, got -1"."""
    kind, ctx, value = error["type"], error.get("ctx", {}), error["input"]
    loc: tuple[str | int, ...] = tuple(error["loc"])
    if kind in ("missing", "extra_forbidden", "union_tag_not_found"):
        key, loc = (loc[-1], loc[:-1]) if kind != "union_tag_not_found" else ("kind", loc)
        if kind == "extra_forbidden":
            return _path(loc), f"unknown key {key!r}; expected one of " + ", ".join(sorted(_fields_at(loc)))
        return _path(loc), f"missing required key {key!r}"
    if kind == "scenario":
        return _path(loc + tuple(ctx["at"])), error["msg"]
    if kind == "union_tag_invalid":
        tags = " or ".join(ctx["expected_tags"].rsplit(", ", 1))
        return _path(loc + ("kind",)), f"must be {tags}, got {ctx['tag']!r}"
    if kind == "literal_error":
        return _path(loc), f"must be {ctx['expected']}, got {value!r}"
    bound = {
        "greater_than": (">", "gt"),
        "greater_than_equal": (">=", "ge"),
        "less_than": ("<", "lt"),
        "less_than_equal": ("<=", "le"),
    }
    if kind in bound:
        sign, name = bound[kind]
        return _path(loc), f"must be {sign} {ctx[name]:g}, got {value!r}"
    said = {
        "float_type": "must be a finite number",
        "finite_number": "must be a finite number",
        "int_type": "must be an integer",
        "bool_type": "must be true or false",
        "string_type": "must be a non-empty string",
        "string_too_short": "must be a non-empty string",
    }
    if kind in said:
        return _path(loc), f"{said[kind]}, got {value!r}"
    if kind in ("model_type", "model_attributes_type", "dict_type"):
        return _path(loc), f"must be an object, got {_kind(value)}"
    if kind == "list_type":
        return _path(loc), f"must be a list, got {_kind(value)}"
    return _path(loc), error["msg"]


def _path(loc: tuple[str | int, ...]) -> str:
    """`targets[0].shape`: pydantic's location with the union members it names left out."""
    return _walk(loc)[0]


def _fields_at(loc: tuple[str | int, ...]) -> list[str]:
    """The keys the object at `loc` may hold."""
    models = _models(_walk(loc)[1])
    return list(models[0].model_fields) if models else []


def _walk(loc: tuple[str | int, ...]) -> tuple[str, Any]:
    """(the file's path to `loc`, the annotation there), from ScenarioSpec down. A key that names
    one of several models (a generator's kind) picks the member and is no part of the path."""
    out, annotation = "", cast(Any, ScenarioSpec)
    for key in loc:
        models = _models(annotation)
        if isinstance(key, str) and len(models) > 1 and not any(key in m.model_fields for m in models):
            annotation = next((m for m in models if get_args(m.model_fields["kind"].annotation) == (key,)), None)
            continue
        out += f"[{key}]" if isinstance(key, int) else (f".{key}" if out else key)
        annotation = (
            next((_bare(get_args(m)[0]) for m in _members(annotation) if get_origin(m) is list), None)
            if isinstance(key, int)
            else next((_bare(m.model_fields[key].annotation) for m in models if key in m.model_fields), None)
        )
    return out or "(top level)", annotation


def _models(annotation: Any) -> list[type[BaseModel]]:
    return [m for m in _members(annotation) if isinstance(m, type) and issubclass(m, BaseModel)]


def _bare(annotation: Any) -> Any:
    while get_origin(annotation) is Annotated:
        annotation = get_args(annotation)[0]
    return annotation


def _members(annotation: Any) -> list[Any]:
    """A union's members (None left out), or the one annotation."""
    annotation = _bare(annotation)
    if get_origin(annotation) in (Union, types.UnionType):
        return [_bare(a) for a in get_args(annotation) if a is not type(None)]
    return [annotation]
