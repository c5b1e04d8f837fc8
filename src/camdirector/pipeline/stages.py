"""The per-frame director pipeline: the order of its stages, written down here and nowhere else.

Stage order (one module each; `Stage` values are the `stage_ms` keys on the wire):
  INGEST      pipeline/session.py       apply the frame's transforms to targets and the ray scene
  FRAMING     pipeline/toric/framing.py  framed points A and B (gaze room for one target), the
                                         torus; the occlusion maps take in the moved objects
  PROJECTION  pipeline/toric/occlusion_maps.py  S-maps and V-maps of the target samples (map
                                         modes, on schedule)
  AMAP        pipeline/toric/anticipation_map.py  the occlusion anticipation map (map modes, on schedule)
  MOTION      pipeline/toric/camera_motion.py  FRAMING_ONLY: damped return to the preferred place;
              pipeline/toric/reactive.py       REACTIVE: that, pulled in front of occluders;
              pipeline/toric/occlusion_search.py  RAYCAST and map modes: the paper's search and cuts
  VISIBILITY  pipeline/toric/visibility.py  the rig's own estimate of how much of the targets is visible

After INGEST the session's rig runs the rest (`CameraRig.run`, pipeline/camera_rig.py, which also
chooses the rig). FRAMING to VISIBILITY are the TORIC rig's (pipeline/toric/rig.py runs them in
this order). With `style.rig = TRACKS` (pipeline/tracks/rig.py, the graph director of the
camera-tracks paper) a frame is INGEST, then MOTION and VISIBILITY by the director in its own
order (Section 5), with its own `stage_ms` keys (`TracksStage`; no FRAMING, PROJECTION or AMAP):
  cut_check      direct visibility of the actor and the framing check feed the cutting strategy
  target_update  a cut's continuity search, or the target moving strategy on the tracks
  camera_update  the camera jumps on a cut or follows the target by the force model; the
                 actor's visibility from the new position
With `style.rig = MATCH` (pipeline/match/rig.py, the casting director) a frame is INGEST, then
`MatchStage`: BUFFER (the delay buffer; while it fills, no pose), then for each frame the edit
window works out ahead of the program moment PLAN (on planning ticks), CAMERA, VISIBILITY and EDIT,
then EDIT again for the program moment's frame answered.
The state passed along the stages, `FrameState`, is pipeline/state.py's: a core every rig fills
and the part of the rig that ran the frame.
Each stage is lapped on the session's injected clock: INGEST by the session itself, the rig's by
an `infra.stage_clock.StageClock` (the compiled TORIC rig's FRAMING_ONLY and REACTIVE frames by
`camdirector._native.toric_frame`, at the same readings).
Building the reply (worker/codec.py) is no stage: it happens after `stage_ms` has been read
into the reply, so it is counted only in the frame's `compute_ms`, which the session table
measures around the whole frame.
"""

from __future__ import annotations

import enum


class Stage(enum.Enum):
    """The TORIC pipeline's stages in order; values are their `stage_ms` keys."""

    INGEST = "ingest"
    FRAMING = "framing"
    PROJECTION = "projection"
    AMAP = "amap"
    MOTION = "motion"
    VISIBILITY = "visibility"


class TracksStage(enum.Enum):
    """The TRACKS rig's stages after INGEST in order: the graph director's steps of one frame
    (pipeline/tracks/director.py, the camera-tracks paper's Section 5); values are their `stage_ms` keys."""

    CUT_CHECK = "cut_check"  # direct visibility and framing feed the cutting strategy
    TARGET_UPDATE = "target_update"  # a cut's continuity search, or the target moving strategy
    CAMERA_UPDATE = "camera_update"  # the camera jumps or follows; the actor's visibility from there


class MatchStage(enum.Enum):
    """The MATCH rig's stages after INGEST in order (pipeline/match/rig.py); values are their `stage_ms` keys."""

    BUFFER = "buffer"  # the delay buffer takes the frame and gives the program moment
    PLAN = "plan"  # a planning tick: takes, the director's cut decision, candidates
    CAMERA = "camera"  # the program camera's motion and pose, the candidates' poses
    VISIBILITY = "visibility"  # the framed subjects' visibility by ray casts
    EDIT = "edit"  # the edit window: a short shot given to a neighbour, the program moment's frame answered (edit_window.py)
