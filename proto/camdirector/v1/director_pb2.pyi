from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class VisibilityMode(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    VISIBILITY_MODE_UNSPECIFIED: _ClassVar[VisibilityMode]
    ANTICIPATION: _ClassVar[VisibilityMode]
    NO_ANTICIPATION: _ClassVar[VisibilityMode]
    RAYCAST: _ClassVar[VisibilityMode]
    REACTIVE: _ClassVar[VisibilityMode]
    FRAMING_ONLY: _ClassVar[VisibilityMode]

class StyleMask(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    STYLE_MASK_EMPTY: _ClassVar[StyleMask]
    STYLE_MASK_SOFT_BEHIND: _ClassVar[StyleMask]
    STYLE_MASK_HARD_BEHIND: _ClassVar[StyleMask]
    STYLE_MASK_AVOID_BEHIND_TOP_BOTTOM: _ClassVar[StyleMask]

class MapBackend(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    MAP_BACKEND_AUTO: _ClassVar[MapBackend]
    MAP_BACKEND_GL: _ClassVar[MapBackend]
    MAP_BACKEND_EMBREE: _ClassVar[MapBackend]

class Rig(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    RIG_UNSPECIFIED: _ClassVar[Rig]
    RIG_TORIC: _ClassVar[Rig]
    RIG_TRACKS: _ClassVar[Rig]
    RIG_MATCH: _ClassVar[Rig]

class ShotSize(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    SHOT_SIZE_UNSPECIFIED: _ClassVar[ShotSize]
    SHOT_SIZE_MEDIUM: _ClassVar[ShotSize]
    SHOT_SIZE_LONG: _ClassVar[ShotSize]
    SHOT_SIZE_EXTREME_LONG: _ClassVar[ShotSize]

class Movement(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    MOVEMENT_UNSPECIFIED: _ClassVar[Movement]
    MOVEMENT_DYNAMIC_NO_CUTS: _ClassVar[Movement]
    MOVEMENT_DYNAMIC_WITH_CUTS: _ClassVar[Movement]
    MOVEMENT_STATIC: _ClassVar[Movement]

class MatchDirector(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    MATCH_DIRECTOR_UNSPECIFIED: _ClassVar[MatchDirector]
    MATCH_DIRECTOR_PLANNED: _ClassVar[MatchDirector]
    MATCH_DIRECTOR_HLTV: _ClassVar[MatchDirector]
    MATCH_DIRECTOR_AUTOTRACK: _ClassVar[MatchDirector]

class PoseFormat(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    POSE_FORMAT_UNSPECIFIED: _ClassVar[PoseFormat]
    POSE_FORMAT_OPENTRACKIO_JSON: _ClassVar[PoseFormat]
    POSE_FORMAT_OPENTRACKIO_CBOR: _ClassVar[PoseFormat]
    POSE_FORMAT_FREED_D1: _ClassVar[PoseFormat]

class EventKind(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    EVENT_KIND_UNSPECIFIED: _ClassVar[EventKind]
    EVENT_KILL: _ClassVar[EventKind]
    EVENT_DAMAGE: _ClassVar[EventKind]
    EVENT_OBJECTIVE: _ClassVar[EventKind]
    EVENT_CUSTOM: _ClassVar[EventKind]

class ShotKind(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    SHOT_KIND_UNSPECIFIED: _ClassVar[ShotKind]
    SHOT_DUEL: _ClassVar[ShotKind]
    SHOT_FOLLOW: _ClassVar[ShotKind]
    SHOT_GROUP: _ClassVar[ShotKind]
    SHOT_OVERVIEW: _ClassVar[ShotKind]
    SHOT_REPLAY: _ClassVar[ShotKind]
VISIBILITY_MODE_UNSPECIFIED: VisibilityMode
ANTICIPATION: VisibilityMode
NO_ANTICIPATION: VisibilityMode
RAYCAST: VisibilityMode
REACTIVE: VisibilityMode
FRAMING_ONLY: VisibilityMode
STYLE_MASK_EMPTY: StyleMask
STYLE_MASK_SOFT_BEHIND: StyleMask
STYLE_MASK_HARD_BEHIND: StyleMask
STYLE_MASK_AVOID_BEHIND_TOP_BOTTOM: StyleMask
MAP_BACKEND_AUTO: MapBackend
MAP_BACKEND_GL: MapBackend
MAP_BACKEND_EMBREE: MapBackend
RIG_UNSPECIFIED: Rig
RIG_TORIC: Rig
RIG_TRACKS: Rig
RIG_MATCH: Rig
SHOT_SIZE_UNSPECIFIED: ShotSize
SHOT_SIZE_MEDIUM: ShotSize
SHOT_SIZE_LONG: ShotSize
SHOT_SIZE_EXTREME_LONG: ShotSize
MOVEMENT_UNSPECIFIED: Movement
MOVEMENT_DYNAMIC_NO_CUTS: Movement
MOVEMENT_DYNAMIC_WITH_CUTS: Movement
MOVEMENT_STATIC: Movement
MATCH_DIRECTOR_UNSPECIFIED: MatchDirector
MATCH_DIRECTOR_PLANNED: MatchDirector
MATCH_DIRECTOR_HLTV: MatchDirector
MATCH_DIRECTOR_AUTOTRACK: MatchDirector
POSE_FORMAT_UNSPECIFIED: PoseFormat
POSE_FORMAT_OPENTRACKIO_JSON: PoseFormat
POSE_FORMAT_OPENTRACKIO_CBOR: PoseFormat
POSE_FORMAT_FREED_D1: PoseFormat
EVENT_KIND_UNSPECIFIED: EventKind
EVENT_KILL: EventKind
EVENT_DAMAGE: EventKind
EVENT_OBJECTIVE: EventKind
EVENT_CUSTOM: EventKind
SHOT_KIND_UNSPECIFIED: ShotKind
SHOT_DUEL: ShotKind
SHOT_FOLLOW: ShotKind
SHOT_GROUP: ShotKind
SHOT_OVERVIEW: ShotKind
SHOT_REPLAY: ShotKind

class Vec3(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class Quat(_message.Message):
    __slots__ = ("x", "y", "z", "w")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    W_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    w: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ..., w: _Optional[float] = ...) -> None: ...

class Transform(_message.Message):
    __slots__ = ("position", "rotation", "scale")
    POSITION_FIELD_NUMBER: _ClassVar[int]
    ROTATION_FIELD_NUMBER: _ClassVar[int]
    SCALE_FIELD_NUMBER: _ClassVar[int]
    position: Vec3
    rotation: Quat
    scale: Vec3
    def __init__(self, position: _Optional[_Union[Vec3, _Mapping]] = ..., rotation: _Optional[_Union[Quat, _Mapping]] = ..., scale: _Optional[_Union[Vec3, _Mapping]] = ...) -> None: ...

class TriangleMesh(_message.Message):
    __slots__ = ("vertices", "indices")
    VERTICES_FIELD_NUMBER: _ClassVar[int]
    INDICES_FIELD_NUMBER: _ClassVar[int]
    vertices: _containers.RepeatedScalarFieldContainer[float]
    indices: _containers.RepeatedScalarFieldContainer[int]
    def __init__(self, vertices: _Optional[_Iterable[float]] = ..., indices: _Optional[_Iterable[int]] = ...) -> None: ...

class Primitive(_message.Message):
    __slots__ = ("box", "sphere", "cylinder", "capsule")
    class Box(_message.Message):
        __slots__ = ("size",)
        SIZE_FIELD_NUMBER: _ClassVar[int]
        size: Vec3
        def __init__(self, size: _Optional[_Union[Vec3, _Mapping]] = ...) -> None: ...
    class Sphere(_message.Message):
        __slots__ = ("radius",)
        RADIUS_FIELD_NUMBER: _ClassVar[int]
        radius: float
        def __init__(self, radius: _Optional[float] = ...) -> None: ...
    class Cylinder(_message.Message):
        __slots__ = ("radius", "height")
        RADIUS_FIELD_NUMBER: _ClassVar[int]
        HEIGHT_FIELD_NUMBER: _ClassVar[int]
        radius: float
        height: float
        def __init__(self, radius: _Optional[float] = ..., height: _Optional[float] = ...) -> None: ...
    class Capsule(_message.Message):
        __slots__ = ("radius", "height")
        RADIUS_FIELD_NUMBER: _ClassVar[int]
        HEIGHT_FIELD_NUMBER: _ClassVar[int]
        radius: float
        height: float
        def __init__(self, radius: _Optional[float] = ..., height: _Optional[float] = ...) -> None: ...
    BOX_FIELD_NUMBER: _ClassVar[int]
    SPHERE_FIELD_NUMBER: _ClassVar[int]
    CYLINDER_FIELD_NUMBER: _ClassVar[int]
    CAPSULE_FIELD_NUMBER: _ClassVar[int]
    box: Primitive.Box
    sphere: Primitive.Sphere
    cylinder: Primitive.Cylinder
    capsule: Primitive.Capsule
    def __init__(self, box: _Optional[_Union[Primitive.Box, _Mapping]] = ..., sphere: _Optional[_Union[Primitive.Sphere, _Mapping]] = ..., cylinder: _Optional[_Union[Primitive.Cylinder, _Mapping]] = ..., capsule: _Optional[_Union[Primitive.Capsule, _Mapping]] = ...) -> None: ...

class Mesh(_message.Message):
    __slots__ = ("glb", "obj", "triangles", "primitive")
    GLB_FIELD_NUMBER: _ClassVar[int]
    OBJ_FIELD_NUMBER: _ClassVar[int]
    TRIANGLES_FIELD_NUMBER: _ClassVar[int]
    PRIMITIVE_FIELD_NUMBER: _ClassVar[int]
    glb: bytes
    obj: bytes
    triangles: TriangleMesh
    primitive: Primitive
    def __init__(self, glb: _Optional[bytes] = ..., obj: _Optional[bytes] = ..., triangles: _Optional[_Union[TriangleMesh, _Mapping]] = ..., primitive: _Optional[_Union[Primitive, _Mapping]] = ...) -> None: ...

class SceneObject(_message.Message):
    __slots__ = ("id", "mesh", "transform", "dynamic")
    ID_FIELD_NUMBER: _ClassVar[int]
    MESH_FIELD_NUMBER: _ClassVar[int]
    TRANSFORM_FIELD_NUMBER: _ClassVar[int]
    DYNAMIC_FIELD_NUMBER: _ClassVar[int]
    id: str
    mesh: Mesh
    transform: Transform
    dynamic: bool
    def __init__(self, id: _Optional[str] = ..., mesh: _Optional[_Union[Mesh, _Mapping]] = ..., transform: _Optional[_Union[Transform, _Mapping]] = ..., dynamic: _Optional[bool] = ...) -> None: ...

class Target(_message.Message):
    __slots__ = ("id", "mesh", "transform", "aim_offset", "team", "display_name", "team_name")
    ID_FIELD_NUMBER: _ClassVar[int]
    MESH_FIELD_NUMBER: _ClassVar[int]
    TRANSFORM_FIELD_NUMBER: _ClassVar[int]
    AIM_OFFSET_FIELD_NUMBER: _ClassVar[int]
    TEAM_FIELD_NUMBER: _ClassVar[int]
    DISPLAY_NAME_FIELD_NUMBER: _ClassVar[int]
    TEAM_NAME_FIELD_NUMBER: _ClassVar[int]
    id: str
    mesh: Mesh
    transform: Transform
    aim_offset: Vec3
    team: int
    display_name: str
    team_name: str
    def __init__(self, id: _Optional[str] = ..., mesh: _Optional[_Union[Mesh, _Mapping]] = ..., transform: _Optional[_Union[Transform, _Mapping]] = ..., aim_offset: _Optional[_Union[Vec3, _Mapping]] = ..., team: _Optional[int] = ..., display_name: _Optional[str] = ..., team_name: _Optional[str] = ...) -> None: ...

class Lens(_message.Message):
    __slots__ = ("vertical_fov_deg", "aspect")
    VERTICAL_FOV_DEG_FIELD_NUMBER: _ClassVar[int]
    ASPECT_FIELD_NUMBER: _ClassVar[int]
    vertical_fov_deg: float
    aspect: float
    def __init__(self, vertical_fov_deg: _Optional[float] = ..., aspect: _Optional[float] = ...) -> None: ...

class ScreenPoint(_message.Message):
    __slots__ = ("x", "y")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ...) -> None: ...

class Style(_message.Message):
    __slots__ = ("screen_a", "screen_b", "visibility", "gaze_room_m", "preferred_theta_ratio", "preferred_phi_deg", "response_time_s", "max_speed_m_s", "max_accel_m_s2", "mask", "map_resolution", "map_backend", "rig", "shot_size", "movement", "match_director", "min_shot_s", "max_shot_s", "match_director_name")
    SCREEN_A_FIELD_NUMBER: _ClassVar[int]
    SCREEN_B_FIELD_NUMBER: _ClassVar[int]
    VISIBILITY_FIELD_NUMBER: _ClassVar[int]
    GAZE_ROOM_M_FIELD_NUMBER: _ClassVar[int]
    PREFERRED_THETA_RATIO_FIELD_NUMBER: _ClassVar[int]
    PREFERRED_PHI_DEG_FIELD_NUMBER: _ClassVar[int]
    RESPONSE_TIME_S_FIELD_NUMBER: _ClassVar[int]
    MAX_SPEED_M_S_FIELD_NUMBER: _ClassVar[int]
    MAX_ACCEL_M_S2_FIELD_NUMBER: _ClassVar[int]
    MASK_FIELD_NUMBER: _ClassVar[int]
    MAP_RESOLUTION_FIELD_NUMBER: _ClassVar[int]
    MAP_BACKEND_FIELD_NUMBER: _ClassVar[int]
    RIG_FIELD_NUMBER: _ClassVar[int]
    SHOT_SIZE_FIELD_NUMBER: _ClassVar[int]
    MOVEMENT_FIELD_NUMBER: _ClassVar[int]
    MATCH_DIRECTOR_FIELD_NUMBER: _ClassVar[int]
    MIN_SHOT_S_FIELD_NUMBER: _ClassVar[int]
    MAX_SHOT_S_FIELD_NUMBER: _ClassVar[int]
    MATCH_DIRECTOR_NAME_FIELD_NUMBER: _ClassVar[int]
    screen_a: ScreenPoint
    screen_b: ScreenPoint
    visibility: VisibilityMode
    gaze_room_m: float
    preferred_theta_ratio: float
    preferred_phi_deg: float
    response_time_s: float
    max_speed_m_s: float
    max_accel_m_s2: float
    mask: StyleMask
    map_resolution: int
    map_backend: MapBackend
    rig: Rig
    shot_size: ShotSize
    movement: Movement
    match_director: MatchDirector
    min_shot_s: float
    max_shot_s: float
    match_director_name: str
    def __init__(self, screen_a: _Optional[_Union[ScreenPoint, _Mapping]] = ..., screen_b: _Optional[_Union[ScreenPoint, _Mapping]] = ..., visibility: _Optional[_Union[VisibilityMode, str]] = ..., gaze_room_m: _Optional[float] = ..., preferred_theta_ratio: _Optional[float] = ..., preferred_phi_deg: _Optional[float] = ..., response_time_s: _Optional[float] = ..., max_speed_m_s: _Optional[float] = ..., max_accel_m_s2: _Optional[float] = ..., mask: _Optional[_Union[StyleMask, str]] = ..., map_resolution: _Optional[int] = ..., map_backend: _Optional[_Union[MapBackend, str]] = ..., rig: _Optional[_Union[Rig, str]] = ..., shot_size: _Optional[_Union[ShotSize, str]] = ..., movement: _Optional[_Union[Movement, str]] = ..., match_director: _Optional[_Union[MatchDirector, str]] = ..., min_shot_s: _Optional[float] = ..., max_shot_s: _Optional[float] = ..., match_director_name: _Optional[str] = ...) -> None: ...

class CreateSessionRequest(_message.Message):
    __slots__ = ("objects", "targets", "lens", "style", "seed", "record", "level_id", "delay_s", "pose_outputs", "client_protocol")
    OBJECTS_FIELD_NUMBER: _ClassVar[int]
    TARGETS_FIELD_NUMBER: _ClassVar[int]
    LENS_FIELD_NUMBER: _ClassVar[int]
    STYLE_FIELD_NUMBER: _ClassVar[int]
    SEED_FIELD_NUMBER: _ClassVar[int]
    RECORD_FIELD_NUMBER: _ClassVar[int]
    LEVEL_ID_FIELD_NUMBER: _ClassVar[int]
    DELAY_S_FIELD_NUMBER: _ClassVar[int]
    POSE_OUTPUTS_FIELD_NUMBER: _ClassVar[int]
    CLIENT_PROTOCOL_FIELD_NUMBER: _ClassVar[int]
    objects: _containers.RepeatedCompositeFieldContainer[SceneObject]
    targets: _containers.RepeatedCompositeFieldContainer[Target]
    lens: Lens
    style: Style
    seed: int
    record: bool
    level_id: str
    delay_s: float
    pose_outputs: _containers.RepeatedCompositeFieldContainer[PoseOutput]
    client_protocol: int
    def __init__(self, objects: _Optional[_Iterable[_Union[SceneObject, _Mapping]]] = ..., targets: _Optional[_Iterable[_Union[Target, _Mapping]]] = ..., lens: _Optional[_Union[Lens, _Mapping]] = ..., style: _Optional[_Union[Style, _Mapping]] = ..., seed: _Optional[int] = ..., record: _Optional[bool] = ..., level_id: _Optional[str] = ..., delay_s: _Optional[float] = ..., pose_outputs: _Optional[_Iterable[_Union[PoseOutput, _Mapping]]] = ..., client_protocol: _Optional[int] = ...) -> None: ...

class PoseOutput(_message.Message):
    __slots__ = ("format", "address", "source_number", "sensor_height_mm")
    FORMAT_FIELD_NUMBER: _ClassVar[int]
    ADDRESS_FIELD_NUMBER: _ClassVar[int]
    SOURCE_NUMBER_FIELD_NUMBER: _ClassVar[int]
    SENSOR_HEIGHT_MM_FIELD_NUMBER: _ClassVar[int]
    format: PoseFormat
    address: str
    source_number: int
    sensor_height_mm: float
    def __init__(self, format: _Optional[_Union[PoseFormat, str]] = ..., address: _Optional[str] = ..., source_number: _Optional[int] = ..., sensor_height_mm: _Optional[float] = ...) -> None: ...

class CreateSessionResponse(_message.Message):
    __slots__ = ("session_id", "recording_path")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    RECORDING_PATH_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    recording_path: str
    def __init__(self, session_id: _Optional[str] = ..., recording_path: _Optional[str] = ...) -> None: ...

class ObjectState(_message.Message):
    __slots__ = ("id", "transform")
    ID_FIELD_NUMBER: _ClassVar[int]
    TRANSFORM_FIELD_NUMBER: _ClassVar[int]
    id: str
    transform: Transform
    def __init__(self, id: _Optional[str] = ..., transform: _Optional[_Union[Transform, _Mapping]] = ...) -> None: ...

class FrameUpdate(_message.Message):
    __slots__ = ("session_id", "frame", "time_s", "states", "packed_ids", "packed_transforms", "events", "player_stats", "answered_frame")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    TIME_S_FIELD_NUMBER: _ClassVar[int]
    STATES_FIELD_NUMBER: _ClassVar[int]
    PACKED_IDS_FIELD_NUMBER: _ClassVar[int]
    PACKED_TRANSFORMS_FIELD_NUMBER: _ClassVar[int]
    EVENTS_FIELD_NUMBER: _ClassVar[int]
    PLAYER_STATS_FIELD_NUMBER: _ClassVar[int]
    ANSWERED_FRAME_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    frame: int
    time_s: float
    states: _containers.RepeatedCompositeFieldContainer[ObjectState]
    packed_ids: _containers.RepeatedScalarFieldContainer[str]
    packed_transforms: _containers.RepeatedScalarFieldContainer[float]
    events: _containers.RepeatedCompositeFieldContainer[GameEvent]
    player_stats: _containers.RepeatedCompositeFieldContainer[PlayerStats]
    answered_frame: int
    def __init__(self, session_id: _Optional[str] = ..., frame: _Optional[int] = ..., time_s: _Optional[float] = ..., states: _Optional[_Iterable[_Union[ObjectState, _Mapping]]] = ..., packed_ids: _Optional[_Iterable[str]] = ..., packed_transforms: _Optional[_Iterable[float]] = ..., events: _Optional[_Iterable[_Union[GameEvent, _Mapping]]] = ..., player_stats: _Optional[_Iterable[_Union[PlayerStats, _Mapping]]] = ..., answered_frame: _Optional[int] = ...) -> None: ...

class PlayerStats(_message.Message):
    __slots__ = ("id", "health", "armor", "items", "frags")
    ID_FIELD_NUMBER: _ClassVar[int]
    HEALTH_FIELD_NUMBER: _ClassVar[int]
    ARMOR_FIELD_NUMBER: _ClassVar[int]
    ITEMS_FIELD_NUMBER: _ClassVar[int]
    FRAGS_FIELD_NUMBER: _ClassVar[int]
    id: str
    health: int
    armor: int
    items: int
    frags: int
    def __init__(self, id: _Optional[str] = ..., health: _Optional[int] = ..., armor: _Optional[int] = ..., items: _Optional[int] = ..., frags: _Optional[int] = ...) -> None: ...

class GameEvent(_message.Message):
    __slots__ = ("kind", "actor_id", "other_actor_id", "priority", "time_s", "label", "position")
    KIND_FIELD_NUMBER: _ClassVar[int]
    ACTOR_ID_FIELD_NUMBER: _ClassVar[int]
    OTHER_ACTOR_ID_FIELD_NUMBER: _ClassVar[int]
    PRIORITY_FIELD_NUMBER: _ClassVar[int]
    TIME_S_FIELD_NUMBER: _ClassVar[int]
    LABEL_FIELD_NUMBER: _ClassVar[int]
    POSITION_FIELD_NUMBER: _ClassVar[int]
    kind: EventKind
    actor_id: str
    other_actor_id: str
    priority: int
    time_s: float
    label: str
    position: Vec3
    def __init__(self, kind: _Optional[_Union[EventKind, str]] = ..., actor_id: _Optional[str] = ..., other_actor_id: _Optional[str] = ..., priority: _Optional[int] = ..., time_s: _Optional[float] = ..., label: _Optional[str] = ..., position: _Optional[_Union[Vec3, _Mapping]] = ...) -> None: ...

class ShotInfo(_message.Message):
    __slots__ = ("subject_ids", "kind", "reason", "held", "replay_frame", "replay_time_s", "replay_kill_time_s", "eyes_id")
    SUBJECT_IDS_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    REASON_FIELD_NUMBER: _ClassVar[int]
    HELD_FIELD_NUMBER: _ClassVar[int]
    REPLAY_FRAME_FIELD_NUMBER: _ClassVar[int]
    REPLAY_TIME_S_FIELD_NUMBER: _ClassVar[int]
    REPLAY_KILL_TIME_S_FIELD_NUMBER: _ClassVar[int]
    EYES_ID_FIELD_NUMBER: _ClassVar[int]
    subject_ids: _containers.RepeatedScalarFieldContainer[str]
    kind: ShotKind
    reason: str
    held: bool
    replay_frame: int
    replay_time_s: float
    replay_kill_time_s: float
    eyes_id: str
    def __init__(self, subject_ids: _Optional[_Iterable[str]] = ..., kind: _Optional[_Union[ShotKind, str]] = ..., reason: _Optional[str] = ..., held: _Optional[bool] = ..., replay_frame: _Optional[int] = ..., replay_time_s: _Optional[float] = ..., replay_kill_time_s: _Optional[float] = ..., eyes_id: _Optional[str] = ...) -> None: ...

class CandidateShot(_message.Message):
    __slots__ = ("pose", "shot", "score")
    POSE_FIELD_NUMBER: _ClassVar[int]
    SHOT_FIELD_NUMBER: _ClassVar[int]
    SCORE_FIELD_NUMBER: _ClassVar[int]
    pose: CameraPose
    shot: ShotInfo
    score: float
    def __init__(self, pose: _Optional[_Union[CameraPose, _Mapping]] = ..., shot: _Optional[_Union[ShotInfo, _Mapping]] = ..., score: _Optional[float] = ...) -> None: ...

class CameraPose(_message.Message):
    __slots__ = ("position", "rotation", "vertical_fov_deg")
    POSITION_FIELD_NUMBER: _ClassVar[int]
    ROTATION_FIELD_NUMBER: _ClassVar[int]
    VERTICAL_FOV_DEG_FIELD_NUMBER: _ClassVar[int]
    position: Vec3
    rotation: Quat
    vertical_fov_deg: float
    def __init__(self, position: _Optional[_Union[Vec3, _Mapping]] = ..., rotation: _Optional[_Union[Quat, _Mapping]] = ..., vertical_fov_deg: _Optional[float] = ...) -> None: ...

class Diagnostics(_message.Message):
    __slots__ = ("theta", "phi", "alpha", "stage_ms", "flags", "scores")
    class StageMsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    class ScoresEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    THETA_FIELD_NUMBER: _ClassVar[int]
    PHI_FIELD_NUMBER: _ClassVar[int]
    ALPHA_FIELD_NUMBER: _ClassVar[int]
    STAGE_MS_FIELD_NUMBER: _ClassVar[int]
    FLAGS_FIELD_NUMBER: _ClassVar[int]
    SCORES_FIELD_NUMBER: _ClassVar[int]
    theta: float
    phi: float
    alpha: float
    stage_ms: _containers.ScalarMap[str, float]
    flags: _containers.RepeatedScalarFieldContainer[str]
    scores: _containers.ScalarMap[str, float]
    def __init__(self, theta: _Optional[float] = ..., phi: _Optional[float] = ..., alpha: _Optional[float] = ..., stage_ms: _Optional[_Mapping[str, float]] = ..., flags: _Optional[_Iterable[str]] = ..., scores: _Optional[_Mapping[str, float]] = ...) -> None: ...

class CameraUpdate(_message.Message):
    __slots__ = ("frame", "time_s", "pose", "cut", "shot_id", "visibility", "compute_ms", "stale", "message", "diagnostics", "shot", "candidates", "buffering")
    FRAME_FIELD_NUMBER: _ClassVar[int]
    TIME_S_FIELD_NUMBER: _ClassVar[int]
    POSE_FIELD_NUMBER: _ClassVar[int]
    CUT_FIELD_NUMBER: _ClassVar[int]
    SHOT_ID_FIELD_NUMBER: _ClassVar[int]
    VISIBILITY_FIELD_NUMBER: _ClassVar[int]
    COMPUTE_MS_FIELD_NUMBER: _ClassVar[int]
    STALE_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    DIAGNOSTICS_FIELD_NUMBER: _ClassVar[int]
    SHOT_FIELD_NUMBER: _ClassVar[int]
    CANDIDATES_FIELD_NUMBER: _ClassVar[int]
    BUFFERING_FIELD_NUMBER: _ClassVar[int]
    frame: int
    time_s: float
    pose: CameraPose
    cut: bool
    shot_id: int
    visibility: float
    compute_ms: float
    stale: bool
    message: str
    diagnostics: Diagnostics
    shot: ShotInfo
    candidates: _containers.RepeatedCompositeFieldContainer[CandidateShot]
    buffering: bool
    def __init__(self, frame: _Optional[int] = ..., time_s: _Optional[float] = ..., pose: _Optional[_Union[CameraPose, _Mapping]] = ..., cut: _Optional[bool] = ..., shot_id: _Optional[int] = ..., visibility: _Optional[float] = ..., compute_ms: _Optional[float] = ..., stale: _Optional[bool] = ..., message: _Optional[str] = ..., diagnostics: _Optional[_Union[Diagnostics, _Mapping]] = ..., shot: _Optional[_Union[ShotInfo, _Mapping]] = ..., candidates: _Optional[_Iterable[_Union[CandidateShot, _Mapping]]] = ..., buffering: _Optional[bool] = ...) -> None: ...

class UpdateStyleRequest(_message.Message):
    __slots__ = ("session_id", "style")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    STYLE_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    style: Style
    def __init__(self, session_id: _Optional[str] = ..., style: _Optional[_Union[Style, _Mapping]] = ...) -> None: ...

class UpdateStyleResponse(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class TakeShotRequest(_message.Message):
    __slots__ = ("session_id", "subject_ids", "kind", "release")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    SUBJECT_IDS_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    RELEASE_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    subject_ids: _containers.RepeatedScalarFieldContainer[str]
    kind: ShotKind
    release: bool
    def __init__(self, session_id: _Optional[str] = ..., subject_ids: _Optional[_Iterable[str]] = ..., kind: _Optional[_Union[ShotKind, str]] = ..., release: _Optional[bool] = ...) -> None: ...

class TakeShotResponse(_message.Message):
    __slots__ = ("shot",)
    SHOT_FIELD_NUMBER: _ClassVar[int]
    shot: ShotInfo
    def __init__(self, shot: _Optional[_Union[ShotInfo, _Mapping]] = ...) -> None: ...

class CloseSessionRequest(_message.Message):
    __slots__ = ("session_id",)
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    def __init__(self, session_id: _Optional[str] = ...) -> None: ...

class CloseSessionResponse(_message.Message):
    __slots__ = ("frames",)
    FRAMES_FIELD_NUMBER: _ClassVar[int]
    frames: int
    def __init__(self, frames: _Optional[int] = ...) -> None: ...

class RecordEntry(_message.Message):
    __slots__ = ("create", "frame", "style", "camera", "take")
    CREATE_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    STYLE_FIELD_NUMBER: _ClassVar[int]
    CAMERA_FIELD_NUMBER: _ClassVar[int]
    TAKE_FIELD_NUMBER: _ClassVar[int]
    create: CreateSessionRequest
    frame: FrameUpdate
    style: UpdateStyleRequest
    camera: CameraUpdate
    take: TakeShotRequest
    def __init__(self, create: _Optional[_Union[CreateSessionRequest, _Mapping]] = ..., frame: _Optional[_Union[FrameUpdate, _Mapping]] = ..., style: _Optional[_Union[UpdateStyleRequest, _Mapping]] = ..., camera: _Optional[_Union[CameraUpdate, _Mapping]] = ..., take: _Optional[_Union[TakeShotRequest, _Mapping]] = ...) -> None: ...
