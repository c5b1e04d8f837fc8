"""The per-sample occlusion prediction A_s: where a target sample's occluders are predicted to be
within the horizon W, from its S-map and V-map (the paper's occlusion prediction model).

Paper: occlusion-anticipation-toric-space.md, section 4.2 (the uncertainty function U = U_l * U_a,
eq. 1, and A_s as a pixel-wise double sum over S_s and V_s). The A-map aggregates the 2r A_s
(anticipation_map.py); the parameters are anticipation_settings.py's.

Our reading of the parts the paper leaves open (each is a documented setting):

- Units. The paper compares v1 = V(neighbour), a velocity, with v2 = (theta', phi') - (theta, phi), an
  offset. We take v1 as the occluder's predicted travel over the time horizon W, in texels:
  D = V * W / texel size, and measure the length difference relative to it:
  delta = (|D| - |v2|) / |D|. delta_W = 0.6 then means "arrives between 0.4 W and 1.6 W", whatever the
  map's resolution or window size (an absolute delta_W = 0.6 would be 0.6 texel, or 0.6 rad, both
  unworkable). gamma_W = 0.5 rad is the angular cutoff as written.
- W. The paper refreshes every W / r seconds and gives 0.1 s with r = 5, so W = 0.5 s.
- Normalisation. A literal double sum of U * S grows with the kernel's area; the paper's A is a
  probability in [0, 1]. Each occluded texel's kernel is normalised to unit sum (a blur spreads the
  texel's occlusion over where the occluder is predicted to be) and A_s is clipped at 1 where
  predictions converge.
- An occluder whose travel over W is under half a texel stays in its texel (A_s = S there): a
  static scene gives A = the mean of the S-maps, which is the paper's variant without anticipation
  (method "W" of its Figure 12); `anticipate=False` selects it everywhere.
- Travel is clamped at max_travel_texels: faster relative motion is predicted over a
  proportionally shorter horizon (the kernel must stay inside a bounded neighbourhood).

Speed: the travel of each occluded texel is snapped to a bin (direction_bins directions, lengths in
a geometric progression of ratio length_bin_ratio); KernelBank holds each bin's normalised kernel as
a row of a per-length table, built on first use; the prediction gathers the rows of the occluded
texels, one travel length at a time, and adds them with np.bincount (its cost against a plain
numpy blur: docs/toric.md). `anticipation_reference` computes the same snapped model texel by
texel and is the test oracle; the snapping (at most 2.8 deg and 5 % of the travel with the
defaults) is part of the model, so the two agree to float rounding.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from camdirector.geometry.toric_maps.base import MapWindow
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings

# A kernel table's (di, dj, weight): texel offsets int32 and their weights float64, same shape.
KernelTable = tuple[npt.NDArray[np.int32], npt.NDArray[np.int32], npt.NDArray[np.float64]]

# -- the uncertainty function (section 4.2, eq. 1) ----------------------------------------------


def length_falloff(delta: npt.ArrayLike, cutoff: float) -> npt.NDArray[np.float64]:
    """U_l(delta) = max(1 - |delta| / delta_W, 0)."""
    return np.maximum(1.0 - np.abs(np.asarray(delta, dtype=np.float64)) / cutoff, 0.0)


def angle_falloff(gamma_rad: npt.ArrayLike, cutoff_rad: float) -> npt.NDArray[np.float64]:
    """U_a(gamma) = max(1 - |gamma| / gamma_W, 0)."""
    return np.maximum(1.0 - np.abs(np.asarray(gamma_rad, dtype=np.float64)) / cutoff_rad, 0.0)


def uncertainty(
    travel: npt.ArrayLike, offset: npt.ArrayLike, length_cutoff: float, angle_cutoff_rad: float
) -> npt.NDArray[np.float64]:
    """U(v1, v2) = U_l(delta) * U_a(gamma) for travel v1 (..., 2) and offset v2 (..., 2), in texels.

    v1: the occluder's predicted travel over W from the neighbour texel; v2: the offset from that
    neighbour to the texel being predicted. delta = (|v1| - |v2|) / |v1| (see the module docstring),
    gamma = the angle between v1 and v2 (0 for a zero offset). A zero travel is a still occluder:
    U = 1 at offset 0 and 0 elsewhere.
    """
    v1 = np.asarray(travel, dtype=np.float64)
    v2 = np.asarray(offset, dtype=np.float64)
    length = np.hypot(v1[..., 0], v1[..., 1])
    reach = np.hypot(v2[..., 0], v2[..., 1])
    cross = v1[..., 0] * v2[..., 1] - v1[..., 1] * v2[..., 0]
    dot = v1[..., 0] * v2[..., 0] + v1[..., 1] * v2[..., 1]
    gamma = np.where(reach > 0.0, np.arctan2(np.abs(cross), dot), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(length > 0.0, (length - reach) / length, 0.0)
    moving = length_falloff(delta, length_cutoff) * angle_falloff(gamma, angle_cutoff_rad)
    still = (reach == 0.0).astype(np.float64)
    return np.where(length > 0.0, moving, still)


def travel_texels(velocity_rad_s: npt.ArrayLike, window: MapWindow, horizon_s: float) -> npt.NDArray[np.float64]:
    """Predicted travel over the horizon (..., 2) texels from Toric rates (..., 2) rad/s."""
    v = np.asarray(velocity_rad_s, dtype=np.float64)
    return v * (horizon_s / np.array([window.theta_step_rad, window.phi_step_rad]))


def snap_travel(travel: npt.ArrayLike, settings: AnticipationSettings) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Kernel-bank bin (...,) int and the bin's travel (..., 2) texels for travels (..., 2) texels.

    Bin 0: a still occluder (travel under min_travel_texels). Others: 1 + length * direction_bins +
    direction, the travel clamped to max_travel_texels, its direction rounded to one of
    direction_bins, its length to min_travel * ratio^k. The snapped travel is part of the model:
    the reference and the kernel bank both use it.
    """
    t = np.asarray(travel, dtype=np.float64)
    length = np.hypot(t[..., 0], t[..., 1])
    n_dir, n_len = settings.direction_bins, settings.length_bins
    clamped = np.minimum(length, settings.max_travel_texels)
    with np.errstate(divide="ignore"):
        k_len = np.rint(np.log(np.maximum(clamped, 1e-300) / settings.min_travel_texels) / math.log(settings.length_bin_ratio))
    k_len = np.clip(k_len, 0, n_len - 1).astype(np.int64)
    k_dir = np.mod(np.rint(np.arctan2(t[..., 1], t[..., 0]) / math.tau * n_dir), n_dir).astype(np.int64)
    still = length < settings.min_travel_texels
    bins = np.where(still, 0, 1 + k_len * n_dir + k_dir)
    snapped_length = np.where(still, 0.0, settings.min_travel_texels * settings.length_bin_ratio**k_len)
    angle = k_dir * (math.tau / n_dir)
    snapped = np.stack([snapped_length * np.cos(angle), snapped_length * np.sin(angle)], axis=-1)
    return bins, snapped


