"""The transport edge: camdirector.v1 messages in, the pipeline's own types out, and back.

Everything that arrives from a client is validated here and refused with a DirectorError that
names the field; past this module the pipeline sees only dataclasses and numpy arrays. A session
with `style.rig = RIG_TRACKS` needs exactly one target and a `level_id` the server's level
registry holds for the session's tenant (loaded here, through the worker's LevelCache, so a session never starts without
its level); `level_id` without that rig, and the TRACKS style fields under the TORIC rig, are
refused rather than ignored. The rig cannot change during a session (UpdateStyle): TORIC to
TRACKS would need a level the session was not created with, and TRACKS to TORIC a second framing
setup for a scene built around one actor; a new session does either.

Any target's `display_name`, and a MATCH target's `team_name`, is at most 64 code points with no
control character: shown to people, never an identity.
A MATCH session (`RIG_MATCH`) has 2 to 64 targets, the players, each with its `team`; its
`level_id` is optional; `delay_s` in [0, 300] is the broadcast delay (refused for the other rigs,
as are `events` and the MATCH style fields). A frame's events name players of the session
(a kill both its attacker and its victim), have a priority in [0, 15] (0: the kind's default) and a
time no later than the frame's time plus the delay (0: the frame's time). A frame's `player_stats`
(MATCH only, like events) each name a player of the session, none twice. A MATCH style's
director is a name of the director registry (pipeline/match/director_registry.py):
`match_director_name` when set, else the built-in of the `match_director` enum (unset: "planned");
an unknown name is refused, listing the registered ones, and `shown_style` shows the resolved name back.

`pose_outputs` (at most 8) are checked here, before the scene: a known format, an address
`udp://HOST:PORT` whose HOST is an IPv4 address or a name that resolves to one (once, here, within
2 s; IPv6 is refused: OpenTrackIO 1.0.1 has none), a port in [1, 65535], a source number in the
format's range and a sensor height in [1, 100] mm (0: 24), and the address it resolved to inside one
of the networks the operator allowed (`ServerSettings.pose_output_allow`, loopback by default): a
key to a session is not a key to make the server send datagrams anywhere. Sending is
worker/pose_out.py's.
"""

from __future__ import annotations

import ipaddress
import math
import socket
import unicodedata
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any, Protocol

import numpy as np

import camdirector._native as native
from camdirector.errors import exhausted, invalid, not_found, precondition
from camdirector.geometry import meshes
from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.meshes import MeshError, TriMesh
from camdirector.geometry.toric import composition_angle
from camdirector.geometry.transforms import IDENTITY_QUAT, RigidTransform
from camdirector.infra.tenants import DEFAULT_TENANT
from camdirector.pipeline.inputs import EventKind, FrameInput, GameEvent, ObjectSpec, PlayerStats, SceneSpec, TargetSpec
from camdirector.pipeline.match.director_registry import DEFAULT_DIRECTOR, director_by_wire, director_entry
from camdirector.pipeline.match.frame import ReplayedMoment, ShotChoice, ShotKind
from camdirector.pipeline.rigs import RIGS, runs_compiled
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import (
    MapBackendChoice,
    MaskKind,
    Movement,
    Rig,
    ShotSize,
    Style,
    VisibilityMode,
)
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.level_cache import LevelCache
from camdirector.worker.pose_out import PoseFormat, PoseOutputSpec

