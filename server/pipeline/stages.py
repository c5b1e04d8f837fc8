"""The per-frame director pipeline: the order of its stages and the state passed along them.

Stage order (one module each):
  INGEST      session.py        apply the frame's transforms to targets and the ray scene
  FRAMING     framing.py        framed points A and B (gaze room for one target), the torus
  PROJECTION  occlusion_maps.py S-maps and V-maps of the target samples (map modes, on schedule)
  AMAP        anticipation.py   the occlusion anticipation map (map modes, on schedule)
  MOTION      camera_motion.py  FRAMING_ONLY: damped return to the preferred place;
              reactive.py       REACTIVE: that, pulled in front of occluders;
              occlusion_search.py  RAYCAST and map modes: the paper's search and cuts
  VISIBILITY  visibility.py     the rig's own estimate of how much of the targets is visible
  OUTPUT      wire.py           the CameraUpdate

FRAMING to VISIBILITY are the TORIC rig's (toric_rig.py runs them in this order). With
`style.rig = TRACKS` (tracks_rig.py, the graph director of the camera-tracks paper) a
frame is INGEST, then MOTION and VISIBILITY by the director in its own order (Section 5):
  cut_check      direct visibility of the actor and the framing check feed the cutting strategy
  target_update  a cut's continuity search, or the target moving strategy on the tracks
  camera_update  the camera jumps on a cut or follows the target by the force model; the
                 actor's visibility from the new position
then OUTPUT; these three names are its `stage_ms` keys (no FRAMING, PROJECTION or AMAP).
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.toric import Torus


class Stage(enum.IntEnum):
    INGEST = 0
    FRAMING = 1
    PROJECTION = 2
    AMAP = 3
    MOTION = 4
    VISIBILITY = 5
    OUTPUT = 6


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
    flags: list[str] = field(default_factory=list)  # degraded-mode notes for diagnostics
    scores: dict[str, float] = field(default_factory=dict)  # TRACKS: the chosen target's sub-scores, [0, 1]
    stage_ms: dict[str, float] = field(default_factory=dict)
