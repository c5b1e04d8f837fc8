"""A session's occlusion anticipation map (the A-map, anticipation.py) as a picture, so that a
director sees why the camera of a map mode went where it did (the paper's Figures 5 and 10 show
it the same way): rows are theta, columns phi, over the window around the camera; white where
the targets are predicted visible, red where predicted occluded; the camera's texel is crossed in
blue. Made on demand in the worker that holds the session, never per frame.
"""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

SCALE_PX = 4  # pixels per map texel
_CROSS_HALF_PX = 6  # half the size of the camera's cross


def anticipation_png(a_map: np.ndarray, camera_texel: tuple[float, float]) -> bytes:
    """PNG of `a_map` (n, n) float, A in [0, 1], with the camera at texel (i, j) (floats; off the
    window when outside [-0.5, n - 0.5])."""
    a = np.clip(np.nan_to_num(np.asarray(a_map, dtype=np.float64)), 0.0, 1.0)
    fade = (255.0 * (1.0 - a)).astype(np.uint8)
    rgb = np.stack([np.full_like(fade, 255), fade, fade], axis=-1)  # white -> red
    rgb = rgb.repeat(SCALE_PX, axis=0).repeat(SCALE_PX, axis=1)
    size = rgb.shape[0]
    row, col = (int(round((c + 0.5) * SCALE_PX)) for c in camera_texel)
    if 0 <= row < size and 0 <= col < size:
        rgb[row, max(col - _CROSS_HALF_PX, 0) : col + _CROSS_HALF_PX + 1] = (30, 80, 220)
        rgb[max(row - _CROSS_HALF_PX, 0) : row + _CROSS_HALF_PX + 1, col] = (30, 80, 220)
    out = io.BytesIO()
    Image.fromarray(rgb, "RGB").save(out, format="PNG")
    return out.getvalue()