_MASKS = {
    pb.STYLE_MASK_EMPTY: MaskKind.EMPTY,
    pb.STYLE_MASK_SOFT_BEHIND: MaskKind.SOFT_BEHIND,
    pb.STYLE_MASK_HARD_BEHIND: MaskKind.HARD_BEHIND,
    pb.STYLE_MASK_AVOID_BEHIND_TOP_BOTTOM: MaskKind.AVOID_BEHIND_TOP_BOTTOM,
}
_RIGS = {pb.RIG_UNSPECIFIED: Rig.TORIC} | {entry.rig.value: entry.rig for entry in RIGS}  # Rig has the wire's numbers
MAX_PLAYERS = 64  # players of a MATCH session (the wire contract)
MAX_DELAY_S = 300.0  # broadcast delay of a MATCH session, s (the wire contract)
MAX_NAME_CHARS = 64  # a target's display_name and team_name, Unicode code points (the wire contract)
MAX_PRIORITY = 15  # a game event's priority (HLTV's scale)
_SHOT_SIZES = {
    pb.SHOT_SIZE_UNSPECIFIED: ShotSize.LONG,
    pb.SHOT_SIZE_MEDIUM: ShotSize.MEDIUM,
    pb.SHOT_SIZE_LONG: ShotSize.LONG,
    pb.SHOT_SIZE_EXTREME_LONG: ShotSize.EXTREME_LONG,
}
_MOVEMENTS = {
    pb.MOVEMENT_UNSPECIFIED: Movement.DYNAMIC_WITH_CUTS,
    pb.MOVEMENT_DYNAMIC_NO_CUTS: Movement.DYNAMIC_NO_CUTS,
    pb.MOVEMENT_DYNAMIC_WITH_CUTS: Movement.DYNAMIC_WITH_CUTS,
    pb.MOVEMENT_STATIC: Movement.STATIC,
}
MAX_POSE_OUTPUTS = 8  # pose outputs of a session (the wire contract)
DEFAULT_SENSOR_HEIGHT_MM = 24.0  # a pose output's sensor_height_mm when 0: a full-frame 35 mm still sensor
SENSOR_HEIGHT_RANGE_MM = (1.0, 100.0)
SOURCE_NUMBER_RANGES = {
    PoseFormat.OPENTRACKIO_JSON: (1, 200),  # OpenTrackIO: "Source Numbers above 200 are reserved"
    PoseFormat.OPENTRACKIO_CBOR: (1, 200),
    PoseFormat.FREED_D1: (1, 255),
}  # FreeD: the camera id byte
RESOLVE_TIMEOUT_S = 2.0  # a pose output's host name must resolve within this, s
_resolver: ThreadPoolExecutor | None = None  # looks names up off the worker's thread, so a slow one cannot hold it
MIN_ALPHA_RAD = math.radians(0.5)  # screen points closer than this angle give no usable torus
PACKED_STRIDE = 10  # doubles per object in FrameUpdate.packed_transforms


def _vec3(msg: pb.Vec3, what: str) -> np.ndarray:
    v = np.array([msg.x, msg.y, msg.z])
    if not np.all(np.isfinite(v)):
        raise invalid(f"{what} has a NaN or infinite component")
    return v


def transform_from_msg(msg: pb.Transform, what: str, portable: bool = False) -> RigidTransform:
    """portable: the quaternion's length summed in one order, the same bits on every machine (the
    compiled frame path's creation request), not by np.linalg.norm, a BLAS dot whose kernel is the CPU's."""
    position = _vec3(msg.position, f"{what}.position")
    rotation = IDENTITY_QUAT.copy()
    if msg.HasField("rotation"):
        x, y, z, w = msg.rotation.x, msg.rotation.y, msg.rotation.z, msg.rotation.w
        q = np.array([x, y, z, w])
        if not np.all(np.isfinite(q)):
            raise invalid(f"{what}.rotation has a NaN or infinite component")
        norm = math.sqrt(x * x + y * y + z * z + w * w) if portable else float(np.linalg.norm(q))
        if norm < 1e-6:
            raise invalid(f"{what}.rotation is a zero-length quaternion")
        rotation = q / norm
    scale = np.ones(3)
    if msg.HasField("scale"):
        scale = _vec3(msg.scale, f"{what}.scale")
        if np.any(np.abs(scale) < 1e-9):
            raise invalid(f"{what}.scale has a zero component")
    return RigidTransform(position, rotation, scale)


def transforms_from_packed(values: np.ndarray, ids) -> list[RigidTransform]:
    """values: (n, 10) rows px, py, pz, qx, qy, qz, qw, sx, sy, sz; validated all at once."""
    bad = ~np.isfinite(values).all(axis=1)
    norms = np.linalg.norm(values[:, 3:7], axis=1)
    for row, message in (
        (bad, "has a NaN or infinite value"),
        (norms < 1e-6, "rotation is a zero-length quaternion"),
        ((np.abs(values[:, 7:10]) < 1e-9).any(axis=1), "scale has a zero component"),
    ):
        if row.any():
            raise invalid(f"packed state {ids[int(np.argmax(row))]!r} {message}")
    rotations = values[:, 3:7] / norms[:, None]
    # Rows of fresh arrays, not a copy per row: a copy per object and field cost 2 us each.
    return [RigidTransform(p, q, s) for p, q, s in zip(values[:, 0:3].copy(), rotations, values[:, 7:10].copy())]


