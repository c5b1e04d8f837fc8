"""PROJECTION and AMAP of the map modes, compiled (issue 43; the compiled TORIC rig's maps,
compiled_rig.py): occlusion_maps.py's `OcclusionMaps` whose S-maps and V-maps are ray cast in
camdirector._native (geometry/toric_maps/native.py: the paper's section 4.1 by rays, as the
Embree backend casts them) and whose per-sample predictions A_s are its `KernelBank`'s
(native/src/prediction.rs: section 4.2, occlusion_prediction.py's model), and whose aggregate A
and style mask are `aggregate_amap`'s (native/src/amap.rs, style_mask.rs: sections 4.2 and 5.2,
the numpy code's bits).

Both give the same bits on every x86-64 machine, where GL's maps depend on the renderer and
numpy's sums on the CPU. The schedule, the sample points and the window stay Python
(occlusion_maps.py, anticipation_map.py), so what a session draws from its generator, and when,
is the Python's. A style that names a backend (GL, EMBREE) gets it; AUTO
gets the compiled one.

Where the process says so (`hand_updates_apart`: the front's table of `serve --workers 0`), the
compiled backend's amortized update is handed to the process's maps thread (`_start`): the
scene's move, the rays and A_s with the GIL released, and the aggregate, while the session's
thread answers other frames. That thread takes an update back that the maps thread has not begun
(an idle moment, or the update's frame), so under a burst of updates both cores compute them, and
waits on its frame for one that it has. The inputs are fixed on the frame that drew the update,
so the numbers are those of computing it on the session's thread. Why: with every session in the
front (`serve --workers 0`), the rays were a fifth of the front thread's time under 16
ANTICIPATION sessions (py-spy), and that thread is what the sessions queue for; the figures are in
docs/frame_path.md. GL's contexts belong to their thread and Embree's calls hold the GIL, so those
backends' updates stay on the session's thread.
"""

from __future__ import annotations

import functools
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import numpy.typing as npt

import camdirector._native as native
from camdirector.geometry.toric_maps.base import ShadowVelocityMaps
from camdirector.geometry.toric_maps.native import NativeMapBackend, share_texels_here
from camdirector.pipeline.style import MapBackendChoice, Style
from camdirector.pipeline.toric.anticipation_map import AnticipationMap
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.occlusion_maps import OcclusionMaps, _DeferredUpdate
from camdirector.pipeline.toric.style_masks import StyleMaskSettings


@functools.lru_cache(maxsize=8)
def compiled_bank(settings: AnticipationSettings) -> Any:
    """One _native.KernelBank per process and settings (about 20 ms to build), shared by sessions."""
    return native.KernelBank(settings)


@functools.cache
def maps_thread() -> ThreadPoolExecutor:
    """The process's one maps thread (module docstring), started on its first update: one, so that
    the updates of a worker's sessions take one core between them, in the order they were drawn;
    its rays on that core alone (the process's texel threads, `map_threads`, would take the core
    of the thread answering frames)."""
    return ThreadPoolExecutor(max_workers=1, thread_name_prefix="camdirector-maps", initializer=share_texels_here, initargs=(1,))


# A forked child has no maps thread (threads do not fork): it starts its own.
os.register_at_fork(after_in_child=maps_thread.cache_clear)


class CompiledAnticipationMap(AnticipationMap):
    """AnticipationMap whose aggregate A and style mask are formed in camdirector._native
    (`aggregate_amap`, native/src/amap.rs and style_mask.rs) with the GIL released: the numpy
    code's bits, and no Python on the maps thread while it forms them."""

    aggregate = staticmethod(native.aggregate_amap)


class CompiledOcclusionMaps(OcclusionMaps):
    """OcclusionMaps with PROJECTION's rays and AMAP's predictions and aggregate compiled (module
    docstring)."""

    _amap_class = CompiledAnticipationMap

    def _anticipation_map(self, settings: AnticipationSettings, mask: StyleMaskSettings) -> AnticipationMap:
        compiled_bank(settings)  # built with the A-map, as the Python bank is, not on a frame
        return super()._anticipation_map(settings, mask)

    def _backend_of(self, style: Style) -> str:
        return {MapBackendChoice.GL: "gl", MapBackendChoice.EMBREE: "embree"}.get(style.map_backend, "native")

    def _start(self, update: _DeferredUpdate) -> None:
        if isinstance(self.backend, NativeMapBackend) and self.backend.apart:
            update.computing, update.handed = maps_thread().submit(self._compute, update, None, True), True

    def _turn_rates(
        self, before_xyzw: npt.NDArray[np.float64], now_xyzw: npt.NDArray[np.float64], dt_s: float
    ) -> npt.NDArray[np.float64]:
        """OcclusionMaps._turn_rates in camdirector._native (`turn_rates`): scipy's within rounding,
        the same bits on every machine, and no scipy call on the maps thread."""
        rates: npt.NDArray[np.float64] = native.turn_rates(before_xyzw, now_xyzw, dt_s)
        return rates

    def _predict(self, maps: ShadowVelocityMaps) -> npt.NDArray[np.float32]:
        predicted: npt.NDArray[np.float32] = compiled_bank(self.amap.settings).predict(
            maps.shadow, maps.velocity_rad_s, maps.window
        )
        return predicted