def kernel_key(settings: AnticipationSettings) -> tuple[float, float, float, float, int, float]:
    """The settings a kernel bank depends on (not the window: kernels are in texels)."""
    return (
        settings.length_cutoff,
        settings.angle_cutoff_rad,
        settings.max_travel_texels,
        settings.min_travel_texels,
        settings.direction_bins,
        settings.length_bin_ratio,
    )


def _kernel_radius(length_texels: float, settings: AnticipationSettings) -> int:
    """Half-side of the square holding a kernel: U_l is 0 beyond (1 + delta_W) |v1|."""
    return int(math.ceil((1.0 + settings.length_cutoff) * length_texels))


# -- reference (the oracle) ---------------------------------------------------------------------


def anticipation_reference(
    shadow: npt.ArrayLike,
    velocity_rad_s: npt.ArrayLike,
    window: MapWindow,
    settings: AnticipationSettings = AnticipationSettings(),
) -> npt.NDArray[np.float64]:
    """A_s of one sample: (res, res) float64 from its S-map (res, res) and V-map (res, res, 2) rad/s.

    Plain and slow, the test oracle of predict_occlusion. For every occluded texel n, the kernel
    U(D_n, d) over the neighbourhood d, normalised to unit sum, is added at n + d (section 4.2: "a
    pixel-wise level, through a double sum over pixels of S"); contributions leaving the window are
    lost; the result is clipped to [0, 1].
    """
    s = np.asarray(shadow, dtype=np.float64)
    n = s.shape[0]
    if not settings.anticipate:
        return np.clip(s, 0.0, 1.0)
    out = np.zeros((n, n))
    travel = travel_texels(velocity_rad_s, window, settings.horizon_s)
    for i, j in zip(*np.nonzero(s > 0.0)):
        bin_id, snapped = snap_travel(travel[i, j], settings)
        if bin_id == 0:
            out[i, j] += s[i, j]
            continue
        radius = _kernel_radius(float(np.hypot(*snapped)), settings)
        di, dj = np.meshgrid(np.arange(-radius, radius + 1), np.arange(-radius, radius + 1), indexing="ij")
        weights = uncertainty(snapped, np.stack([di, dj], axis=-1), settings.length_cutoff, settings.angle_cutoff_rad)
        if weights.sum() <= 0.0:  # no texel centre in the wedge: the occluder stays
            out[i, j] += s[i, j]
            continue
        weights /= weights.sum()
        for a, b, w in zip(di.ravel(), dj.ravel(), weights.ravel()):
            if w > 0.0 and 0 <= i + a < n and 0 <= j + b < n:
                out[i + a, j + b] += s[i, j] * w
    return np.clip(out, 0.0, 1.0)


