"""Occlusion anticipation map (A-map): the uncertainty blur, style masks and the amortized schedule.

Paper: occlusion-anticipation-toric-space.md, section 4.2 (uncertainty function U = U_l * U_a, the
per-sample prediction A_s as a pixel-wise double sum over S_s and V_s, the aggregation over the 2r
samples), 5.2 (style masks), 6 ("Computational costs breakdown": refresh 2 of the 2r maps per update,
one update every W / r seconds) and Table 2 (r = 5, delta_W = 0.6, gamma_W = 0.5).

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
- Style masks: the paper writes A = 1 - (1 - A * Mask), which is A * Mask and would make excluded
  places look free. We apply A = 1 - (1 - A) * Mask with Mask = 1 allowed, 0 excluded, so an empty
  mask leaves A unchanged and an excluded place reads as certainly occluded.

Speed: the travel of each occluded texel is snapped to a bin (direction_bins directions, lengths in
a geometric progression of ratio length_bin_ratio); KernelBank holds each bin's normalised kernel as
a row of a per-length table, built on first use; the prediction gathers the rows of the occluded
texels, one travel length at a time, and adds them with np.bincount (about 0.5 ms for two 64 x 64
maps with 12 % occluded texels travelling about 12 texels, against about 6 ms for a plain numpy
17 x 17 blur, DESIGN.md). `anticipation_reference` computes the same snapped model texel by texel
and is the test oracle; the snapping (at most 2.8 deg and 5 % of the travel with the defaults)
is part of the model, so the two agree to float rounding.

Per-frame use (the session rig), with geometry.toric_maps and server.target_sampling::

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

import enum
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from camdirector.geometry.toric import Torus
from camdirector.geometry.toric_maps.base import MapWindow, ShadowVelocityMaps, WindowSettings


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
    # 2 and 3 cost the demo's ANTICIPATION visibility (mean 0.92 and 0.98 against 0.996 at 0 and 1). [0, 16]
    apply_after_frames: int = 1

    def __post_init__(self):
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


# -- the uncertainty function (section 4.2, eq. 1) ----------------------------------------------

def length_falloff(delta, cutoff: float) -> np.ndarray:
    """U_l(delta) = max(1 - |delta| / delta_W, 0)."""
    return np.maximum(1.0 - np.abs(np.asarray(delta, dtype=np.float64)) / cutoff, 0.0)


def angle_falloff(gamma_rad, cutoff_rad: float) -> np.ndarray:
    """U_a(gamma) = max(1 - |gamma| / gamma_W, 0)."""
    return np.maximum(1.0 - np.abs(np.asarray(gamma_rad, dtype=np.float64)) / cutoff_rad, 0.0)


def uncertainty(travel, offset, length_cutoff: float, angle_cutoff_rad: float) -> np.ndarray:
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


def travel_texels(velocity_rad_s, window: MapWindow, horizon_s: float) -> np.ndarray:
    """Predicted travel over the horizon (..., 2) texels from Toric rates (..., 2) rad/s."""
    v = np.asarray(velocity_rad_s, dtype=np.float64)
    return v * (horizon_s / np.array([window.theta_step_rad, window.phi_step_rad]))


def snap_travel(travel, settings: AnticipationSettings) -> tuple[np.ndarray, np.ndarray]:
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
        k_len = np.rint(np.log(np.maximum(clamped, 1e-300) / settings.min_travel_texels)
                        / math.log(settings.length_bin_ratio))
    k_len = np.clip(k_len, 0, n_len - 1).astype(np.int64)
    k_dir = np.mod(np.rint(np.arctan2(t[..., 1], t[..., 0]) / math.tau * n_dir), n_dir).astype(np.int64)
    still = length < settings.min_travel_texels
    bins = np.where(still, 0, 1 + k_len * n_dir + k_dir)
    snapped_length = np.where(still, 0.0, settings.min_travel_texels * settings.length_bin_ratio ** k_len)
    angle = k_dir * (math.tau / n_dir)
    snapped = np.stack([snapped_length * np.cos(angle), snapped_length * np.sin(angle)], axis=-1)
    return bins, snapped


def _kernel_key(settings: AnticipationSettings) -> tuple:
    """The settings a kernel bank depends on (not the window: kernels are in texels)."""
    return (settings.length_cutoff, settings.angle_cutoff_rad, settings.max_travel_texels,
            settings.min_travel_texels, settings.direction_bins, settings.length_bin_ratio)


def _kernel_radius(length_texels: float, settings: AnticipationSettings) -> int:
    """Half-side of the square holding a kernel: U_l is 0 beyond (1 + delta_W) |v1|."""
    return int(math.ceil((1.0 + settings.length_cutoff) * length_texels))


# -- reference (the oracle) ---------------------------------------------------------------------

def anticipation_reference(shadow: np.ndarray, velocity_rad_s: np.ndarray, window: MapWindow,
                           settings: AnticipationSettings = AnticipationSettings()) -> np.ndarray:
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
    """One warmed bank per process and settings (warming takes about 0.07 s), shared by sessions."""
    bank = KernelBank(settings)
    bank.warm()
    return bank


class KernelBank:
    """Normalised kernels per travel bin (snap_travel), built on first use.

    One table per travel length: (direction_bins, K) offsets and weights, each direction's kernel
    padded with zero weights to the longest one of that length, so a group of texels with the same
    travel length gathers its kernels as whole rows (no per-entry bookkeeping). Kernels are in texel
    units: one bank serves every window and resolution with the same settings. warm() builds all
    tables at once (about 0.1 s with the defaults).
    """

    def __init__(self, settings: AnticipationSettings = AnticipationSettings()):
        self.settings = settings
        self._tables: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._flat: dict[tuple[int, int], np.ndarray] = {}

    def __reduce__(self):
        """Pickled as its settings (2 MB of tables with the defaults, a function of them alone)."""
        return shared_bank, (self.settings,)

    @property
    def max_radius(self) -> int:
        """Largest kernel half-side of any bin, texels."""
        st = self.settings
        return _kernel_radius(st.min_travel_texels * st.length_bin_ratio ** (st.length_bins - 1), st)

    def table(self, length_bin: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(di, dj, weight), each (direction_bins, K): the kernels of one travel length."""
        cached = self._tables.get(length_bin)
        if cached is not None:
            return cached
        st = self.settings
        length = st.min_travel_texels * st.length_bin_ratio ** length_bin
        radius = _kernel_radius(length, st)
        di, dj = np.meshgrid(np.arange(-radius, radius + 1), np.arange(-radius, radius + 1), indexing="ij")
        offsets = np.stack([di.ravel(), dj.ravel()], axis=-1)                       # (g, 2)
        angle = np.arange(st.direction_bins) * (math.tau / st.direction_bins)
        travel = length * np.stack([np.cos(angle), np.sin(angle)], axis=-1)        # (n_dir, 2)
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
            t_di[d, :len(keep)], t_dj[d, :len(keep)] = offsets[keep, 0], offsets[keep, 1]
            t_w[d, :len(keep)] = row[keep] / row[keep].sum()
        self._tables[length_bin] = (t_di, t_dj, t_w)
        return self._tables[length_bin]

    def kernel(self, bin_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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

    def _flat_offsets(self, length_bin: int, width: int) -> np.ndarray:
        key = (length_bin, width)
        flat = self._flat.get(key)
        if flat is None:
            di, dj, _ = self.table(length_bin)
            flat = di.astype(np.intp) * width + dj
            self._flat[key] = flat
        return flat

    def scatter(self, bins: np.ndarray, base: np.ndarray, values: np.ndarray | None, width: int,
                size: int) -> np.ndarray:
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


def predict_occlusion(shadow: np.ndarray, velocity_rad_s: np.ndarray, window: MapWindow,
                      settings: AnticipationSettings = AnticipationSettings(),
                      bank: KernelBank | None = None) -> np.ndarray:
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
    elif _kernel_key(bank.settings) != _kernel_key(settings):
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
    values = flat_s[occluded]
    values = None if np.all(values == 1.0) else values.astype(np.float64)
    out = bank.scatter(bins, base, values, width, k * width * width).reshape(k, width, width)
    out = np.minimum(out[:, pad:pad + n, pad:pad + n], 1.0).astype(np.float32)
    return out[0] if single else out


# -- style masks (section 5.2) ------------------------------------------------------------------

class MaskKind(enum.Enum):
    """The paper's Figure 10 masks."""

    EMPTY = "empty"                                  # (a) no preference
    SOFT_BEHIND = "soft_behind"                      # (b) flexible exclusion behind the targets, a gradient
    HARD_BEHIND = "hard_behind"                      # (c) hard exclusion behind the targets
    AVOID_BEHIND_TOP_BOTTOM = "avoid_behind_top_bottom"  # (d) smooth: behind, top views and bottom views


@dataclass(frozen=True)
class StyleMaskSettings:
    """A style mask over Toric texture space: 1 = allowed, 0 = excluded (applied by apply_style_mask).

    "Behind the targets": the camera further back than A along the B -> A direction, i.e. theta below
    pi - 2 alpha (at theta = pi - 2 alpha the camera is level with A on the A-B axis). With one target,
    B is its gaze-room point ahead, so this is behind the character. Top and bottom views are read on
    phi, the rotation about the A-B axis from straight above it (|phi| = 90 deg is level with it).
    """

    kind: MaskKind = MaskKind.EMPTY
    soft_width_rad: float = 0.6          # width in theta of the soft "behind" gradient, rad. (0, 3]
    top_view_phi_deg: float = 30.0       # |phi| below this is a top view, deg. [0, 90]
    bottom_view_phi_deg: float = 135.0   # |phi| above this is a bottom view, deg. [90, 180]
    view_ramp_deg: float = 20.0          # width of the smooth top/bottom transitions, deg. (0, 90]

    def __post_init__(self):
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


def _smoothstep(edge0: float, edge1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def style_mask(mask: StyleMaskSettings, window: MapWindow, alpha_rad: float) -> np.ndarray:
    """(res, res) float32 in [0, 1] over the window: 1 where viewpoints are allowed."""
    theta, phi = window.grid()
    if mask.kind is MaskKind.EMPTY:
        return np.ones(theta.shape, dtype=np.float32)
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


def apply_style_mask(a_map: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A' = 1 - (1 - A) * Mask (section 5.2, read as explained in the module docstring), float32.

    Computed in float64 so that Mask = 1 gives back A exactly and Mask = 0 gives exactly 1.
    """
    a = np.asarray(a_map, dtype=np.float64)
    return (1.0 - (1.0 - a) * np.asarray(mask, dtype=np.float64)).astype(np.float32)


# -- the amortized A-map ------------------------------------------------------------------------

class AnticipationMap:
    """The 2r per-sample predictions A_s and their masked aggregate A, on the paper's schedule.

    Slots: slot = target * r + sample (pipeline/toric/target_sampling.py numbers its points the same way).
    Each slot keeps its A_s on the window it was computed on; the aggregate is formed on the newest
    window, older maps resampled into it (a whole-texel shift when the windows share a lattice, see
    MapWindow.around). A texel's A is the mean over the slots whose maps cover it (the paper's
    1 / (2r) sum when all do); texels no map covers read 0 with coverage 0.
    """

    def __init__(self, target_count: int, settings: AnticipationSettings = AnticipationSettings(),
                 mask: StyleMaskSettings = StyleMaskSettings(), bank: KernelBank | None = None):
        if target_count not in (1, 2):
            raise ValueError("AnticipationMap: target_count must be 1 or 2")
        if bank is not None and _kernel_key(bank.settings) != _kernel_key(settings):
            raise ValueError("AnticipationMap: the kernel bank was built for other settings")
        self.settings = settings
        self.mask = mask
        self.target_count = target_count
        self.bank = bank if bank is not None else KernelBank(settings)
        r, n = settings.samples_per_target, settings.window.resolution
        self.slot_count = target_count * r
        self._a_s = np.zeros((self.slot_count, n, n), dtype=np.float32)
        self._windows: list[MapWindow | None] = [None] * self.slot_count
        self.computed_at_s = np.full(self.slot_count, np.nan)    # when each slot's map was made, s
        self._cursor = 0                                         # sample index refreshed next
        self._next_due_s: float | None = None
        self._last_update_s: float | None = None
        self._alpha_rad = 0.0
        self.window: MapWindow | None = None                     # the window of a_map
        self.a_map: np.ndarray | None = None                     # (res, res) float32, masked A
        self.coverage: np.ndarray | None = None                  # (res, res) float32, fraction of slots covering

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

    def set_mask(self, mask: StyleMaskSettings) -> None:
        """Takes effect at once on a_map (the style can change live)."""
        self.mask = mask
        if self.window is not None:
            self._aggregate()

    # -- updates -------------------------------------------------------------------------------

    def refresh(self, time_s: float, slots, maps: ShadowVelocityMaps, torus: Torus) -> None:
        """Store the predictions of freshly computed maps (maps.count == len(slots)) and re-aggregate:
        `schedule`, `predict` and `store` in one (the session's maps run them apart, occlusion_maps.py).

        maps.window becomes the aggregate's window. torus: the current one (its alpha places the
        style mask's "behind" boundary).
        """
        slots = [int(s) for s in slots]
        if len(slots) != maps.count or not all(0 <= s < self.slot_count for s in slots):
            raise ValueError("AnticipationMap.refresh: one valid slot per map")
        self.schedule(time_s, slots)
        self.store(time_s, slots, self.predict(maps), maps.window, torus)

    def schedule(self, time_s: float, slots: list[int]) -> None:
        """The update at time_s of `slots` is under way: the round robin moves on (when they are
        its slots) and the next update is due one period later (one period after time_s when
        behind schedule or time went back)."""
        r = self.settings.samples_per_target
        round_robin = sorted(target * r + self._cursor for target in range(self.target_count))
        if sorted(slots) == round_robin:
            self._cursor = (self._cursor + 1) % r
        period = self.settings.update_period_s
        behind = self._next_due_s is None or self._last_update_s is None or time_s < self._last_update_s \
            or time_s >= self._next_due_s + period
        self._next_due_s = time_s + period if behind else self._next_due_s + period
        self._last_update_s = time_s

    def predict(self, maps: ShadowVelocityMaps) -> np.ndarray:
        """A_s (k, res, res) float32 of k freshly computed maps; changes nothing here."""
        if maps.window.resolution != self.settings.window.resolution:
            raise ValueError("AnticipationMap: maps have another resolution than the settings")
        return predict_occlusion(maps.shadow, maps.velocity_rad_s, maps.window, self.settings, self.bank)

    def store(self, time_s: float, slots: list[int], predicted: np.ndarray, window: MapWindow, torus: Torus) -> None:
        """Keeps the predictions (k, res, res) of `slots`, made at time_s on `window`, which becomes
        the aggregate's, and re-aggregates."""
        for slot, a_s in zip(slots, predicted):
            self._a_s[slot] = a_s
            self._windows[slot] = window
            self.computed_at_s[slot] = time_s
        self.window = window
        self._alpha_rad = torus.alpha
        self._aggregate()

    def _aggregate(self) -> None:
        n = self.settings.window.resolution
        total = np.zeros((n, n), dtype=np.float32)
        count = np.zeros((n, n), dtype=np.float32)
        for slot, window in enumerate(self._windows):
            if window is None:
                continue
            if window == self.window:
                total += self._a_s[slot]
                count += 1.0
            else:
                values, covered = window.resample(self._a_s[slot], self.window)
                total += values
                count += covered
        a = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
        self.coverage = count / self.slot_count
        self.a_map = apply_style_mask(a, style_mask(self.mask, self.window, self._alpha_rad))

    # -- reading -------------------------------------------------------------------------------

    def lookup(self, theta_rad, phi_rad, outside: float = np.nan) -> np.ndarray:
        """A at Toric angles (broadcast arrays, radians), bilinear; ``outside`` off the window or before any update."""
        theta = np.asarray(theta_rad, dtype=np.float64)
        phi = np.asarray(phi_rad, dtype=np.float64)
        shape = np.broadcast_shapes(theta.shape, phi.shape)
        if self.a_map is None:
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
        value = ((1 - wi) * ((1 - wj) * a[i0, j0] + wj * a[i0, j1])
                 + wi * ((1 - wj) * a[i1, j0] + wj * a[i1, j1]))
        return np.where(ok, value, outside)
