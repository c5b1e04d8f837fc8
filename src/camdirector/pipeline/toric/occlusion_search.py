"""MOTION stage of the visibility modes: the physically plausible search of the
occlusion-anticipation paper (section 5 and 5.1).

The camera is a particle on the moving torus: its place (theta, phi) moves with the targets, and
its own velocity lives in the torus's tangent plane, in world units. Each frame, with p the camera
and p(v) = p + v dt (1 - c/m dt) where it would coast to:
  1. single frame D_S: sample the area reachable in one frame, an annular sector around the
     velocity, angle span f_r = (2 pi - chi) / e^(g |v| dt) + chi and radial span
     f_l = max(2 h |v| dt, rho) (equation 3), on the tangent plane, projected onto the torus; take
     the least risky sample if it is less risky than p(v);
  2. look-ahead D_LA: the same with N dt; if it finds a better place, step toward it but stay in
     D_S (the paper's intersection of D_S's edge with [p(v), p_hat]; D_S's edge is taken as the
     circle of radius f_l / 2 around p(v));
  3. cut D_C: ray casts from candidate places over the whole torus to the target sample points
     (no prediction), pruned by the 30-degree rule; a less occluded one is cut to, velocity reset;
  4. otherwise coast: p_next = p(v).
Then v_next = (p_next - p) / dt (1 - c/m dt) (kept undamped as the realised velocity, the damping
applied when it is used, so the limits below compare against the motion that really happened).
The risk the local searches read is a `RiskField`: the A-map (ANTICIPATION), the averaged S-maps
(NO_ANTICIPATION) or ray casts (RAYCAST).

Beyond the paper, stated here because they change behaviour: the style's speed and acceleration
limits clamp every non-cut step (so motion stays physically plausible whatever the risk field
does); cut candidates stay on the upright side of the torus; the camera keeps away from top and bottom
views (view_phi_margin_deg);
a shot lasts at least `min_shot_s` before the next cut, so a flickering occluder cannot make a
flurry of cuts; and when the camera has been mostly occluded (ray casts to the samples) for
`stuck_s`, the cut search runs first: a risk field can keep offering marginally better places
inside an occluder's shadow (we saw the A-map do so under a wide, slow wall), and the local
searches would never give up.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from camdirector.geometry.toric import Torus, tangent_frame, theta_max, torus_angles_many, torus_position

# Occluded fraction (n,) of the target sample points from each camera place (n, 3), by ray casts.
Occlusion = Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]


class RiskField(Protocol):
    def risk(self, theta: npt.NDArray[np.float64], phi: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """(n,) occlusion risk in [0, 1] at torus places (n,) theta, (n,) phi radians."""


@dataclass(frozen=True)
class SearchSettings:
    samples: int = 50  # candidates per local search area (paper, section 6). [1, 10000]
    chi_deg: float = 10.0  # angular span at high speed, chi (Table 2), deg. (0, 360]
    g_per_m: float = 5.0  # how fast the angular span narrows with the step length, g (Table 2), 1/m. [0, 1000]
    h: float = 0.5  # linear freedom in speed, h (Table 2). [0, 10]
    rho_m: float = 0.1  # smallest linear span, rho (Table 2), m. (0, 100]
    look_ahead_frames: int = 10  # N of D_LA (user-defined in the paper). [2, 1000]
    damping_per_s: float = 4.0  # c/m of the damping force (the paper gives no value), 1/s. [0, 30]
    cut_samples: int = 64  # cut candidates over the torus. [1, 100000]
    min_cut_angle_deg: float = 30.0  # the 30-degree rule: a cut turns the view at least this much, deg. [0, 180]
    min_shot_s: float = 1.0  # no cut before a shot is this long (not in the paper), s. [0, 600]
    improvement: float = 0.005  # a place is less occluded only when better by this much (above the maps' noise). [0, 1]
    stuck_occluded: float = 0.5  # ray-cast occluded share of the samples that counts as "stuck" (not in the paper). [0, 1]
    stuck_s: float = 0.25  # stuck this long: try the cut before any local move (not in the paper), s. [0, 60]
    theta_margin_ratio: float = 0.2  # the camera keeps this share of theta's range from either end (not in the paper). [0, 0.45]
    view_phi_margin_deg: float = 25.0  # margin kept from top (phi 0) and bottom (phi 180) views (not in the paper), deg. [0, 89]

    def __post_init__(self) -> None:
        if not (1 <= self.samples <= 10000 and 1 <= self.cut_samples <= 100000 and self.look_ahead_frames >= 2):
            raise ValueError("search sample counts out of range")
        if not (0 < self.chi_deg <= 360 and self.rho_m > 0 and 0 <= self.damping_per_s <= 30):
            raise ValueError("search constants out of range")


@dataclass
class SearchResult:
    theta: float
    phi: float
    cut: bool
    strategy: str  # "start", "single_frame", "look_ahead", "cut", "coast"
    risk: float  # risk of the chosen place (local searches) or its occluded fraction (cut)


def _spans(settings: SearchSettings, speed_m_s: float, dt_s: float) -> tuple[float, float]:
    """(f_r radians, f_l metres) of equation 3, with f_l >= rho."""
    step = speed_m_s * dt_s
    chi = math.radians(settings.chi_deg)
    f_r = (math.tau - chi) / math.exp(settings.g_per_m * step) + chi
    return f_r, max(2.0 * settings.h * step, settings.rho_m)


class OcclusionSearch:
    """The camera particle of one session: place (theta, phi) and tangent velocity (3,) m/s."""

    def __init__(self, settings: SearchSettings, rng: np.random.Generator) -> None:
        self.settings = settings
        self.rng = rng
        self.theta: float | None = None
        self.phi = 0.0
        self.velocity_world = np.zeros(3)
        self.shot_start_s = 0.0
        self._occluded_since_s: float | None = None

    def start(self, theta: float, phi: float, time_s: float) -> SearchResult:
        self.theta, self.phi = theta, phi
        self.velocity_world = np.zeros(3)
        self.shot_start_s = time_s
        self._occluded_since_s = None
        return SearchResult(theta, phi, cut=True, strategy="start", risk=0.0)

    def _sector(
        self,
        p: npt.NDArray[np.float64],
        e1: npt.NDArray[np.float64],
        e2: npt.NDArray[np.float64],
        v_t: npt.NDArray[np.float64],
        dt_s: float,
    ) -> tuple[npt.NDArray[np.float64], float]:
        """(samples (n, 3) world on the tangent plane, f_l) of the area reachable in dt_s."""
        speed = float(np.linalg.norm(v_t))
        f_r, f_l = _spans(self.settings, speed, dt_s)
        heading = math.atan2(v_t @ e2, v_t @ e1) if speed > 0 else 0.0
        n = self.settings.samples
        angle = heading + self.rng.uniform(-0.5 * f_r, 0.5 * f_r, n)
        d0, d1 = max(0.0, speed * dt_s - 0.5 * f_l), speed * dt_s + 0.5 * f_l
        dist = np.sqrt(self.rng.uniform(d0 * d0, d1 * d1, n))  # uniform over the sector's area
        offsets = dist[:, None] * (np.cos(angle)[:, None] * e1 + np.sin(angle)[:, None] * e2)
        return p + offsets, f_l

    def step(
        self,
        torus: Torus,
        dt_s: float,
        time_s: float,
        risk: RiskField,
        cut_occlusion: Occlusion,
        side: float,
        max_speed_m_s: float,
        max_accel_m_s2: float,
    ) -> SearchResult:
        """One frame of section 5. `cut_occlusion(positions (n, 3)) -> (n,)` occluded fraction by
        ray casts; `side` (+1 / -1) is the upright half of the torus for cut candidates."""
        s = self.settings
        assert self.theta is not None  # start() places the particle before its first step
        p = torus_position(torus, self.theta, self.phi)
        if dt_s <= 0.0:
            return SearchResult(self.theta, self.phi, cut=False, strategy="coast", risk=float("nan"))
        t_theta, t_phi, normal = tangent_frame(torus, self.theta, self.phi)
        e1 = t_theta / np.linalg.norm(t_theta)
        e2 = np.cross(normal, e1)
        v_real = self.velocity_world - (self.velocity_world @ normal) * normal  # last frame's motion
        decay = max(0.0, 1.0 - s.damping_per_s * dt_s)
        v_t = v_real * decay  # the paper's damped velocity v_i
        coast = p + v_t * dt_s
        theta_c, phi_c = torus_angles_many(torus, coast[None])
        risk_coast = float(risk.risk(theta_c, phi_c)[0])

        occluded_now = float(cut_occlusion(p[None])[0])
        if occluded_now < s.stuck_occluded:
            self._occluded_since_s = None
        elif self._occluded_since_s is None:
            self._occluded_since_s = time_s
        can_cut = time_s - self.shot_start_s >= s.min_shot_s
        if can_cut and self._occluded_since_s is not None and time_s - self._occluded_since_s >= s.stuck_s:
            result = self._cut_to(torus, coast, cut_occlusion, side, time_s)
            if result is not None:
                return result

        target, strategy, chosen_risk = coast, "coast", risk_coast
        single, f_l = self._sector(p, e1, e2, v_t, dt_s)
        lo, hi = self._theta_range(torus)
        th, ph = torus_angles_many(torus, single)
        risks = np.where(self._outside(th, ph, lo, hi), np.inf, risk.risk(th, ph))
        best = int(np.argmin(risks))
        if risks[best] < risk_coast - s.improvement:
            target, strategy, chosen_risk = single[best], "single_frame", float(risks[best])
        else:
            ahead, _ = self._sector(p, e1, e2, v_t, s.look_ahead_frames * dt_s)
            th, ph = torus_angles_many(torus, ahead)
            risks = np.where(self._outside(th, ph, lo, hi), np.inf, risk.risk(th, ph))
            best = int(np.argmin(risks))
            if risks[best] < risk_coast - s.improvement:
                toward = ahead[best] - coast
                reach = float(np.linalg.norm(toward))
                target = coast + toward * min(1.0, 0.5 * f_l / reach) if reach > 0 else coast
                strategy, chosen_risk = "look_ahead", float(risks[best])
            elif can_cut:
                result = self._cut_to(torus, coast, cut_occlusion, side, time_s)
                if result is not None:
                    return result

        # physical limits of the style on the camera's own motion, braking by damping included
        velocity = (target - p) / dt_s
        accel = (velocity - v_real) / dt_s
        a = float(np.linalg.norm(accel))
        if a > max_accel_m_s2:
            velocity = v_real + accel * (max_accel_m_s2 / a * dt_s)
        speed = float(np.linalg.norm(velocity))
        if speed > max_speed_m_s:
            velocity *= max_speed_m_s / speed
        theta_n, phi_n = torus_angles_many(torus, (p + velocity * dt_s)[None])
        margin = math.radians(s.view_phi_margin_deg)
        phi_next = math.copysign(min(max(abs(float(phi_n[0])), margin), math.pi - margin), float(phi_n[0]))
        self.theta, self.phi = min(max(float(theta_n[0]), lo), hi), phi_next
        p_next = torus_position(torus, self.theta, self.phi)
        self.velocity_world = (p_next - p) / dt_s
        return SearchResult(self.theta, self.phi, cut=False, strategy=strategy, risk=chosen_risk)

    def _outside(
        self, theta: npt.NDArray[np.float64], phi: npt.NDArray[np.float64], lo: float, hi: float
    ) -> npt.NDArray[np.bool_]:
        """Places the camera may not go: the arc's ends, and top and bottom views."""
        margin = math.radians(self.settings.view_phi_margin_deg)
        outside: npt.NDArray[np.bool_] = (theta < lo) | (theta > hi) | (np.abs(phi) < margin) | (np.abs(phi) > math.pi - margin)
        return outside

    def _theta_range(self, torus: Torus) -> tuple[float, float]:
        """Allowed theta, radians: the arc's ends put the camera on top of A or B."""
        top = theta_max(torus.alpha)
        return self.settings.theta_margin_ratio * top, (1.0 - self.settings.theta_margin_ratio) * top

    def _cut_to(
        self, torus: Torus, coast: npt.NDArray[np.float64], cut_occlusion: Occlusion, side: float, time_s: float
    ) -> SearchResult | None:
        """Teleports to a cut place when there is one (velocity reset, a new shot)."""
        cut = self._cut(torus, coast, cut_occlusion, side)
        if cut is None:
            return None
        self.theta, self.phi, occluded = cut
        self.velocity_world = np.zeros(3)
        self.shot_start_s = time_s
        self._occluded_since_s = None
        return SearchResult(self.theta, self.phi, cut=True, strategy="cut", risk=occluded)

    def _cut(
        self, torus: Torus, coast: npt.NDArray[np.float64], cut_occlusion: Occlusion, side: float
    ) -> tuple[float, float, float] | None:
        """(theta, phi, occluded fraction) of a less occluded place obeying the 30-degree rule, or None."""
        s = self.settings
        current = float(cut_occlusion(coast[None])[0])
        if current <= s.improvement:
            return None
        margin = math.radians(s.view_phi_margin_deg)
        theta = self.rng.uniform(*self._theta_range(torus), s.cut_samples)
        phi = side * self.rng.uniform(margin, math.pi - margin, s.cut_samples)
        places = torus_position(torus, theta, phi)
        focus = 0.5 * (torus.a_world + torus.b_world)
        now = (focus - coast) / np.linalg.norm(focus - coast)
        views = focus - places
        views /= np.linalg.norm(views, axis=1, keepdims=True)
        keep = views @ now <= math.cos(math.radians(s.min_cut_angle_deg))
        if not keep.any():
            return None
        theta, phi, places = theta[keep], phi[keep], places[keep]
        occluded = cut_occlusion(places)
        best = int(np.argmin(occluded))
        if occluded[best] < current - s.improvement:
            return float(theta[best]), float(phi[best]), float(occluded[best])
        return None


class RaycastRisk:
    """The paper's R baseline as a RiskField: no maps, rays from each candidate place to the
    target sample points at search time (fraction occluded)."""

    def __init__(self, torus: Torus, occluded_fraction: Occlusion) -> None:
        self.torus = torus
        self.occluded_fraction = occluded_fraction

    def risk(self, theta: npt.NDArray[np.float64], phi: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return self.occluded_fraction(torus_position(self.torus, theta, phi))
