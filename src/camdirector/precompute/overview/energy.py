"""The path energy E = E_internal + E_external (paper Section 4).

    E_external = -sum_t S_p(t) * V(p_t)
    E_internal = sum_t  c1 * acc_t^2 + c2 * floor(speed_t)_{>1}^4
                      + c3 * angacc_t^2 + c4 * floor(angspeed_t)_{>1}^4 + friction_t

with c1..c5 = 10, 10, 5, 5, 2, S_max = height/6, alpha_max = 20 deg, F_max = height/20 (per
second: the paper gives no time unit; per frame would allow 8.5 m/s at 30 fps).

Choices where the paper leaves the units open (so that every term is dimensionless and the
coefficients keep their published meaning at any frame rate and skeleton size):

* speed_t = |p_{t+1} - p_{t-1}| / (2 dt S_max) and angspeed_t = angle(u_{t-1}, u_{t+1}) /
  (2 dt alpha_max), exactly as written, with u_t the unit view direction from p_t to the look-at
  point (alpha_t is "the camera [...] viewing angle to the target").
* acc_t = |p_{t-1} - 2 p_t + p_{t+1}| / (dt S_max): the change of velocity over one frame as a
  fraction of the speed limit; angacc_t = |u_{t-1} - 2 u_t + u_{t+1}| / (dt alpha_max) likewise
  (|du| is the angle in radians for small angles).
* Friction. As printed, -c5 * floor(f)_{<1}^2 with f = |p_{t+1} - p_{t-1}| / (2 dt F_max) is 0 for
  a static camera and -c5 just below F_max: it would reward drifting at F_max, the opposite of
  "a friction term which counteracts forces and promotes static camera up to a certain force".
  We use friction_t = c5 * min(f, 1)^2: 0 for a static camera (as printed), rising to c5 at F_max
  and flat above, so a camera moves only when the gain in the other terms pays for leaving rest.
  An earlier reading, -c5 * (1 - f^2) below F_max, behaves the same inside a shot (it differs by
  the constant -c5 per frame) but made every internal term sum negative for a resting camera, so
  a cut, which removes two terms, *raised* E_internal by 2 c5: the paper says the opposite,
  "by splitting the shot into two different shots, we reduce the internal energy". With every
  term >= 0, removing terms at a cut never raises E_internal. The constant also made E of a
  static camera mostly friction (90% on the dance), which blurred Figure 10's E ratios.
* Terms need both neighbours: a shot of n frames has n - 2 internal terms; there are no terms
  across a cut.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.potential import PotentialSpace

_TIE_RELATIVE = 1e-9  # relative difference below which two energies are a tie


@dataclass(frozen=True)
class EnergyWeights:
    """The constants of E for one clip: c1..c5; limits in SI: max_speed_m_s (S_max),
    max_angular_speed_rad_s (alpha_max), friction_speed_m_s (F_max); dt_s per frame."""

    c1: float
    c2: float
    c3: float
    c4: float
    c5: float
    max_speed_m_s: float
    max_angular_speed_rad_s: float
    friction_speed_m_s: float
    dt_s: float

    @classmethod
    def for_track(cls, track: CharacterTrack, settings: OverviewSettings) -> EnergyWeights:
        h = track.height_m
        return cls(
            c1=settings.c1,
            c2=settings.c2,
            c3=settings.c3,
            c4=settings.c4,
            c5=settings.c5,
            max_speed_m_s=settings.max_speed_heights_s * h,
            max_angular_speed_rad_s=np.radians(settings.max_angular_speed_deg_s),
            friction_speed_m_s=settings.friction_speed_heights_s * h,
            dt_s=track.dt_s,
        )


@dataclass(frozen=True)
class PathEnergy:
    """E = internal + external; v_sum: sum_t V(p_t) (no saliency weight), all over whole clip."""

    total: float
    internal: float
    external: float
    v_sum: float


def energy_below(value: float, reference: float) -> bool:
    """value < reference by more than rounding (relative `_TIE_RELATIVE`): one path scored by two
    summation orders, such as a static camera and an annealed path that kept it, differs by about
    1e-13, which is a tie, not a gain."""
    return value < reference - _TIE_RELATIVE * max(1.0, abs(reference))


def view_directions(path_m: np.ndarray, look_at_m: np.ndarray) -> np.ndarray:
    """(n, ..., 3) unit vectors from camera positions (n, ..., 3) to look-at points (n, 3)."""
    d = look_at_m.reshape(look_at_m.shape[:1] + (1,) * (path_m.ndim - 2) + (3,)) - path_m
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)


def internal_terms(path_m: np.ndarray, look_at_m: np.ndarray, w: EnergyWeights) -> np.ndarray:
    """(n - 2, ...) E_internal terms at the interior frames of one shot's path (n, 3), or of
    several paths at once (n, P, 3) sharing the look-at points (n, 3); each term is >= 0."""
    if len(path_m) < 3:
        return np.zeros((0,) + path_m.shape[1:-1])
    u = view_directions(path_m, look_at_m)
    prev, cur, nxt = path_m[:-2], path_m[1:-1], path_m[2:]
    acc = np.linalg.norm(prev - 2.0 * cur + nxt, axis=-1) / (w.dt_s * w.max_speed_m_s)
    span = np.linalg.norm(nxt - prev, axis=-1) / (2.0 * w.dt_s)
    speed = span / w.max_speed_m_s
    u_prev, u_cur, u_next = u[:-2], u[1:-1], u[2:]
    ang_acc = np.linalg.norm(u_prev - 2.0 * u_cur + u_next, axis=-1) / (w.dt_s * w.max_angular_speed_rad_s)
    ang = np.arccos(np.clip(np.einsum("...k,...k->...", u_prev, u_next), -1.0, 1.0))
    ang_speed = ang / (2.0 * w.dt_s * w.max_angular_speed_rad_s)
    friction = span / w.friction_speed_m_s
    return (
        w.c1 * acc**2
        + w.c2 * np.where(speed > 1.0, speed, 0.0) ** 4
        + w.c3 * ang_acc**2
        + w.c4 * np.where(ang_speed > 1.0, ang_speed, 0.0) ** 4
        + w.c5 * np.minimum(friction, 1.0) ** 2
    )


def path_energy(
    path_m: np.ndarray,
    shots: np.ndarray,
    track: CharacterTrack,
    space: PotentialSpace,
    pose_saliency: np.ndarray,
    w: EnergyWeights,
) -> PathEnergy:
    """E of a path (T, 3) over all track frames, cut into shots (S, 2) [first, last] frames."""
    frames = np.arange(track.frame_count)
    v = space.sample(frames, path_m)
    internal = sum(float(internal_terms(path_m[a : b + 1], track.look_at_m[a : b + 1], w).sum()) for a, b in shots)
    external = -float(np.sum(pose_saliency * v))
    return PathEnergy(total=internal + external, internal=internal, external=external, v_sum=float(v.sum()))