def mesh_from_msg(msg: pb.Mesh, what: str, portable: bool = False) -> TriMesh:
    """portable: a primitive stood up the same on every machine (meshes.py's `_stood_up`: the
    compiled frame path's)."""
    kind = msg.WhichOneof("source")
    try:
        if kind == "triangles":
            return meshes.from_arrays(
                np.asarray(msg.triangles.vertices, dtype=np.float32), np.asarray(msg.triangles.indices, dtype=np.uint32)
            )
        if kind == "glb":
            return meshes.from_glb(msg.glb)
        if kind == "obj":
            return meshes.from_obj(msg.obj)
        if kind == "primitive":
            return _primitive(msg.primitive, portable)
    except MeshError as exc:
        raise invalid(f"{what}: {exc}") from None
    raise invalid(f"{what} is empty: set one of glb, obj, triangles, primitive")


def _primitive(msg: pb.Primitive, portable: bool) -> TriMesh:
    shape = msg.WhichOneof("shape")
    if shape == "box":
        return meshes.box([msg.box.size.x, msg.box.size.y, msg.box.size.z])
    if shape == "sphere":
        return meshes.sphere(msg.sphere.radius)
    if shape == "cylinder":
        return meshes.cylinder(msg.cylinder.radius, msg.cylinder.height, portable=portable)
    if shape == "capsule":
        return meshes.capsule(msg.capsule.radius, msg.capsule.height, portable=portable)
    raise MeshError("primitive has no shape")


def lens_from_msg(msg: pb.Lens) -> Lens:
    fov = msg.vertical_fov_deg or Lens.vertical_fov_deg
    aspect = msg.aspect or Lens.aspect
    if not (math.isfinite(fov) and 1.0 < fov < 170.0):
        raise invalid(f"lens.vertical_fov_deg must be in (1, 170), got {fov}")
    if not (math.isfinite(aspect) and 0.1 <= aspect <= 10.0):
        raise invalid(f"lens.aspect must be in [0.1, 10], got {aspect}")
    return Lens(vertical_fov_deg=fov, aspect=aspect)


def style_from_msg(msg: pb.Style, lens: Lens, current: Style | None = None) -> Style:
    """The style of a CreateSession, or of an UpdateStyle to a session whose style is `current`."""
    values: dict[str, Any] = {}  # Style's fields by name, each of its own type
    for name in ("screen_a", "screen_b"):
        if msg.HasField(name):
            point = getattr(msg, name)
            values[name] = (point.x, point.y)
    for name in (
        "gaze_room_m",
        "preferred_theta_ratio",
        "preferred_phi_deg",
        "response_time_s",
        "max_speed_m_s",
        "max_accel_m_s2",
    ):
        if msg.HasField(name):
            values[name] = getattr(msg, name)
    try:
        mode = VisibilityMode(msg.visibility)
    except ValueError:
        raise invalid(f"style.visibility {msg.visibility} is not a VisibilityMode") from None
    try:
        values["mask"] = _MASKS[msg.mask]
        values["map_backend"] = MapBackendChoice(msg.map_backend)
    except (KeyError, ValueError):
        raise invalid(f"style.mask {msg.mask} or style.map_backend {msg.map_backend} is not known") from None
    if msg.map_resolution:
        values["map_resolution"] = msg.map_resolution
    for name, table in (("rig", _RIGS), ("shot_size", _SHOT_SIZES), ("movement", _MOVEMENTS)):
        number = getattr(msg, name)
        if number not in table:
            raise invalid(f"style.{name} {number} is not a known {name}")
        values[name] = table[number]
    if current is not None and values["rig"] != current.rig:
        raise precondition(
            f"style.rig cannot change during a session ({current.rig.name} -> {values['rig'].name}): "
            "create a new session with that rig (an UpdateStyle replaces the whole style, so a "
            "TRACKS session repeats rig = RIG_TRACKS)"
        )
    if values["rig"] != Rig.TRACKS and (msg.shot_size or msg.movement):
        raise invalid(
            "style.shot_size and style.movement direct the TRACKS rig; set style.rig = RIG_TRACKS "
            "(with a level_id) or leave them unset"
        )
    match_fields = [name for name in ("min_shot_s", "max_shot_s") if msg.HasField(name)]
    if values["rig"] != Rig.MATCH and (msg.match_director or msg.match_director_name or match_fields):
        raise invalid(
            "style.match_director, style.match_director_name, style.min_shot_s and style.max_shot_s "
            "direct the MATCH rig; set style.rig = RIG_MATCH or leave them unset"
        )
    if values["rig"] == Rig.MATCH:
        values["match_director"] = _match_director(msg)
    for name in match_fields:
        values[name] = getattr(msg, name)
    try:
        style = Style(visibility=VisibilityMode.FRAMING_ONLY if mode == VisibilityMode.UNSPECIFIED else mode, **values)
    except ValueError as exc:
        raise invalid(str(exc)) from None
    if composition_angle(style.screen_a, style.screen_b, lens) < MIN_ALPHA_RAD:
        raise invalid("style.screen_a and style.screen_b are too close for this lens (under 0.5 deg apart)")
    return style


