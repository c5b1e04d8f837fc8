"""Style masks over Toric texture space: the viewpoints a map mode avoids, applied to the A-map.

Paper: occlusion-anticipation-toric-space.md, section 5.2 and Figure 10 (the masks: (a) empty,
(b) a gradient behind the targets, (c) a hard exclusion behind them, (d) behind, top and bottom
views avoided smoothly). Which mask a style asks for is `pipeline.style.MaskKind`.

Our reading: the paper writes A = 1 - (1 - A * Mask), which is A * Mask and would make excluded
places look free. We apply A = 1 - (1 - A) * Mask with Mask = 1 allowed, 0 excluded, so an empty
mask leaves A unchanged and an excluded place reads as certainly occluded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from camdirector.geometry.toric_maps.base import MapWindow
from camdirector.pipeline.style import MaskKind


@dataclass(frozen=True)
class StyleMaskSettings:
    """A style mask over Toric texture space: 1 = allowed, 0 = excluded (applied by apply_style_mask).

    "Behind the targets": the camera further back than A along the B -> A direction, i.e. theta below
    pi - 2 alpha (at theta = pi - 2 alpha the camera is level with A on the A-B axis). With one target,
    B is its gaze-room point ahead, so this is behind the character. Top and bottom views are read on
    phi, the rotation about the A-B axis from straight above it (|phi| = 90 deg is level with it).
    """

    kind: MaskKind = MaskKind.EMPTY
    soft_width_rad: float = 0.6  # width in theta of the soft "behind" gradient, rad. (0, 3]
    top_view_phi_deg: float = 30.0  # |phi| below this is a top view, deg. [0, 90]
    bottom_view_phi_deg: float = 135.0  # |phi| above this is a bottom view, deg. [90, 180]
    view_ramp_deg: float = 20.0  # width of the smooth top/bottom transitions, deg. (0, 90]

    def __post_init__(self) -> None:
        checks = [
            (isinstance(self.kind, MaskKind), "kind must be a MaskKind"),
            (0.0 < self.soft_width_rad <= 3.0, "soft_width_rad must be in (0, 3]"),
            (0.0 <= self.top_view_phi_deg <= 90.0, "top_view_phi_deg must be in [0, 90]"),
            (90.0 <= self.bottom_view_phi_deg <= 180.0, "bottom_view_phi_deg must be in [90, 180]"),
            (0.0 < self.view_ramp_deg <= 90.0, "view_ramp_deg must be in (0, 90]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"StyleMaskSettings: {message}")


def behind_theta_rad(alpha_rad: float) -> float:
    """theta below which the camera is behind A (further from B than A is, along the A-B axis).

    From geometry/toric.py's closed form: the camera's coordinate along AB from the midpoint is
    -r sin(alpha + theta), and it passes A's (-r sin alpha) at theta = pi - 2 alpha.
    """
    return math.pi - 2.0 * alpha_rad


def _smoothstep(edge0: float, edge1: float, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    t: npt.NDArray[np.float64] = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def style_mask(mask: StyleMaskSettings, window: MapWindow, alpha_rad: float) -> npt.NDArray[np.float32]:
    """(res, res) float32 in [0, 1] over the window: 1 where viewpoints are allowed."""
    if mask.kind is MaskKind.EMPTY:  # the default: no texel grid to make (a map update's aggregate makes one mask)
        return np.ones((window.resolution, window.resolution), dtype=np.float32)
    theta, phi = window.grid()
    behind = behind_theta_rad(alpha_rad)
    if mask.kind is MaskKind.HARD_BEHIND:
        return (theta >= behind).astype(np.float32)
    soft = _smoothstep(behind - mask.soft_width_rad, behind, theta)
    if mask.kind is MaskKind.SOFT_BEHIND:
        return soft.astype(np.float32)
    abs_phi = np.degrees(np.abs(np.remainder(phi + math.pi, math.tau) - math.pi))
    half = 0.5 * mask.view_ramp_deg
    top = _smoothstep(mask.top_view_phi_deg - half, mask.top_view_phi_deg + half, abs_phi)
    bottom = 1.0 - _smoothstep(mask.bottom_view_phi_deg - half, mask.bottom_view_phi_deg + half, abs_phi)
    return (soft * top * bottom).astype(np.float32)


def apply_style_mask(a_map: npt.ArrayLike, mask: npt.ArrayLike) -> npt.NDArray[np.float32]:
    """A' = 1 - (1 - A) * Mask (section 5.2, read as explained in the module docstring), float32.

    Computed in float64 so that Mask = 1 gives back A exactly and Mask = 0 gives exactly 1.
    """
    a = np.asarray(a_map, dtype=np.float64)
    return (1.0 - (1.0 - a) * np.asarray(mask, dtype=np.float64)).astype(np.float32)
