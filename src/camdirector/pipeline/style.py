"""The director's style: one typed object, defaults with unit and limit, validated once.

Mirrors `camdirector.v1.Style`; `worker/codec.py` converts and validates at the edge. `rig` picks
the camera rig: TORIC (the framing rig, every field but the last two) or TRACKS (camera tracks on
a precomputed level, tracks/rig.py), which reads only `shot_size` and `movement` (the directorial
styles of the topology-aware camera tracks paper, Section 6.1) and handles occlusion by its own
cutting strategy, so a TORIC visibility mode is refused with it.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class VisibilityMode(enum.IntEnum):
    """Same numbers as camdirector.v1.VisibilityMode."""

    UNSPECIFIED = 0
    ANTICIPATION = 1
    NO_ANTICIPATION = 2
    RAYCAST = 3
    REACTIVE = 4
    FRAMING_ONLY = 5


class MapBackendChoice(enum.IntEnum):
    """Same numbers as camdirector.v1.MapBackend."""

    AUTO = 0
    GL = 1
    EMBREE = 2


class MaskKind(enum.Enum):
    """Viewpoints the TORIC map modes avoid: the occlusion-anticipation paper's Figure 10 masks
    (Section 5.2), computed by pipeline/toric/style_masks.py."""

    EMPTY = "empty"  # (a) no preference
    SOFT_BEHIND = "soft_behind"  # (b) flexible exclusion behind the targets, a gradient
    HARD_BEHIND = "hard_behind"  # (c) hard exclusion behind the targets
    AVOID_BEHIND_TOP_BOTTOM = "avoid_behind_top_bottom"  # (d) smooth: behind, top views and bottom views


class ShotSize(enum.Enum):
    """TRACKS: the actor's size on screen (the camera-tracks paper, Section 6.1); what each keeps in
    frame is pipeline/tracks/shot_sizes.py's."""

    MEDIUM = "medium"
    LONG = "long"
    EXTREME_LONG = "extreme_long"


class Movement(enum.Enum):
    """TRACKS: how the camera may move and cut (the camera-tracks paper, Section 6.1)."""

    DYNAMIC_NO_CUTS = "dynamic_no_cuts"
    DYNAMIC_WITH_CUTS = "dynamic_with_cuts"
    STATIC = "static"


class Rig(enum.IntEnum):
    """Same numbers as camdirector.v1.Rig (UNSPECIFIED is TORIC and never stored)."""

    TORIC = 1
    TRACKS = 2
    MATCH = 3


# Modes whose camera moves by the paper's search (occlusion_search.py) rather than the toric spring.
SEARCH_MODES = frozenset({VisibilityMode.ANTICIPATION, VisibilityMode.NO_ANTICIPATION, VisibilityMode.RAYCAST})
# Modes that read the occlusion maps (occlusion_maps.py).
MAP_MODES = frozenset({VisibilityMode.ANTICIPATION, VisibilityMode.NO_ANTICIPATION})


@dataclass(frozen=True)
class Style:
    screen_a: tuple[float, float] = (-1.0 / 3.0, 0.0)  # normalised screen point of A, each in [-1, 1]
    screen_b: tuple[float, float] = (1.0 / 3.0, 0.0)  # of B (or the gaze-room point); != screen_a
    visibility: VisibilityMode = VisibilityMode.FRAMING_ONLY
    gaze_room_m: float = 2.5  # one target: lead point distance ahead, m. [0.05, 1000]
    preferred_theta_ratio: float = 0.35  # place on the arc, 0 at A .. 1 at B. [0.02, 0.98]
    preferred_phi_deg: float = 70.0  # 0 above the A-B axis, 90 level beside it, deg. [0, 180]
    response_time_s: float = 0.5  # time constant of the damped return to the preferred place, s. [0.02, 60]
    max_speed_m_s: float = 8.0  # camera speed limit on the torus, m/s. (0, 1000]
    max_accel_m_s2: float = 12.0  # camera acceleration limit on the torus, m/s^2. (0, 10000]
    mask: MaskKind = MaskKind.EMPTY  # viewpoints the map modes avoid (the paper's Figure 10)
    map_resolution: int = 64  # occlusion map texels per side. [16, 512]
    map_backend: MapBackendChoice = MapBackendChoice.AUTO  # how the maps are computed
    rig: Rig = Rig.TORIC  # the camera rig
    shot_size: ShotSize = ShotSize.LONG  # TRACKS: the actor's size on screen
    movement: Movement = Movement.DYNAMIC_WITH_CUTS  # TRACKS: how the camera may move and cut
    match_director: str = "planned"  # MATCH: which director picks the shots, a name of match/director_registry.py
    min_shot_s: float = 2.0  # MATCH: shortest shot, except after a take, s. [0.5, 30]
    max_shot_s: float = 8.0  # MATCH: longest shot the director makes without an event, s. [min_shot_s, 120]

    def __post_init__(self) -> None:
        for name, value, kind in (
            ("rig", self.rig, Rig),
            ("shot_size", self.shot_size, ShotSize),
            ("movement", self.movement, Movement),
            ("match_director", self.match_director, str),
        ):
            if not isinstance(value, kind):
                raise ValueError(f"style.{name} must be a {kind.__name__}, got {value!r}")
        if self.rig == Rig.MATCH and self.visibility != VisibilityMode.FRAMING_ONLY:
            raise ValueError(
                f"style.visibility {self.visibility.name} is a mode of the TORIC rig; the MATCH rig "
                "chooses its camera places by ray casts itself: leave style.visibility unset"
            )
        if self.rig == Rig.TRACKS and self.visibility != VisibilityMode.FRAMING_ONLY:
            raise ValueError(
                f"style.visibility {self.visibility.name} is a mode of the TORIC rig; the TRACKS rig "
                "cuts away from occlusion itself: leave style.visibility unset"
            )
        for name, point in (("screen_a", self.screen_a), ("screen_b", self.screen_b)):
            if not all(math.isfinite(c) and -1.0 <= c <= 1.0 for c in point):
                raise ValueError(f"style.{name} must have x and y in [-1, 1], got {point}")
        if math.dist(self.screen_a, self.screen_b) < 1e-3:
            raise ValueError("style.screen_a and style.screen_b must differ")
        limits = [
            ("gaze_room_m", self.gaze_room_m, 0.05, 1000.0),
            ("preferred_theta_ratio", self.preferred_theta_ratio, 0.02, 0.98),
            ("preferred_phi_deg", self.preferred_phi_deg, 0.0, 180.0),
            ("response_time_s", self.response_time_s, 0.02, 60.0),
            ("max_speed_m_s", self.max_speed_m_s, 1e-6, 1000.0),
            ("max_accel_m_s2", self.max_accel_m_s2, 1e-6, 10000.0),
            ("min_shot_s", self.min_shot_s, 0.5, 30.0),
            ("max_shot_s", self.max_shot_s, self.min_shot_s, 120.0),
        ]
        if not 16 <= self.map_resolution <= 512:
            raise ValueError(f"style.map_resolution must be in [16, 512], got {self.map_resolution}")
        for limited, number, low, high in limits:
            if not (math.isfinite(number) and low <= number <= high):
                raise ValueError(f"style.{limited} must be in [{low:g}, {high:g}], got {number}")
