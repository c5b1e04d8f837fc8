"""Motion overview of a clip: the paper's stages in order (Figure 3), one module each.

    Stage.TRACK      character_track.py   the character at the analysis rate
    Stage.SALIENCY   saliency.py          S_p and S_limb (non-linear MDS vs smooth curve)
    Stage.LIMBS      limb_visibility.py   E_limb by rendering ellipsoids (moderngl EGL)
    Stage.POTENTIAL  potential.py         V over candidate positions x frames (viewpoint_quality.py)
    Stage.SHOTS      shots.py             quantum annealing (annealing.py) and shot splitting
    Stage.FRAMING    framing.py           positions, look-at and FOV per shot at the clip's rate

Time base (our deviation, documented): every stage up to SHOTS runs on clip frames taken every
round(clip rate / `analysis_rate_hz`) frames (15 Hz by default: every 2nd frame at 30 fps, every
8th at 120 fps); FRAMING interpolates the path back to every clip frame. The paper runs on every
frame; sampling keeps a 1000-frame clip under 10 s on two CPU cores. The speed limit, the frame
containment and the bounding-volume checks hold at every clip frame (framing.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

import numpy as np

from camdirector.infra.stage_clock import StageClock
from camdirector.precompute.overview.body_parts import BodyPartMap, map_body_parts
from camdirector.precompute.overview.bvh import MotionClip
from camdirector.precompute.overview.character_track import CharacterTrack, sample_frames, track_character
from camdirector.precompute.overview.energy import EnergyWeights, PathEnergy, path_energy
from camdirector.precompute.overview.final_framing import Framing, frame_clip
from camdirector.precompute.overview.limb_visibility import LimbVisibilityRenderer, render_limb_visibility
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.potential import PotentialSpace, build_potential_space
from camdirector.precompute.overview.saliency import Saliency, compute_saliency
from camdirector.precompute.overview.shot_splitting import ShotPlan, plan_shots


class Stage(Enum):
    """Pipeline order; values are the keys of `OverviewResult.timings_ms`."""

    TRACK = "track"
    SALIENCY = "saliency"
    LIMBS = "limb_visibility"
    POTENTIAL = "potential"
    SHOTS = "annealing_and_shots"
    FRAMING = "framing"


_PROGRESS_AFTER: dict[Enum, float] = {
    Stage.TRACK: 0.02,
    Stage.SALIENCY: 0.2,
    Stage.LIMBS: 0.45,
    Stage.POTENTIAL: 0.6,
    Stage.SHOTS: 0.97,
    Stage.FRAMING: 1.0,
}


@dataclass(frozen=True)
class OverviewAnalysis:
    """What the stages computed at the analysis rate (for evaluation and plots): parts, track,
    saliency, potential space, the energy constants and the shot plan (analysis-frame indices)."""

    parts: BodyPartMap
    track: CharacterTrack
    saliency: Saliency
    space: PotentialSpace
    weights: EnergyWeights
    plan: ShotPlan


@dataclass(frozen=True)
class OverviewResult:
    """The overview camera of a clip, one row per clip frame (F).

    camera_position_m (F, 3), look_at_m (F, 3), up (F, 3) world +Y, rotation_xyzw (F, 4)
    camera-to-world (looks down -Z), vertical_fov_deg (F,), shot_index (F,) int;
    shots (S, 2) int [first, last] clip frames; energy: E, E_internal, E_external and sum V of
    the path at the analysis rate (Section 4); quality: (T,) Q(p_t) at the analysis frames;
    analysis_frames (T,) int; frame_time_s: the clip's; character_height_m; max_speed_m_s
    (S_max); timings_ms: per `Stage` value, milliseconds; settings: those used; analysis: the
    stages' intermediate results.
    """

    camera_position_m: np.ndarray
    look_at_m: np.ndarray
    up: np.ndarray
    rotation_xyzw: np.ndarray
    vertical_fov_deg: np.ndarray
    shot_index: np.ndarray
    shots: np.ndarray
    energy: PathEnergy
    quality: np.ndarray
    analysis_frames: np.ndarray
    frame_time_s: float
    character_height_m: float
    max_speed_m_s: float
    timings_ms: dict[str, float]
    settings: OverviewSettings
    analysis: OverviewAnalysis


def plan_overview(
    clip: MotionClip,
    settings: OverviewSettings,
    rng: np.random.Generator,
    *,
    scene=None,
    progress: Callable[[float], None] | None = None,
    renderer: LimbVisibilityRenderer | None = None,
) -> OverviewResult:
    """Plan a multi-shot overview camera for a motion clip (the paper's whole method).

    scene: optional static trimesh.Trimesh whose triangles occlude the character;
    progress: called with the fraction done (0..1] after each stage;
    renderer: an existing LimbVisibilityRenderer to reuse (one is made and released otherwise).
    Raises ValueError when the skeleton cannot be mapped or no camera position frames the body.
    """
    stage_clock = StageClock(progress, _PROGRESS_AFTER)
    done = stage_clock.done
    timings = stage_clock.timings_ms

    parts = map_body_parts(clip)
    analysis_frames = sample_frames(clip.frame_count, clip.frame_time_s, settings.analysis_rate_hz)
    track = track_character(clip, parts, settings, analysis_frames)
    done(Stage.TRACK)
    saliency = compute_saliency(track, parts, settings)
    done(Stage.SALIENCY)
    own_renderer = renderer is None
    limb_renderer = LimbVisibilityRenderer(settings.limb_tile_px) if renderer is None else renderer
    try:
        limbs = render_limb_visibility(clip, parts, track, saliency.pose, settings, limb_renderer)
    finally:
        if own_renderer:
            limb_renderer.release()
    done(Stage.LIMBS)
    space = build_potential_space(track, parts, saliency, limbs, settings, scene)
    done(Stage.POTENTIAL)
    weights = EnergyWeights.for_track(track, settings)
    max_shots = max(1, math.ceil(settings.max_shots_per_1000_frames * clip.frame_count / 1000.0))
    plan = plan_shots(track, space, saliency.pose, weights, settings, rng, max_shots)
    done(Stage.SHOTS)
    track_full = track_character(clip, parts, settings, np.arange(clip.frame_count))
    framing: Framing = frame_clip(track_full, plan.path_m, plan.shots, analysis_frames, settings)
    done(Stage.FRAMING)
    return OverviewResult(
        camera_position_m=framing.position_m,
        look_at_m=framing.look_at_m,
        up=framing.up,
        rotation_xyzw=framing.rotation_xyzw,
        vertical_fov_deg=framing.vertical_fov_deg,
        shot_index=framing.shot_index,
        shots=framing.shots,
        energy=path_energy(plan.path_m, plan.shots, track, space, saliency.pose, weights),
        quality=plan.quality_history[-1],
        analysis_frames=analysis_frames,
        frame_time_s=clip.frame_time_s,
        character_height_m=track.height_m,
        max_speed_m_s=weights.max_speed_m_s,
        timings_ms=timings,
        settings=settings,
        analysis=OverviewAnalysis(parts=parts, track=track, saliency=saliency, space=space, weights=weights, plan=plan),
    )
