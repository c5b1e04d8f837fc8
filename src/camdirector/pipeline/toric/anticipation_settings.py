"""The occlusion anticipation map's parameters: the per-sample prediction's (occlusion_prediction.py)
and the map's schedule (anticipation_map.py).

Paper: occlusion-anticipation-toric-space.md, section 4.2 (delta_W, gamma_W), 6 ("Computational
costs breakdown": refresh 2 of the 2r maps per update, one update every W / r seconds) and Table 2
(r = 5, delta_W = 0.6, gamma_W = 0.5). Where the paper leaves a value open, the field's comment says
our choice; occlusion_prediction.py's docstring says how we read delta_W and W.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from camdirector.geometry.toric_maps.base import WindowSettings


@dataclass(frozen=True)
class AnticipationSettings:
    """The A-map's parameters; defaults are the paper's (Table 2, section 6) where it gives them."""

    samples_per_target: int = 5          # r: sample points (and maps) per target. [1, 16]
    horizon_s: float = 0.5               # W: prediction window; one update every W / r, s. [0.02, 10]
    length_cutoff: float = 0.6           # delta_W: length falloff, relative to the predicted travel. (0, 4]
    angle_cutoff_rad: float = 0.5        # gamma_W: angular falloff, rad. (0, pi]
    anticipate: bool = True              # False: A_s = S_s, the paper's "without anticipation" variant
    max_travel_texels: float = 16.0      # predicted travel over W is clamped to this, texels. [1, 256]
    min_travel_texels: float = 0.5       # slower occluders stay in their texel, texels. [0.05, 4]
    direction_bins: int = 64             # kernel bank: travel directions (5.6 deg apart by default). [8, 1024]
    length_bin_ratio: float = 1.1        # kernel bank: ratio of successive travel lengths. (1, 2]
    window: WindowSettings = field(default_factory=WindowSettings)  # map window and resolution (64 x 64)
    # Ours, not the paper's: an amortized update reaches the search this many frames after the frame
    # it is due on, and is computed in between when its worker is idle (occlusion_maps.py); 0: at once.
    # More than 1 costs the map modes' visibility (docs/toric.md). [0, 16]
    apply_after_frames: int = 1

    def __post_init__(self) -> None:
        checks = [
            (1 <= self.samples_per_target <= 16, "samples_per_target must be in [1, 16]"),
            (0.02 <= self.horizon_s <= 10.0, "horizon_s must be in [0.02, 10]"),
            (0.0 < self.length_cutoff <= 4.0, "length_cutoff must be in (0, 4]"),
            (0.0 < self.angle_cutoff_rad <= math.pi, "angle_cutoff_rad must be in (0, pi]"),
            (1.0 <= self.max_travel_texels <= 256.0, "max_travel_texels must be in [1, 256]"),
            (0.05 <= self.min_travel_texels <= 4.0, "min_travel_texels must be in [0.05, 4]"),
            (self.min_travel_texels < self.max_travel_texels, "min_travel_texels must be below max_travel_texels"),
            (8 <= self.direction_bins <= 1024, "direction_bins must be in [8, 1024]"),
            (1.0 < self.length_bin_ratio <= 2.0, "length_bin_ratio must be in (1, 2]"),
            (0 <= self.apply_after_frames <= 16, "apply_after_frames must be in [0, 16]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"AnticipationSettings: {message}")

    @property
    def update_period_s(self) -> float:
        """W / r: time between two updates, s (section 6)."""
        return self.horizon_s / self.samples_per_target

    @property
    def length_bins(self) -> int:
        """Number of travel lengths in the kernel bank: min * ratio^k <= max."""
        return int(math.floor(math.log(self.max_travel_texels / self.min_travel_texels)
                              / math.log(self.length_bin_ratio) + 1e-9)) + 1
