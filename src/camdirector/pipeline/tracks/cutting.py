"""Cutting strategy (Section 5.1): the checks that need no new target position.

A cut is due when the shot has lasted its drawn duration (a log-normal model of shot durations
[Galvane et al. 2015b]: ln(duration) ~ N(ln `shot_duration_median_s`, `shot_duration_sigma`),
never under `min_shot_s`), when the actor has been occluded for longer than `occlusion_cut_s`
(200 ms in the paper), or when the framing (shot size) has been violated for longer than
`framing_cut_s` (200 ms). Occlusion and framing count from the first frame they are seen bad.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from camdirector.pipeline.tracks.settings import DirectorSettings


class CutReason(Enum):
    FIRST_SHOT = "first_shot"
    SHOT_DURATION = "shot_duration"
    OCCLUSION = "occlusion"
    FRAMING = "framing"
    NO_TARGET = "no_target"


def draw_shot_duration_s(rng: np.random.Generator, settings: DirectorSettings) -> float:
    """One shot duration from the log-normal model, seconds (at least `min_shot_s`)."""
    return max(settings.min_shot_s, float(rng.lognormal(np.log(settings.shot_duration_median_s), settings.shot_duration_sigma)))


@dataclass
class CutClock:
    """Running timers of the current shot, seconds of the session clock."""

    shot_start_s: float
    shot_duration_s: float
    occluded_since_s: float | None = None
    misframed_since_s: float | None = None

    def observe(self, time_s: float, occluded: bool, misframed: bool) -> None:
        """Record this frame's occlusion and framing state."""
        self.occluded_since_s = (self.occluded_since_s if self.occluded_since_s is not None else time_s) if occluded else None
        self.misframed_since_s = (self.misframed_since_s if self.misframed_since_s is not None else time_s) if misframed else None

    def reason(self, time_s: float, settings: DirectorSettings) -> CutReason | None:
        """Why a cut is due now, or None."""
        if self.occluded_since_s is not None and time_s - self.occluded_since_s > settings.occlusion_cut_s:
            return CutReason.OCCLUSION
        if self.misframed_since_s is not None and time_s - self.misframed_since_s > settings.framing_cut_s:
            return CutReason.FRAMING
        if time_s - self.shot_start_s >= self.shot_duration_s:
            return CutReason.SHOT_DURATION
        return None