# -- fast: the kernel bank ----------------------------------------------------------------------


@functools.lru_cache(maxsize=8)
def shared_bank(settings: AnticipationSettings) -> KernelBank:
    """One warmed bank per process and settings (warming: docs/toric.md), shared by sessions."""
    bank = KernelBank(settings)
    bank.warm()
    return bank


class KernelBank:
    """Normalised kernels per travel bin (snap_travel), built on first use.

    One table per travel length: (direction_bins, K) offsets and weights, each direction's kernel
    padded with zero weights to the longest one of that length, so a group of texels with the same
    travel length gathers its kernels as whole rows (no per-entry bookkeeping). Kernels are in texel
    units: one bank serves every window and resolution with the same settings. warm() builds all
    tables at once (its cost: docs/toric.md).
    """

    def __init__(self, settings: AnticipationSettings = AnticipationSettings()) -> None:
        self.settings = settings
        self._tables: dict[int, KernelTable] = {}
        self._flat: dict[tuple[int, int], npt.NDArray[np.intp]] = {}

    def __reduce__(self) -> tuple[Callable[[AnticipationSettings], KernelBank], tuple[AnticipationSettings]]:
        """Pickled as its settings (2 MB of tables with the defaults, a function of them alone)."""
        return shared_bank, (self.settings,)

    @property
    def max_radius(self) -> int:
        """Largest kernel half-side of any bin, texels."""
        st = self.settings
        return _kernel_radius(st.min_travel_texels * st.length_bin_ratio ** (st.length_bins - 1), st)

    def table(self, length_bin: int) -> KernelTable:
        """(di, dj, weight), each (direction_bins, K): the kernels of one travel length."""
        cached = self._tables.get(length_bin)
        if cached is not None:
            return cached
        st = self.settings
        length = st.min_travel_texels * st.length_bin_ratio**length_bin
        radius = _kernel_radius(length, st)
        di, dj = np.meshgrid(np.arange(-radius, radius + 1), np.arange(-radius, radius + 1), indexing="ij")
        offsets = np.stack([di.ravel(), dj.ravel()], axis=-1)  # (g, 2)
        angle = np.arange(st.direction_bins) * (math.tau / st.direction_bins)
        travel = length * np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (n_dir, 2)
        weights = uncertainty(travel[:, None, :], offsets[None, :, :], st.length_cutoff, st.angle_cutoff_rad)
        width = max(int((weights > 0.0).sum(axis=1).max()), 1)
        t_di = np.zeros((st.direction_bins, width), dtype=np.int32)
        t_dj = np.zeros((st.direction_bins, width), dtype=np.int32)
        t_w = np.zeros((st.direction_bins, width))
        for d, row in enumerate(weights):
            keep = np.flatnonzero(row > 0.0)
            if len(keep) == 0:  # no texel centre in the wedge: the occluder stays
                t_w[d, 0] = 1.0
                continue
            t_di[d, : len(keep)], t_dj[d, : len(keep)] = offsets[keep, 0], offsets[keep, 1]
            t_w[d, : len(keep)] = row[keep] / row[keep].sum()
        self._tables[length_bin] = (t_di, t_dj, t_w)
        return self._tables[length_bin]

    def kernel(self, bin_id: int) -> KernelTable:
        """(di, dj, weight) of one bin's kernel, its non-zero entries only."""
        if bin_id == 0:
            return np.zeros(1, np.int32), np.zeros(1, np.int32), np.ones(1)
        length_bin, direction = divmod(int(bin_id) - 1, self.settings.direction_bins)
        di, dj, w = (a[direction] for a in self.table(length_bin))
        keep = w > 0.0
        return di[keep], dj[keep], w[keep]

    def warm(self) -> None:
        """Build every table now (a server worker can pay this once at start)."""
        for length_bin in range(self.settings.length_bins):
            self.table(length_bin)

    def _flat_offsets(self, length_bin: int, width: int) -> npt.NDArray[np.intp]:
        key = (length_bin, width)
        flat = self._flat.get(key)
        if flat is None:
            di, dj, _ = self.table(length_bin)
            flat = di.astype(np.intp) * width + dj
            self._flat[key] = flat
        return flat

    def scatter(
        self, bins: npt.ArrayLike, base: npt.NDArray[np.intp], values: npt.NDArray[np.float64] | None, width: int, size: int
    ) -> npt.NDArray[np.float64]:
        """Sum of every source's kernel placed at its flat position: (size,) float64.

        bins (m,): each source's bin; base (m,) intp: its flat index in a buffer of rows ``width``
        long, with room for max_radius on every side; values (m,): its weight, None for all 1.
        Sources are grouped by travel length; each group gathers its kernel rows and adds them with
        one np.bincount.
        """
        bins = np.asarray(bins, dtype=np.intp)
        out = np.zeros(size)
        still = bins == 0
        if still.any():
            out += np.bincount(base[still], weights=None if values is None else values[still], minlength=size)
        moving = np.flatnonzero(~still)
        if len(moving) == 0:
            return out
        length_bin, direction = np.divmod(bins[moving] - 1, self.settings.direction_bins)
        order = np.argsort(length_bin, kind="stable")
        sorted_bins = length_bin[order]
        starts = np.flatnonzero(np.r_[True, sorted_bins[1:] != sorted_bins[:-1]])
        for first, last in zip(starts, np.r_[starts[1:], len(order)]):
            group = order[first:last]
            sources = moving[group]
            rows = direction[group]
            target = self._flat_offsets(int(sorted_bins[first]), width)[rows]
            target += base[sources, None]
            weight = self.table(int(sorted_bins[first]))[2][rows]
            if values is not None:
                weight = weight * values[sources, None]
            out += np.bincount(target.ravel(), weights=weight.ravel(), minlength=size)
        return out