def _match_director(msg: pb.Style) -> str:
    """The registry name of the style's director (pipeline/match/director_registry.py): its
    `match_director_name` when set, else the built-in of its `match_director` enum value."""
    if msg.match_director_name:
        try:
            return director_entry(msg.match_director_name).name
        except KeyError as exc:
            raise invalid(f"style.match_director_name: {exc.args[0]}") from None
    if msg.match_director == pb.MATCH_DIRECTOR_UNSPECIFIED:
        return DEFAULT_DIRECTOR
    entry = (
        director_by_wire(pb.MatchDirector.Name(msg.match_director)) if msg.match_director in pb.MatchDirector.values() else None
    )
    if entry is None:
        raise invalid(f"style.match_director {msg.match_director} is not a known match_director")
    return entry.name


def shown_style(msg: pb.Style, style: Style) -> pb.Style:
    """The style as a session shows it back (GET /v1/sessions/{id}): as the client sent it, with
    a MATCH style's director by the registry name it resolved to."""
    if style.rig != Rig.MATCH:
        return msg
    shown = pb.Style()
    shown.CopyFrom(msg)
    shown.match_director_name = style.match_director
    return shown


def _check_id(object_id: str, what: str, seen: set[str]) -> None:
    if not object_id:
        raise invalid(f"{what}.id is empty")
    if object_id in seen:
        raise invalid(f"{what}.id {object_id!r} is used twice")
    seen.add(object_id)


def _checked_name(name: str, what: str) -> str:
    """A name shown to people (a target's display_name, team_name): at most MAX_NAME_CHARS code
    points and no control character, which would break a label's line or a log's."""
    if len(name) > MAX_NAME_CHARS:
        raise invalid(f"{what} has {len(name)} characters; at most {MAX_NAME_CHARS} are allowed")
    control = next((c for c in name if unicodedata.category(c) == "Cc"), None)
    if control is not None:
        raise invalid(f"{what} holds the control character U+{ord(control):04X}; a name is one line of text")
    return name


