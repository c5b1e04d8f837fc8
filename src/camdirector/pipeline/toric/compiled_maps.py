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
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.toric_maps.base import ShadowVelocityMaps
from camdirector.pipeline.inputs import DynamicObjects
from camdirector.pipeline.style import MapBackendChoice, Style
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.occlusion_maps import OcclusionMaps
from camdirector.pipeline.toric.target_sampling import TargetSampler


@functools.lru_cache(maxsize=8)
def compiled_bank(settings: AnticipationSettings) -> Any:
    """One _native.KernelBank per process and settings (about 20 ms to build), shared by sessions."""
    return native.KernelBank(settings)


class CompiledOcclusionMaps(OcclusionMaps):
    """OcclusionMaps with PROJECTION's rays and AMAP's predictions compiled (module docstring); its
    kernel bank is built with it (and with a new A-map), as the Python's is, not on a frame."""

    def __init__(
        self,
        static_meshes_world: list[TriMesh],
        dynamic: DynamicObjects,
        sampler: TargetSampler,
        style: Style,
        rng: np.random.Generator,
    ) -> None:
        super().__init__(static_meshes_world, dynamic, sampler, style, rng)
        compiled_bank(self.amap.settings)

    def set_style(self, style: Style) -> None:
        super().set_style(style)
        compiled_bank(self.amap.settings)

    def _backend_of(self, style: Style) -> str:
        return {MapBackendChoice.GL: "gl", MapBackendChoice.EMBREE: "embree"}.get(style.map_backend, "native")

    def _predict(self, maps: ShadowVelocityMaps) -> npt.NDArray[np.float32]:
        predicted: npt.NDArray[np.float32] = compiled_bank(self.amap.settings).predict(
            maps.shadow, maps.velocity_rad_s, maps.window
        )
        return predicted