def predict_occlusion(
    shadow: npt.ArrayLike,
    velocity_rad_s: npt.ArrayLike,
    window: MapWindow,
    settings: AnticipationSettings = AnticipationSettings(),
    bank: KernelBank | None = None,
) -> npt.NDArray[np.float32]:
    """A_s for k samples at once: (k, res, res) float32 from S (k, res, res) and V (k, res, res, 2) rad/s.

    Same model as anticipation_reference (equal to it within float rounding); 2-D inputs are one sample.
    Kernels are scattered into a buffer padded by the largest kernel radius, so no bounds test is
    needed per entry; what lands in the padding (outside the window) is dropped.
    """
    s = np.asarray(shadow, dtype=np.float32)
    single = s.ndim == 2
    if single:
        s = s[None]
        velocity_rad_s = np.asarray(velocity_rad_s)[None]
    k, n, _ = s.shape
    if not settings.anticipate:
        out = np.clip(s, 0.0, 1.0)
        return out[0] if single else out
    if bank is None:
        bank = KernelBank(settings)
    elif kernel_key(bank.settings) != kernel_key(settings):
        raise ValueError("predict_occlusion: the kernel bank was built for other settings")
    flat_s = s.reshape(-1)
    occluded = np.flatnonzero(flat_s > 0.0)
    travel = travel_texels(np.asarray(velocity_rad_s).reshape(-1, 2)[occluded], window, settings.horizon_s)
    bins, _ = snap_travel(travel, settings)
    pad = bank.max_radius
    width = n + 2 * pad
    sample, rest = np.divmod(occluded, n * n)
    row, col = np.divmod(rest, n)
    base = (sample * width + row + pad) * width + col + pad
    occluded_s = flat_s[occluded]
    values = None if np.all(occluded_s == 1.0) else occluded_s.astype(np.float64)
    padded = bank.scatter(bins, base, values, width, k * width * width).reshape(k, width, width)
    predicted = np.minimum(padded[:, pad : pad + n, pad : pad + n], 1.0).astype(np.float32)
    return predicted[0] if single else predicted