def scene_from_request(
    req: pb.CreateSessionRequest, settings: ServerSettings, levels: LevelCache | None = None, tenant: str = DEFAULT_TENANT
) -> SceneSpec:
    """levels: where a TRACKS or MATCH session's level is looked up (default: the registry in
    settings.data_dir); tenant: whose levels (the session's: the tenant of the key that created it)."""
    match = req.style.rig == pb.RIG_MATCH
    if match and not 2 <= len(req.targets) <= MAX_PLAYERS:
        raise invalid(f"a RIG_MATCH session has 2 to {MAX_PLAYERS} players as targets, got {len(req.targets)}")
    if not match and not 1 <= len(req.targets) <= 2:
        raise invalid(f"a session frames one or two targets, got {len(req.targets)}")
    if not match and (req.delay_s or any(t.team or t.team_name for t in req.targets)):
        raise invalid(
            "delay_s, targets[].team and targets[].team_name are for a RIG_MATCH session; "
            "set style.rig = RIG_MATCH or leave them unset"
        )
    if not (math.isfinite(req.delay_s) and 0.0 <= req.delay_s <= MAX_DELAY_S):
        raise invalid(f"delay_s must be in [0, {MAX_DELAY_S:g}] s, got {req.delay_s}")
    if len(req.objects) > settings.max_objects:
        raise exhausted(f"{len(req.objects)} scene objects exceed the limit of {settings.max_objects}")
    lens = lens_from_msg(req.lens)
    style = style_from_msg(req.style, lens)
    # the compiled path's: primitives stood up exactly (meshes.py), quaternions normalised without BLAS
    portable = runs_compiled(style.rig, settings.compiled_frame_path)
    seen: set[str] = set()
    triangles = 0
    objects, targets = [], []
    for i, obj in enumerate(req.objects):
        what = f"objects[{i}]"
        _check_id(obj.id, what, seen)
        mesh = mesh_from_msg(obj.mesh, f"{what}.mesh", portable)
        triangles += mesh.triangle_count
        if triangles > settings.max_triangles:
            raise exhausted(f"scene exceeds the limit of {settings.max_triangles} triangles")
        objects.append(ObjectSpec(obj.id, mesh, transform_from_msg(obj.transform, f"{what}.transform", portable), obj.dynamic))
    for i, target in enumerate(req.targets):
        what = f"targets[{i}]"
        _check_id(target.id, what, seen)
        mesh = mesh_from_msg(target.mesh, f"{what}.mesh", portable)
        triangles += mesh.triangle_count
        if triangles > settings.max_triangles:
            raise exhausted(f"scene exceeds the limit of {settings.max_triangles} triangles")
        targets.append(
            TargetSpec(
                target.id,
                mesh,
                transform_from_msg(target.transform, f"{what}.transform", portable),
                _vec3(target.aim_offset, f"{what}.aim_offset"),
                team=int(target.team),
                display_name=_checked_name(target.display_name, f"{what}.display_name"),
                team_name=_checked_name(target.team_name, f"{what}.team_name"),
            )
        )
    level = None
    if style.rig == Rig.TRACKS:
        if len(targets) != 1:
            raise invalid(f"the TRACKS rig follows exactly one target (the actor), got {len(targets)}")
        if not req.level_id:
            raise invalid("style.rig RIG_TRACKS needs level_id: the name of a level in the server's level registry")
    elif req.level_id and style.rig != Rig.MATCH:
        raise invalid(
            f"level_id {req.level_id!r} is for the TRACKS and MATCH rigs: set style.rig = RIG_TRACKS or leave level_id empty"
        )
    if req.level_id:
        levels = levels if levels is not None else LevelCache(settings.data_dir, settings.job_store)
        level = levels.get(req.level_id, tenant)
    return SceneSpec(objects, targets, lens, style, int(req.seed), level, delay_s=float(req.delay_s))


def _resolve_ipv4(host: str, what: str) -> str:
    """host as an IPv4 address: an address as it is, a name looked up (INVALID_ARGUMENT when it
    does not resolve to one within RESOLVE_TIMEOUT_S)."""
    try:
        return str(ipaddress.IPv4Address(host))
    except ValueError:
        pass
    if ":" in host or not all(c.isalnum() or c in "-._" for c in host) or not host.isascii():
        raise invalid(
            f"{what}: host {host!r} is neither an IPv4 address nor a host name (IPv6 is not supported: "
            "OpenTrackIO 1.0.1 runs over IPv4)"
        )
    global _resolver
    if _resolver is None:
        _resolver = ThreadPoolExecutor(max_workers=2, thread_name_prefix="pose-output-resolve")
    lookup = _resolver.submit(socket.getaddrinfo, host, None, socket.AF_INET, socket.SOCK_DGRAM)
    try:
        return str(lookup.result(timeout=RESOLVE_TIMEOUT_S)[0][4][0])  # AF_INET: (address, port)
    except FutureTimeout:
        raise invalid(f"{what}: host {host!r} did not resolve within {RESOLVE_TIMEOUT_S:g} s") from None
    except (OSError, IndexError, UnicodeError):
        raise invalid(f"{what}: host {host!r} does not resolve to an IPv4 address") from None


