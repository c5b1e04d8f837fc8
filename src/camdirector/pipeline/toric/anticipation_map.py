"""The occlusion anticipation map (A-map): the 2r per-sample predictions A_s aggregated and masked,
refreshed on the paper's amortized schedule.

Paper: occlusion-anticipation-toric-space.md, section 4.2 ("Aggregating predictions for all
samples": A = 1 / (2r) times the sum of the A_s), 5.2 (the style mask applied to A) and 6
("Computational costs breakdown": refresh 2 of the 2r maps per update, one update every W / r
seconds). A_s is occlusion_prediction.py's, the mask style_masks.py's.

Per-frame use (the session's maps, occlusion_maps.py, run `schedule`, `predict` and `store` apart),
with geometry.toric_maps and pipeline/toric/target_sampling.py::

    if amap.due(time_s):
        slots = amap.next_slots()                        # one per target; all of them at first
        sampler.redraw(slots, rng)                       # a fresh random point for each refreshed map
        window = MapWindow.around(torus, theta, phi, settings.window, lattice=amap.window)
        maps = backend.compute(torus, window, sampler.points_world(transforms, slots),
                               exclude_ids=[target_ids[sampler.target_of(s)] for s in slots],
                               previous_torus=previous_torus, dt_s=dt_s)
        amap.refresh(time_s, slots, maps, torus)
    a = amap.lookup(theta_samples, phi_samples)          # the search reads A (nan outside the window)
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, SupportsInt

import numpy as np
import numpy.typing as npt

from camdirector.geometry.toric import Torus
from camdirector.geometry.toric_maps.base import MapWindow, ShadowVelocityMaps
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.occlusion_prediction import KernelBank, kernel_key, predict_occlusion
from camdirector.pipeline.toric.style_masks import StyleMaskSettings, apply_style_mask, style_mask


@dataclass(frozen=True)
class PreparedAggregate:
    """An update's aggregate made ahead of its `store` (AnticipationMap.prepare): what `store`
    would form, valid while the map is as it was (`version`)."""

    version: int  # AnticipationMap.version when it was made
    a_map: npt.NDArray[np.float32]  # (res, res), masked A
    coverage: npt.NDArray[np.floating[Any]]  # (res, res) float32


class AnticipationMap:
    """The 2r per-sample predictions A_s and their masked aggregate A, on the paper's schedule.

    Slots: slot = target * r + sample (pipeline/toric/target_sampling.py numbers its points the same way).
    Each slot keeps its A_s on the window it was computed on; the aggregate is formed on the newest
    window, older maps resampled into it (a whole-texel shift when the windows share a lattice, see
    MapWindow.around). A texel's A is the mean over the slots whose maps cover it (the paper's
    1 / (2r) sum when all do); texels no map covers read 0 with coverage 0.
    """

    # One more at every change of the maps, their windows or the mask: what a PreparedAggregate was
    # made on. A class default, so that a snapshot of a map from before it counts from 0.
    version = 0

    def __init__(
        self,
        target_count: int,
        settings: AnticipationSettings = AnticipationSettings(),
        mask: StyleMaskSettings = StyleMaskSettings(),
        bank: KernelBank | None = None,
    ) -> None:
        if target_count not in (1, 2):
            raise ValueError("AnticipationMap: target_count must be 1 or 2")
        if bank is not None and kernel_key(bank.settings) != kernel_key(settings):
            raise ValueError("AnticipationMap: the kernel bank was built for other settings")
        self.settings = settings
        self.mask = mask
        self.target_count = target_count
        self.bank = bank if bank is not None else KernelBank(settings)
        r, n = settings.samples_per_target, settings.window.resolution
        self.slot_count = target_count * r
        self._a_s = np.zeros((self.slot_count, n, n), dtype=np.float32)
        self._windows: list[MapWindow | None] = [None] * self.slot_count
        self.computed_at_s = np.full(self.slot_count, np.nan)  # when each slot's map was made, s
        self._cursor = 0  # sample index refreshed next
        self._next_due_s: float | None = None
        self._last_update_s: float | None = None
        self._alpha_rad = 0.0
        self.window: MapWindow | None = None  # the window of a_map
        self.a_map: npt.NDArray[np.float32] | None = None  # (res, res) float32, masked A
        self.coverage: npt.NDArray[np.floating[Any]] | None = None  # (res, res) float32, fraction of slots covering

    # -- schedule (section 6) ------------------------------------------------------------------

    def due(self, time_s: float) -> bool:
        """Whether an update is due at time_s: one every W / r seconds, the first at once."""
        if self._next_due_s is None or self._last_update_s is None or time_s < self._last_update_s:
            return True
        return time_s >= self._next_due_s - 1e-9

    @property
    def filled(self) -> bool:
        """Whether every slot has a map (the next update is an amortized one, not a refill)."""
        return all(w is not None for w in self._windows)

    def next_slots(self) -> list[int]:
        """Slots to refresh at the next update: every slot without a map; else one per target."""
        empty = [slot for slot, w in enumerate(self._windows) if w is None]
        if empty:
            return empty
        r = self.settings.samples_per_target
        return [target * r + self._cursor for target in range(self.target_count)]

    def invalidate(self) -> None:
        """Forget every map (after a cut: the old window is elsewhere); the next update refills all."""
        self._windows = [None] * self.slot_count
        self.computed_at_s[:] = np.nan
        self._next_due_s = None
        self.version += 1

    def set_mask(self, mask: StyleMaskSettings) -> None:
        """Takes effect at once on a_map (the style can change live)."""
        self.mask = mask
        self.version += 1
        if self.window is not None:
            self.a_map, self.coverage = self.aggregate(list(self._a_s), self._windows, self.window, self.mask, self._alpha_rad)

    # -- updates -------------------------------------------------------------------------------

    def refresh(self, time_s: float, slots: Iterable[SupportsInt], maps: ShadowVelocityMaps, torus: Torus) -> None:
        """Store the predictions of freshly computed maps (maps.count == len(slots)) and re-aggregate:
        `schedule`, `predict` and `store` in one (the session's maps run them apart, occlusion_maps.py).

        maps.window becomes the aggregate's window. torus: the current one (its alpha places the
        style mask's "behind" boundary).
        """
        refreshed = [int(s) for s in slots]
        if len(refreshed) != maps.count or not all(0 <= s < self.slot_count for s in refreshed):
            raise ValueError("AnticipationMap.refresh: one valid slot per map")
        self.schedule(time_s, refreshed)
        self.store(time_s, refreshed, self.predict(maps), maps.window, torus)

    def schedule(self, time_s: float, slots: list[int]) -> None:
        """The update at time_s of `slots` is under way: the round robin moves on (when they are
        its slots) and the next update is due one period later (one period after time_s when
        behind schedule or time went back)."""
        r = self.settings.samples_per_target
        round_robin = sorted(target * r + self._cursor for target in range(self.target_count))
        if sorted(slots) == round_robin:
            self._cursor = (self._cursor + 1) % r
        period = self.settings.update_period_s
        next_due_s = self._next_due_s
        if (
            next_due_s is None or self._last_update_s is None or time_s < self._last_update_s or time_s >= next_due_s + period
        ):  # behind schedule, or time went back
            self._next_due_s = time_s + period
        else:
            self._next_due_s = next_due_s + period
        self._last_update_s = time_s

    def predict(self, maps: ShadowVelocityMaps) -> npt.NDArray[np.float32]:
        """A_s (k, res, res) float32 of k freshly computed maps; changes nothing here."""
        if maps.window.resolution != self.settings.window.resolution:
            raise ValueError("AnticipationMap: maps have another resolution than the settings")
        return predict_occlusion(maps.shadow, maps.velocity_rad_s, maps.window, self.settings, self.bank)

    def store(
        self,
        time_s: float,
        slots: list[int],
        predicted: npt.NDArray[np.float32],
        window: MapWindow,
        torus: Torus,
        prepared: PreparedAggregate | None = None,
    ) -> None:
        """Keeps the predictions (k, res, res) of `slots`, made at time_s on `window`, which becomes
        the aggregate's, and re-aggregates; or takes `prepared`, this update's aggregate made by
        `prepare` while the map was as it is now (the same numbers)."""
        if prepared is None or prepared.version != self.version:
            prepared = self.prepare(slots, predicted, window, torus)
        for slot, a_s in zip(slots, predicted):
            self._a_s[slot] = a_s
            self._windows[slot] = window
            self.computed_at_s[slot] = time_s
        self.window = window
        self._alpha_rad = torus.alpha
        self.a_map, self.coverage = prepared.a_map, prepared.coverage
        self.version += 1

    def prepare(
        self, slots: Sequence[int], predicted: npt.NDArray[np.float32], window: MapWindow, torus: Torus
    ) -> PreparedAggregate:
        """The aggregate `store` would form with these predictions stored, the map left as it is:
        made ahead, in idle time (occlusion_maps.py)."""
        windows, a_s = list(self._windows), list(self._a_s)
        for slot, values in zip(slots, predicted):
            windows[slot], a_s[slot] = window, np.asarray(values, dtype=np.float32)  # as stored: float32
        a_map, coverage = self.aggregate(a_s, windows, window, self.mask, torus.alpha)
        return PreparedAggregate(self.version, a_map, coverage)

    @staticmethod
    def aggregate(
        a_s: list[npt.NDArray[np.float32]],
        windows: list[MapWindow | None],
        newest: MapWindow,
        mask: StyleMaskSettings,
        alpha_rad: float,
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.floating[Any]]]:
        """The aggregate: (a_map, coverage), each (res, res) float32 on `newest`, of the slots' A_s
        (res, res) float32 on their `windows` (None: a slot without a map, its A_s not read),
        masked by `mask` for a torus of `alpha_rad`. A class's choice: CompiledAnticipationMap's
        is camdirector._native's twin, the same bits."""
        n = newest.resolution
        total = np.zeros((n, n), dtype=np.float32)
        count = np.zeros((n, n), dtype=np.float32)
        for slot, window in enumerate(windows):
            if window is None:
                continue
            if window == newest:
                total += a_s[slot]
                count += 1.0
            else:
                values, covered = window.resample(a_s[slot], newest)
                total += values
                count += covered
        a = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
        return apply_style_mask(a, style_mask(mask, newest, alpha_rad)), count / len(windows)

    # -- reading -------------------------------------------------------------------------------

    def lookup(self, theta_rad: npt.ArrayLike, phi_rad: npt.ArrayLike, outside: float = np.nan) -> npt.NDArray[np.float64]:
        """A at Toric angles (broadcast arrays, radians), bilinear; ``outside`` off the window or before any update."""
        theta = np.asarray(theta_rad, dtype=np.float64)
        phi = np.asarray(phi_rad, dtype=np.float64)
        shape = np.broadcast_shapes(theta.shape, phi.shape)
        if self.a_map is None or self.window is None:  # set together, by the first update
            return np.full(shape, outside)
        i, j = self.window.texel_coords(theta, phi)
        i, j = np.broadcast_arrays(i, j)
        n = self.window.resolution
        ok = (i >= -0.5) & (i <= n - 0.5) & (j >= -0.5) & (j <= n - 0.5)
        ic = np.clip(i, 0.0, n - 1.0)
        jc = np.clip(j, 0.0, n - 1.0)
        i0 = np.minimum(np.floor(ic).astype(np.intp), n - 1)
        j0 = np.minimum(np.floor(jc).astype(np.intp), n - 1)
        i1, j1 = np.minimum(i0 + 1, n - 1), np.minimum(j0 + 1, n - 1)
        wi, wj = ic - i0, jc - j0
        a = self.a_map
        value = (1 - wi) * ((1 - wj) * a[i0, j0] + wj * a[i0, j1]) + wi * ((1 - wj) * a[i1, j0] + wj * a[i1, j1])
        return np.where(ok, value, outside)
