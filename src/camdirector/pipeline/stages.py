"""The per-frame director pipeline: the order of its stages and the state passed along them.

Stage order (one module each; `Stage` values are the `stage_ms` keys on the wire):
  INGEST      sessions/session.py       apply the frame's transforms to targets and the ray scene
  FRAMING     pipeline/toric/framing.py  framed points A and B (gaze room for one target), the
                                         torus; the occlusion maps take in the moved objects
  PROJECTION  pipeline/toric/occlusion_maps.py  S-maps and V-maps of the target samples (map
                                         modes, on schedule)
  AMAP        pipeline/toric/anticipation.py  the occlusion anticipation map (map modes, on schedule)
  MOTION      pipeline/toric/camera_motion.py  FRAMING_ONLY: damped return to the preferred place;
              pipeline/toric/reactive.py       REACTIVE: that, pulled in front of occluders;
              pipeline/toric/occlusion_search.py  RAYCAST and map modes: the paper's search and cuts
  VISIBILITY  pipeline/toric/visibility.py  the rig's own estimate of how much of the targets is visible

FRAMING to VISIBILITY are the TORIC rig's (pipeline/toric/rig.py runs them in this order). With
`style.rig = TRACKS` (pipeline/tracks/rig.py, the graph director of the camera-tracks paper) a
frame is INGEST, then MOTION and VISIBILITY by the director in its own order (Section 5), with
its own `stage_ms` keys (`TracksStage`; no FRAMING, PROJECTION or AMAP):
  cut_check      direct visibility of the actor and the framing check feed the cutting strategy
  target_update  a cut's continuity search, or the target moving strategy on the tracks
  camera_update  the camera jumps on a cut or follows the target by the force model; the
                 actor's visibility from the new position
With `style.rig = MATCH` (pipeline/match/rig.py, the casting director) a frame is INGEST, then
`MatchStage`: BUFFER (the delay buffer; while it fills, no pose), PLAN (on planning ticks), CAMERA,
VISIBILITY.
Each stage is lapped by one `precompute.stage_clock.StageClock` on the session's injected clock.
Building the reply (sessions/codec.py) is no stage: it happens after `stage_ms` has been read
into the reply, so it is counted only in the frame's `compute_ms`, which the session table
measures around the whole frame.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.toric import Torus
from camdirector.pipeline.inputs import GameEvent
from camdirector.pipeline.tracks.director import DirectorStage as TracksStage  # noqa: F401  (its stage_ms keys)


class Stage(enum.Enum):
    """The TORIC pipeline's stages in order; values are their `stage_ms` keys."""

    INGEST = "ingest"
    FRAMING = "framing"
    PROJECTION = "projection"
    AMAP = "amap"
    MOTION = "motion"
    VISIBILITY = "visibility"


class MatchStage(enum.Enum):
    """The MATCH rig's stages after INGEST in order (pipeline/match/rig.py); values are their `stage_ms` keys."""

    BUFFER = "buffer"          # the delay buffer takes the frame and gives the program moment
    PLAN = "plan"              # a planning tick: takes, the director's cut decision, candidates
    CAMERA = "camera"          # the program camera's motion and pose, the candidates' poses
    VISIBILITY = "visibility"  # the framed subjects' visibility by ray casts


class ShotKind(enum.IntEnum):
    """MATCH: what a shot shows (same numbers as camdirector.v1.ShotKind)."""

    DUEL = 1      # two opposing players, the Toric framing of both
    FOLLOW = 2    # one player
    GROUP = 3     # several players
    OVERVIEW = 4  # a high static view of the action


@dataclass(frozen=True)
class ShotChoice:
    """MATCH: whom a shot shows, how, and why (a human-readable reason)."""

    subject_ids: tuple[str, ...]
    kind: ShotKind
    reason: str
    held: bool = False  # a human's take (or its fallback), kept until released


@dataclass(frozen=True)
class Candidate:
    """MATCH: another shot the director could cut to now, for a human director's preview monitors."""

    pose: CameraPose
    shot: ShotChoice
    score: float  # the director's interest in it, >= 0 (comparable within one frame)


@dataclass(frozen=True)
class PlannedCut:
    """MATCH: the next cut the director has planned (with a delay, for an event it knows is coming)."""

    time_s: float     # program time of the cut, s
    shot: ShotChoice  # the shot it will cut to, with the reason


@dataclass
class FrameState:
    """What one frame computes, filled stage by stage."""

    frame: int
    time_s: float
    dt_s: float                                  # since the previous answered frame, s (0 on the first)
    aim_points_world: list[np.ndarray] = field(default_factory=list)  # (3,) per target
    a_world: np.ndarray | None = None            # (3,) framed point A
    b_world: np.ndarray | None = None            # (3,) framed point B
    b_is_gaze_point: bool = False                # B is the one target's gaze-room point, not a target
    torus: Torus | None = None
    theta: float = 0.0                           # rad
    phi: float = 0.0                             # rad
    pose: CameraPose | None = None
    cut: bool = False
    shot_id: int = 0
    visibility: float = 1.0                      # [0, 1]
    framing_error: float = math.nan              # framed points from where the style puts them, screen units (NaN: none)
    flags: list[str] = field(default_factory=list)  # degraded-mode notes for diagnostics
    scores: dict[str, float] = field(default_factory=dict)  # TRACKS: the chosen target's sub-scores, [0, 1]
    stage_ms: dict[str, float] = field(default_factory=dict)
    shot: ShotChoice | None = None               # MATCH: the program's shot
    candidates: list[Candidate] = field(default_factory=list)  # MATCH: the best other shots now
    buffering: bool = False                      # MATCH: the broadcast delay is still filling; no pose
    players: tuple[tuple[str, int], ...] = ()    # MATCH: (id, team) of each target in target order (the rig's)
    events: list[GameEvent] = field(default_factory=list)  # MATCH: the game events at the program moment
    planned_cut: PlannedCut | None = None        # MATCH: the director's next planned cut, if it has one