def _udp_address(address: str, what: str, allowed: tuple[str, ...]) -> tuple[str, int]:
    """(IPv4 address, port) of a `udp://HOST:PORT` whose address is in one of the `allowed` networks."""
    scheme, separator, rest = address.partition("://")
    if not separator or scheme.lower() != "udp":
        raise invalid(f"{what} {address!r} is not udp://HOST:PORT")
    if rest.startswith("["):
        raise invalid(f"{what} {address!r}: IPv6 is not supported (OpenTrackIO 1.0.1 runs over IPv4)")
    if any(c in rest for c in "/?#@"):
        raise invalid(f"{what} {address!r} has more than HOST:PORT after udp://")
    host, colon, port_text = rest.rpartition(":")
    if not colon:
        raise invalid(f"{what} {address!r} has no port: write udp://HOST:PORT")
    if not host:
        raise invalid(f"{what} {address!r} has no host: write udp://HOST:PORT")
    if not (port_text.isascii() and port_text.isdigit()):
        raise invalid(f"{what} {address!r}: port {port_text!r} is not a number")
    port = int(port_text)
    if not 1 <= port <= 65535:
        raise invalid(f"{what} {address!r}: port {port} is out of range [1, 65535]")
    resolved = _resolve_ipv4(host, what)
    if not any(ipaddress.IPv4Address(resolved) in ipaddress.IPv4Network(network) for network in allowed):
        raise invalid(
            f"{what} {address!r}: this server sends poses only to the networks its operator allowed, "
            "and this address is outside them (the operator adds one with `camdirector serve --pose-output-allow`)"
        )
    return resolved, port


def pose_output_from_msg(msg: pb.PoseOutput, what: str, allowed: tuple[str, ...]) -> PoseOutputSpec:
    try:
        fmt = PoseFormat(msg.format)
    except ValueError:
        fmt = None
    if fmt is None or fmt == PoseFormat.UNSPECIFIED:
        problem = "is unset" if fmt is not None else f"{msg.format} is not a PoseFormat"
        raise invalid(
            f"{what}.format {problem}: choose POSE_FORMAT_OPENTRACKIO_JSON, POSE_FORMAT_OPENTRACKIO_CBOR or POSE_FORMAT_FREED_D1"
        )
    low, high = SOURCE_NUMBER_RANGES[fmt]
    source_number = msg.source_number or 1
    if not low <= source_number <= high:
        raise invalid(
            f"{what}.source_number must be in [{low}, {high}] for POSE_FORMAT_{fmt.name} (0 means 1), got {msg.source_number}"
        )
    height = msg.sensor_height_mm or DEFAULT_SENSOR_HEIGHT_MM
    low_mm, high_mm = SENSOR_HEIGHT_RANGE_MM
    if not (math.isfinite(height) and low_mm <= height <= high_mm):
        raise invalid(
            f"{what}.sensor_height_mm must be in [{low_mm:g}, {high_mm:g}] mm "
            f"(0 means {DEFAULT_SENSOR_HEIGHT_MM:g}), got {msg.sensor_height_mm}"
        )
    host, port = _udp_address(msg.address, f"{what}.address", allowed)
    return PoseOutputSpec(fmt, msg.address, host, port, source_number, float(height))


def pose_outputs_from_request(req: pb.CreateSessionRequest, allowed: tuple[str, ...]) -> list[PoseOutputSpec]:
    """The session's pose outputs, checked (module docstring), each to an address in one of the
    `allowed` networks (CIDR); empty when it asks for none."""
    if len(req.pose_outputs) > MAX_POSE_OUTPUTS:
        raise invalid(f"a session has at most {MAX_POSE_OUTPUTS} pose_outputs, got {len(req.pose_outputs)}")
    return [pose_output_from_msg(output, f"pose_outputs[{i}]", allowed) for i, output in enumerate(req.pose_outputs)]


def events_from_msg(msg: pb.FrameUpdate, player_ids: frozenset[str] | None, delay_s: float) -> list[GameEvent]:
    """The frame's events, checked (module docstring); `player_ids`: whom they may name (the rig's
    `PlayerInputs`, pipeline/camera_rig.py), None for a session whose rig takes no game events."""
    if not msg.events:
        return []
    if player_ids is None:
        raise invalid("events are for a RIG_MATCH session")
    events = []
    for i, event in enumerate(msg.events):
        what = f"events[{i}]"
        try:
            kind = EventKind(event.kind)
        except ValueError:
            raise invalid(f"{what}.kind {event.kind} is not an EventKind") from None
        if kind == EventKind.UNSPECIFIED:
            raise invalid(f"{what}.kind is unset")
        if event.priority > MAX_PRIORITY:
            raise invalid(f"{what}.priority must be in [0, {MAX_PRIORITY}], got {event.priority}")
        for name in ("actor_id", "other_actor_id"):
            player = getattr(event, name)
            if player and player not in player_ids:
                raise not_found(f"{what}.{name} {player!r} is not a player of this session")
        if kind == EventKind.KILL and not (event.actor_id and event.other_actor_id):
            raise invalid(f"{what}: a kill names its attacker (actor_id) and its victim (other_actor_id)")
        time_s = event.time_s or msg.time_s
        if not math.isfinite(time_s):
            raise invalid(f"{what}.time_s is NaN or infinite")
        if time_s > msg.time_s + delay_s + 1e-9:
            raise invalid(f"{what}.time_s {time_s} is later than the frame's time {msg.time_s} plus the delay {delay_s} s")
        position = _vec3(event.position, f"{what}.position") if event.HasField("position") else None
        events.append(
            GameEvent(kind, event.actor_id, event.other_actor_id, int(event.priority), float(time_s), event.label, position)
        )
    return events


