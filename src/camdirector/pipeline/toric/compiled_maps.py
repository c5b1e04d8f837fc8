"""PROJECTION and AMAP of the map modes, compiled (issue 43; the compiled TORIC rig's maps,
compiled_rig.py): occlusion_maps.py's `OcclusionMaps` whose S-maps and V-maps are ray cast in
camdirector._native (geometry/toric_maps/native.py: the paper's section 4.1 by rays, as the
Embree backend casts them) and whose per-sample predictions A_s are its `KernelBank`'s
(native/src/prediction.rs: section 4.2, occlusion_prediction.py's model).

Both give the same bits on every x86-64 machine, where GL's maps depend on the renderer and
numpy's sums on the CPU. The schedule, the sample points, the window, the aggregate A and its
style mask stay Python (occlusion_maps.py, anticipation_map.py), so what a session draws from its
generator, and when, is the Python's. A style that names a backend (GL, EMBREE) gets it; AUTO
gets the compiled one.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import numpy.typing as npt

import camdirector._native as native
from camdirector.geometry.toric_maps.base import ShadowVelocityMaps
from camdirector.pipeline.style import MapBackendChoice, Style
from camdirector.pipeline.toric.anticipation_map import AnticipationMap
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.occlusion_maps import OcclusionMaps
from camdirector.pipeline.toric.style_masks import StyleMaskSettings


@functools.lru_cache(maxsize=8)
def compiled_bank(settings: AnticipationSettings) -> Any:
    """One _native.KernelBank per process and settings (about 20 ms to build), shared by sessions."""
    return native.KernelBank(settings)


class CompiledOcclusionMaps(OcclusionMaps):
    """OcclusionMaps with PROJECTION's rays and AMAP's predictions compiled (module docstring)."""

    def _anticipation_map(self, settings: AnticipationSettings, mask: StyleMaskSettings) -> AnticipationMap:
        compiled_bank(settings)  # built with the A-map, as the Python bank is, not on a frame
        return super()._anticipation_map(settings, mask)

    def _backend_of(self, style: Style) -> str:
        return {MapBackendChoice.GL: "gl", MapBackendChoice.EMBREE: "embree"}.get(style.map_backend, "native")

    def _predict(self, maps: ShadowVelocityMaps) -> npt.NDArray[np.float32]:
        predicted: npt.NDArray[np.float32] = compiled_bank(self.amap.settings).predict(
            maps.shadow, maps.velocity_rad_s, maps.window
        )
        return predicted