def player_stats_from_msg(msg: pb.FrameUpdate, player_ids: frozenset[str] | None) -> list[PlayerStats]:
    """The frame's player stats, checked (module docstring): INVALID_ARGUMENT for a session whose
    rig takes no game input (`player_ids` None), a player the session does not have, or one named twice."""
    if not msg.player_stats:
        return []
    if player_ids is None:
        raise invalid("player_stats are for a RIG_MATCH session")
    out, seen = [], set()
    for i, stats in enumerate(msg.player_stats):
        if stats.id not in player_ids:
            raise invalid(f"player_stats[{i}].id {stats.id!r} is not a player of this session")
        if stats.id in seen:
            raise invalid(f"player_stats[{i}].id {stats.id!r} is sent twice in one frame")
        seen.add(stats.id)
        out.append(PlayerStats(stats.id, int(stats.health), int(stats.armor), int(stats.items), int(stats.frags)))
    return out


def take_from_msg(msg: pb.TakeShotRequest, player_ids: frozenset[str]) -> tuple[list[str], ShotKind | None, bool]:
    """A TakeShotRequest as `PlayerInputs.take`'s arguments (pipeline/camera_rig.py): NOT_FOUND for
    a player not in `player_ids`, INVALID_ARGUMENT for an unknown kind or a take without subjects."""
    if msg.release:
        return [], None, True
    try:
        kind = None if msg.kind == pb.SHOT_KIND_UNSPECIFIED else ShotKind(msg.kind)
    except ValueError:
        raise invalid(f"kind {msg.kind} is not a ShotKind") from None
    if not msg.subject_ids and kind != ShotKind.OVERVIEW:
        raise invalid("a TakeShot names its subject_ids (none only for SHOT_OVERVIEW), or sets release to give the program back")
    for player in msg.subject_ids:
        if player not in player_ids:
            raise not_found(f"subject_ids: {player!r} is not a player of this session")
    return list(msg.subject_ids), kind, False


def frame_from_msg(
    msg: pb.FrameUpdate, movable: set[str], static: set[str], player_ids: frozenset[str] | None = None, delay_s: float = 0.0
) -> FrameInput:
    """`movable`: ids of targets and dynamic objects; `static`: ids of static objects; `player_ids`
    and `delay_s`: whom the game events and player stats may name and how far ahead events may be
    (events_from_msg, player_stats_from_msg)."""
    if not math.isfinite(msg.time_s):
        raise invalid("frame time_s is NaN or infinite")
    states: list[tuple[str, RigidTransform]] = []

    def check(object_id: str) -> None:
        if object_id not in movable:
            if object_id in static:
                raise precondition(f"object {object_id!r} is static; create it with dynamic=true to move it")
            raise not_found(f"unknown object id {object_id!r} in frame {msg.frame}")

    for state in msg.states:
        check(state.id)
        states.append((state.id, transform_from_msg(state.transform, f"state {state.id!r} transform")))
    if msg.packed_ids or msg.packed_transforms:
        values = np.asarray(msg.packed_transforms, dtype=np.float64)
        if values.size != PACKED_STRIDE * len(msg.packed_ids):
            raise invalid(f"packed_transforms holds {values.size} values; {PACKED_STRIDE} per packed id expected")
        for object_id in msg.packed_ids:
            check(object_id)
        states.extend(zip(msg.packed_ids, transforms_from_packed(values.reshape(-1, PACKED_STRIDE), msg.packed_ids)))
    return FrameInput(
        msg.session_id,
        int(msg.frame),
        float(msg.time_s),
        states,
        events_from_msg(msg, player_ids, delay_s),
        player_stats_from_msg(msg, player_ids),
    )


_REFUSALS = {"INVALID_ARGUMENT": invalid, "NOT_FOUND": not_found, "FAILED_PRECONDITION": precondition}


def frame_from_wire(
    payload: bytes,
    msg: pb.FrameUpdate,
    movable: set[str],
    static: set[str],
    player_ids: frozenset[str] | None = None,
    delay_s: float = 0.0,
) -> FrameInput:
    """frame_from_msg on the compiled frame path (ServerSettings.frame_path "compiled"): the
    frame's bytes as received (`payload`, whose parse is `msg`) read and checked in
    camdirector._native (native/src/wire.rs), with frame_from_msg's checks in its order and its
    errors. A quaternion is normalised there with its squares summed in order, which may differ
    from numpy's norm in the last bit (numpy's depends on the machine). A frame with game events
    or player stats goes through frame_from_msg."""
    try:
        decoded = native.decode_frame(payload, movable, static, RigidTransform)
    except native.FrameRefused as exc:
        status, message = exc.args
        raise _REFUSALS[status](message) from None
    if decoded is None:
        return frame_from_msg(msg, movable, static, player_ids, delay_s)
    # rows (n, PACKED_STRIDE) float64, as transforms_from_packed's; states (id, RigidTransform of its row)
    session_id, frame, time_s, ids, rows, states = decoded
    return FrameInput(session_id, frame, time_s, states, packed=(ids, rows))


def pose_msg(pose: CameraPose) -> pb.CameraPose:
    p, q = pose.position_world, pose.rotation_xyzw
    return pb.CameraPose(
        position=pb.Vec3(x=p[0], y=p[1], z=p[2]),
        rotation=pb.Quat(x=q[0], y=q[1], z=q[2], w=q[3]),
        vertical_fov_deg=pose.vertical_fov_deg,
    )


def shot_msg(shot: ShotChoice, replay_of: ReplayedMoment | None = None) -> pb.ShotInfo:
    """The wire's shot; a REPLAY's with the moment its picture shows (replay_of) and its kill."""
    out = pb.ShotInfo(subject_ids=shot.subject_ids, kind=int(shot.kind), reason=shot.reason, held=shot.held, eyes_id=shot.eyes_id)
    if replay_of is not None:
        out.replay_frame, out.replay_time_s = replay_of.frame, replay_of.time_s
    if shot.replay is not None:
        out.replay_kill_time_s = shot.replay.kill_time_s
    return out


class Reply(Protocol):
    """What the session table reads and sets of a frame's reply: a pb.CameraUpdate, or on the
    compiled frame path a computed frame's camera_update_wire."""

    compute_ms: float

    @property
    def stale(self) -> bool: ...

    def SerializeToString(self) -> bytes: ...


def camera_update_wire(state: FrameState) -> Reply:
    """camera_update_msg(state, compute_ms=0.0) on the compiled frame path, for a state without a
    MATCH part: written in camdirector._native (native/src/wire.rs), the same bytes as the
    message's but for the order of the map entries (stage_ms, scores), there by key; upb's is
    its hash table's, which changes from one process to the next. Set compute_ms before
    serializing."""
    reply: Reply = native.CameraUpdateWire(state)
    return reply


def camera_update_msg(state: FrameState, compute_ms: float, stale: bool = False, message: str = "") -> pb.CameraUpdate:
    """The reply to a frame: the state's core, and what the wire carries of the rig's part (the
    TORIC camera's place on its torus; the MATCH program's shot, candidates, and while its delay
    fills `buffering`, with no pose)."""
    match = state.match
    out = pb.CameraUpdate(
        frame=state.frame,
        time_s=state.time_s,
        pose=None if state.pose is None else pose_msg(state.pose),
        buffering=match is not None and match.buffering,
        cut=state.cut,
        shot_id=state.shot_id,
        visibility=state.visibility,
        compute_ms=compute_ms,
        stale=stale,
        message=message,
    )
    d = out.diagnostics
    toric = state.toric
    if toric is not None:
        d.theta, d.phi = toric.theta, toric.phi
        if toric.torus is not None:
            d.alpha = toric.torus.alpha
    d.stage_ms.update(state.stage_ms)
    d.flags.extend(state.flags)
    d.scores.update(state.scores)
    if match is not None:
        if match.shot is not None:
            out.shot.CopyFrom(shot_msg(match.shot, match.replay_of))
        for candidate in match.candidates:
            out.candidates.add(
                pose=pose_msg(candidate.pose), shot=shot_msg(candidate.shot, candidate.replay_of), score=candidate.score
            )
    return out
