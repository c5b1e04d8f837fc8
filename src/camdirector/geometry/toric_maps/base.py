"""Toric-space visibility maps: the map window, the occluder scene, the result type, the backend interface.

Paper: occlusion-anticipation-toric-space.md, section 4 (a texture whose coordinates map the Toric
angles (theta, phi) linearly), 4.1 (deferred projection from sample points on the targets), 4.1.1
(target shadow map, S-map), 4.1.2 (occluder velocity map, V-map). Angles and frames are those of
geometry/toric.py: theta along the arc from A, phi about the A-B axis, 0 above it.

Array conventions, shared by every backend and by pipeline/toric/occlusion_prediction.py:

- A map over a window is indexed ``[i, j]`` with ``i`` the theta texel and ``j`` the phi texel; the
  texel centre of ``[i, j]`` is ``(window.theta_centers_rad[i], window.phi_centers_rad[j])``.
- Velocities in texture space are Toric angular rates, radians per second, in the same order as the
  axes: ``velocity_rad_s[..., 0] = d theta / dt``, ``velocity_rad_s[..., 1] = d phi / dt``. Radians (not
  texels) so a map stays meaningful when it is resampled onto another window; multiply by
  ``1 / window.theta_step_rad`` and ``1 / window.phi_step_rad`` for texels per second.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.toric import Torus, torus_position
from camdirector.geometry.transforms import RigidTransform

# A ray (GL: a depth comparison) stops this fraction short of the torus point, and starts this far
# from the sample point: a sample on a surface the target touches (feet on the ground) must not be
# occluded by that surface at distance zero. Both backends use the same two numbers.
SEGMENT_END_MARGIN = 1e-4  # relative to the sample-to-torus distance
SAMPLE_CLEARANCE_M = 1e-3  # occluders nearer than this to the sample point are ignored, m
NOT_OCCLUDED_DEPTH = np.inf  # depth_m where a texel is not occluded


@dataclass(frozen=True)
class WindowSettings:
    """How a map window is sized around the camera (see MapWindow.around).

    The paper projects only "a local area around the current camera position" (section 5.1, cut
    strategy): the whole torus would be too distorted in the rendered buffers. We size that area so
    it is seen from the targets under a fixed angle, which bounds the distortion of the projection
    from the sample points whatever the shot size.
    """

    resolution: int = 64  # texels per side; the paper's default (section 6). [8, 1024]
    half_view_angle_deg: float = 30.0  # half-side of the window seen from the A-B midpoint, deg. [1, 75]
    min_half_extent_m: float = 0.25  # lower clamp of the window's half-side on the torus, m. (0, 1000]
    max_half_extent_m: float = 50.0  # upper clamp, m. [min_half_extent_m, 10000]
    lattice_tolerance: float = 0.15  # keep the previous texel size while the ideal is within this ratio. [0, 1]

    def __post_init__(self) -> None:
        checks = [
            (8 <= self.resolution <= 1024, "resolution must be in [8, 1024]"),
            (1.0 <= self.half_view_angle_deg <= 75.0, "half_view_angle_deg must be in [1, 75]"),
            (0.0 < self.min_half_extent_m <= 1000.0, "min_half_extent_m must be in (0, 1000]"),
            (
                self.min_half_extent_m <= self.max_half_extent_m <= 10000.0,
                "max_half_extent_m must be in [min_half_extent_m, 10000]",
            ),
            (0.0 <= self.lattice_tolerance <= 1.0, "lattice_tolerance must be in [0, 1]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"WindowSettings: {message}")


@dataclass(frozen=True)
class MapWindow:
    """A rectangle of Toric texture space: ``resolution`` x ``resolution`` texels over (theta, phi).

    theta_min_rad, phi_min_rad: lower edges of texel row/column 0, radians. theta_step_rad,
    phi_step_rad: texel size, radians. phi is periodic: a window may run past +-pi (coordinates
    are not wrapped), and lookups wrap phi into the window's turn. theta is not wrapped.
    """

    theta_min_rad: float
    phi_min_rad: float
    theta_step_rad: float
    phi_step_rad: float
    resolution: int = 64
    # (theta_centers_rad, phi_centers_rad), made by __post_init__
    _centers: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.resolution, (int, np.integer)) and 1 <= self.resolution <= 4096):
            raise ValueError(f"MapWindow: resolution must be an int in [1, 4096], got {self.resolution!r}")
        values = (self.theta_min_rad, self.phi_min_rad, self.theta_step_rad, self.phi_step_rad)
        if not all(math.isfinite(v) for v in values):
            raise ValueError("MapWindow: non-finite bound")
        if not (0.0 < self.theta_step_rad and 0.0 < self.phi_step_rad):
            raise ValueError("MapWindow: texel steps must be positive")
        if self.phi_step_rad * self.resolution > math.tau * (1.0 + 1e-9):
            raise ValueError("MapWindow: the phi span exceeds one turn")
        n = self.resolution
        theta = self.theta_min_rad + (np.arange(n) + 0.5) * self.theta_step_rad
        phi = self.phi_min_rad + (np.arange(n) + 0.5) * self.phi_step_rad
        theta.setflags(write=False)
        phi.setflags(write=False)
        object.__setattr__(self, "_centers", (theta, phi))

    # -- geometry of the texture ---------------------------------------------------------------

    @property
    def theta_centers_rad(self) -> npt.NDArray[np.float64]:
        """(res,) theta of each texel row's centre, radians (read-only)."""
        return self._centers[0]

    @property
    def phi_centers_rad(self) -> npt.NDArray[np.float64]:
        """(res,) phi of each texel column's centre, radians, unwrapped (read-only)."""
        return self._centers[1]

    @property
    def theta_span_rad(self) -> float:
        return self.theta_step_rad * self.resolution

    @property
    def phi_span_rad(self) -> float:
        return self.phi_step_rad * self.resolution

    @property
    def center_rad(self) -> tuple[float, float]:
        """(theta, phi) of the window's centre, radians."""
        return (self.theta_min_rad + 0.5 * self.theta_span_rad, self.phi_min_rad + 0.5 * self.phi_span_rad)

    def texel_coords(
        self, theta_rad: npt.ArrayLike, phi_rad: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Float texel coordinates (i, j) of angles; integers are texel centres.

        theta_rad, phi_rad: broadcastable arrays or scalars, radians. phi is wrapped into the turn
        centred on the window. Out-of-window angles give coordinates outside [-0.5, res - 0.5].
        """
        theta = np.asarray(theta_rad, dtype=np.float64)
        phi = np.asarray(phi_rad, dtype=np.float64)
        i = (theta - self.theta_min_rad) / self.theta_step_rad - 0.5
        phi_center = self.phi_min_rad + 0.5 * self.phi_span_rad
        d_phi = np.remainder(phi - phi_center + math.pi, math.tau) - math.pi
        j = (d_phi + 0.5 * self.phi_span_rad) / self.phi_step_rad - 0.5
        return i, j

    def angles(self, i: npt.ArrayLike, j: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(theta, phi) radians of float texel coordinates (i, j); the inverse of texel_coords."""
        theta = self.theta_min_rad + (np.asarray(i, dtype=np.float64) + 0.5) * self.theta_step_rad
        phi = self.phi_min_rad + (np.asarray(j, dtype=np.float64) + 0.5) * self.phi_step_rad
        return theta, phi

    def contains(self, theta_rad: npt.ArrayLike, phi_rad: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether angles fall inside the window's rectangle (bool, broadcast shape)."""
        i, j = self.texel_coords(theta_rad, phi_rad)
        half = 0.5
        n = self.resolution
        return (i >= -half) & (i <= n - half) & (j >= -half) & (j <= n - half)

    def grid(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(theta, phi) of every texel centre, each (res, res), indexed [i, j]."""
        return np.meshgrid(self.theta_centers_rad, self.phi_centers_rad, indexing="ij")

    # -- sizing --------------------------------------------------------------------------------

    @classmethod
    def around(
        cls,
        torus: Torus,
        theta_rad: float,
        phi_rad: float,
        settings: WindowSettings = WindowSettings(),
        lattice: MapWindow | None = None,
    ) -> MapWindow:
        """The window centred on the camera at (theta_rad, phi_rad) on ``torus``.

        Sizing rule: the window is a square of side 2 h metres on the torus at the camera, with
        h = |C - M| tan(half_view_angle), C the camera, M the A-B midpoint, clamped to
        [min_half_extent_m, max_half_extent_m]. Texels are square in metres at the camera (theta
        step h-per-radian from the arc radius, phi step from the camera's distance to the axis), so
        directions measured in texels are directions on the surface there (the A-map's angular
        falloff relies on it). A span is capped at one turn (a camera close to the A-B axis).

        lattice: the previous window. While the ideal texel size stays within
        settings.lattice_tolerance of the lattice's, the lattice's texel size is kept and the new
        window is shifted by whole texels, so maps computed on older windows line up texel for
        texel (pipeline/toric/anticipation_map.py aggregates them without resampling blur).
        """
        n = settings.resolution
        camera = torus_position(torus, float(theta_rad), float(phi_rad))
        half_m = float(np.linalg.norm(camera - torus.mid_world)) * math.tan(math.radians(settings.half_view_angle_deg))
        half_m = min(max(half_m, settings.min_half_extent_m), settings.max_half_extent_m)
        radial_m = torus.center_offset_m - torus.arc_radius_m * math.cos(torus.alpha + float(theta_rad))
        step_theta = min(2.0 * half_m / (n * torus.arc_radius_m), math.tau / n)
        step_phi = min(2.0 * half_m / (n * max(radial_m, 1e-12)), math.tau / n)
        if lattice is not None and lattice.resolution == n:
            ratio_t = step_theta / lattice.theta_step_rad
            ratio_p = step_phi / lattice.phi_step_rad
            tol = settings.lattice_tolerance
            if abs(ratio_t - 1.0) <= tol and abs(ratio_p - 1.0) <= tol:
                step_theta, step_phi = lattice.theta_step_rad, lattice.phi_step_rad
                theta_min = float(theta_rad) - 0.5 * n * step_theta
                d_phi = math.remainder(float(phi_rad) - 0.5 * n * step_phi - lattice.phi_min_rad, math.tau)
                return cls(
                    theta_min_rad=lattice.theta_min_rad + round((theta_min - lattice.theta_min_rad) / step_theta) * step_theta,
                    phi_min_rad=lattice.phi_min_rad + round(d_phi / step_phi) * step_phi,
                    theta_step_rad=step_theta,
                    phi_step_rad=step_phi,
                    resolution=n,
                )
        return cls(
            theta_min_rad=float(theta_rad) - 0.5 * n * step_theta,
            phi_min_rad=float(phi_rad) - 0.5 * n * step_phi,
            theta_step_rad=step_theta,
            phi_step_rad=step_phi,
            resolution=n,
        )

    # -- resampling ----------------------------------------------------------------------------

    def resample(self, values: npt.ArrayLike, destination: MapWindow) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
        """Bilinear resampling of maps on this window onto ``destination``.

        values: (..., res, res) on this window. Returns (values (..., res_d, res_d) float32, covered
        (res_d, res_d) bool): destination texels outside this window are 0 and not covered. Windows
        on one lattice (MapWindow.around with lattice=) differ by whole texels, and the weights are
        then exactly 0 and 1: a plain shift, no blur.
        """
        i, _ = self.texel_coords(destination.theta_centers_rad, self.phi_min_rad)
        _, j = self.texel_coords(self.theta_min_rad, destination.phi_centers_rad)
        rows, row_w, row_ok = _linear_taps(i, self.resolution)
        cols, col_w, col_ok = _linear_taps(j, self.resolution)
        v = np.asarray(values, dtype=np.float32)
        r0 = v[..., rows[0], :]
        r1 = v[..., rows[1], :]
        by_row = r0 + (r1 - r0) * row_w[:, None].astype(np.float32)  # (..., res_d, res)
        c0 = by_row[..., cols[0]]
        c1 = by_row[..., cols[1]]
        out = c0 + (c1 - c0) * col_w.astype(np.float32)
        covered = row_ok[:, None] & col_ok[None, :]
        out *= covered
        return out, covered


def _linear_taps(
    coord: npt.NDArray[np.float64], n: int
) -> tuple[tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Indices (2, m), weights (m,) and validity (m,) for linear interpolation at float coords."""
    ok = (coord >= -0.5 - 1e-6) & (coord <= n - 0.5 + 1e-6)
    # Whole-texel shifts arrive as x.9999999 or x.0000001: snap them so they copy exactly.
    nearest = np.rint(coord)
    c = np.clip(np.where(np.abs(coord - nearest) < 1e-6, nearest, coord), 0.0, n - 1.0)
    lo = np.minimum(np.floor(c).astype(np.intp), n - 1)
    hi = np.minimum(lo + 1, n - 1)
    return (lo, hi), c - lo, ok


# -- the occluder scene ------------------------------------------------------------------------


@dataclass
class DynamicOccluder:
    """One moving rigid object: local mesh, current pose, and its velocity (world frame).

    The velocity of a point p of the object is linear_velocity_m_s + angular_velocity_rad_s x
    (p - transform.position_world): the rotation is about the object's local origin.
    """

    mesh_local: TriMesh
    transform: RigidTransform
    linear_velocity_m_s: npt.NDArray[np.float64]  # (3,) world, m/s
    angular_velocity_rad_s: npt.NDArray[np.float64]  # (3,) world, rad/s
    bound_center_local: npt.NDArray[np.float64] = field(init=False, repr=False)  # (3,) centre of the local bounding sphere
    bound_radius_local: float = field(init=False, repr=False)  # its radius, local units

    def __post_init__(self) -> None:
        lo, hi = self.mesh_local.vertices.min(axis=0), self.mesh_local.vertices.max(axis=0)
        self.bound_center_local = 0.5 * (lo + hi)
        spread = np.linalg.norm(self.mesh_local.vertices - self.bound_center_local, axis=1)
        self.bound_radius_local = float(spread.max())

    def point_velocity(self, points_world: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(n, 3) world velocity, m/s, of the object's points (n, 3) world."""
        arm = np.asarray(points_world, dtype=np.float64) - self.transform.position_world
        return self.linear_velocity_m_s + np.cross(self.angular_velocity_rad_s, arm)


def _vector3(value: npt.ArrayLike, name: str) -> npt.NDArray[np.float64]:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


class OccluderScene:
    """What can hide the targets: static meshes (world frame) and moving rigid objects.

    Shared by both backends; each keeps its own acceleration data (Embree scenes, GL buffers) and
    rebuilds it when ``geometry_version`` changes (meshes added or removed). Moving an object
    (``set_motion``) only changes its pose and velocity: no rebuild.

    Targets may be added as dynamic objects so that one target hides the other; a map computation
    then excludes each sample's own target (the paper renders "the rest of the scene without the
    object o to avoid self-occlusions", section 4.1).
    """

    def __init__(self, static_meshes_world: Sequence[TriMesh] = ()):
        self._static: list[TriMesh] = list(static_meshes_world)
        self._dynamic: dict[str, DynamicOccluder] = {}
        self.geometry_version = 0

    @property
    def static_meshes_world(self) -> tuple[TriMesh, ...]:
        return tuple(self._static)

    @property
    def dynamic(self) -> dict[str, DynamicOccluder]:
        """Moving objects by id, in insertion order (read it, change it through the methods)."""
        return self._dynamic

    @property
    def triangle_count(self) -> int:
        return sum(m.triangle_count for m in self._static) + sum(o.mesh_local.triangle_count for o in self._dynamic.values())

    def add_static(self, mesh_world: TriMesh) -> None:
        self._static.append(mesh_world)
        self.geometry_version += 1

    def add_dynamic(
        self,
        object_id: str,
        mesh_local: TriMesh,
        transform: RigidTransform,
        linear_velocity_m_s: npt.ArrayLike = (0.0, 0.0, 0.0),
        angular_velocity_rad_s: npt.ArrayLike = (0.0, 0.0, 0.0),
    ) -> None:
        if object_id in self._dynamic:
            raise ValueError(f"dynamic object {object_id!r} already added")
        self._dynamic[object_id] = DynamicOccluder(
            mesh_local,
            transform,
            _vector3(linear_velocity_m_s, "linear_velocity_m_s"),
            _vector3(angular_velocity_rad_s, "angular_velocity_rad_s"),
        )
        self.geometry_version += 1

    def remove_dynamic(self, object_id: str) -> None:
        del self._dynamic[object_id]
        self.geometry_version += 1

    def set_motion(
        self,
        object_id: str,
        transform: RigidTransform,
        linear_velocity_m_s: npt.ArrayLike = (0.0, 0.0, 0.0),
        angular_velocity_rad_s: npt.ArrayLike = (0.0, 0.0, 0.0),
    ) -> None:
        """New pose and velocity (world frame; the caller estimates it from successive poses)."""
        self.set_motions(
            [object_id],
            [transform],
            _vector3(linear_velocity_m_s, "linear_velocity_m_s")[None],
            _vector3(angular_velocity_rad_s, "angular_velocity_rad_s")[None],
        )

    def set_motions(
        self,
        object_ids: Sequence[str],
        transforms: Sequence[RigidTransform],
        linear_velocities_m_s: npt.ArrayLike,
        angular_velocities_rad_s: npt.ArrayLike,
    ) -> None:
        """set_motion for m objects at once, velocities (m, 3) world, checked in one pass: a map
        build moves every object of a scene that has a hundred of them."""
        m = len(object_ids)
        linear = np.asarray(linear_velocities_m_s, dtype=np.float64)
        angular = np.asarray(angular_velocities_rad_s, dtype=np.float64)
        for name, v in (("linear_velocities_m_s", linear), ("angular_velocities_rad_s", angular)):
            if v.shape != (m, 3) or not np.isfinite(v).all():
                raise ValueError(f"{name} must be ({m}, 3) finite numbers, got shape {v.shape}")
        if len(transforms) != m:
            raise ValueError(f"set_motions: {m} ids but {len(transforms)} transforms")
        dynamic = self._dynamic
        for object_id, transform, v, w in zip(object_ids, transforms, linear, angular):
            obj = dynamic[object_id]
            obj.transform, obj.linear_velocity_m_s, obj.angular_velocity_rad_s = transform, v, w


# -- results and the backend interface ---------------------------------------------------------


@dataclass(frozen=True)
class ShadowVelocityMaps:
    """S-maps and V-maps of k sample points over one window (sections 4.1.1 and 4.1.2).

    shadow: (k, res, res) float32 in {0, 1}; 1 where the sample point is hidden from the torus point
    of that texel. velocity_rad_s: (k, res, res, 2) float32, the first occluder's velocity at the
    occluding point minus the torus point's velocity, projected on the torus tangent plane and
    expressed as (d theta / dt, d phi / dt) rad/s; 0 where not occluded. depth_m: (k, res, res)
    float32, distance from the sample point to that occluding point; inf where not occluded.
    """

    window: MapWindow
    shadow: npt.NDArray[np.float32]
    velocity_rad_s: npt.NDArray[np.float32]
    depth_m: npt.NDArray[np.float32]

    @property
    def count(self) -> int:
        return int(self.shadow.shape[0])


@runtime_checkable
class MapBackend(Protocol):
    """Computes ShadowVelocityMaps; gl.GLMapBackend and embree.EmbreeMapBackend give the same maps."""

    name: str

    def compute(
        self,
        torus: Torus,
        window: MapWindow,
        sample_points_world: npt.ArrayLike,
        *,
        exclude_ids: Sequence[str | None] | None = None,
        previous_torus: Torus | None = None,
        dt_s: float = 0.0,
    ) -> ShadowVelocityMaps:
        """Maps of k sample points (k, 3) world metres over ``window`` of ``torus``.

        exclude_ids: k entries, the id of the dynamic object each sample lies on (its own target,
        ignored for that sample), or None. previous_torus and dt_s > 0: the torus one step earlier,
        for the torus point velocity subtracted in the V-map (section 4.1.2, by finite differences at
        fixed (theta, phi)); without them the torus is taken as still.
        """
        ...

    def close(self) -> None:
        """Free what the backend holds (GL context, Embree scenes)."""
        ...


def check_compute_args(
    window: MapWindow,
    sample_points_world: npt.ArrayLike,
    exclude_ids: Sequence[str | None] | None,
    previous_torus: Torus | None,
    dt_s: float,
    max_samples: int = 64,
) -> tuple[npt.NDArray[np.float64], list[str | None]]:
    """Validated (k, 3) float64 sample points and a k-list of excluded ids; ValueError otherwise."""
    points = np.asarray(sample_points_world, dtype=np.float64)
    if points.ndim == 1 and points.shape == (3,):
        points = points[None, :]
    if points.ndim != 2 or points.shape[1] != 3 or not 1 <= len(points) <= max_samples:
        raise ValueError(f"sample_points_world must be (k, 3) with 1 <= k <= {max_samples}, got {np.shape(sample_points_world)}")
    if not np.all(np.isfinite(points)):
        raise ValueError("sample_points_world must be finite")
    excluded: list[str | None] = [None] * len(points) if exclude_ids is None else list(exclude_ids)
    if len(excluded) != len(points):
        raise ValueError("exclude_ids must have one entry per sample point")
    if previous_torus is not None and not (math.isfinite(dt_s) and dt_s > 0.0):
        raise ValueError("previous_torus needs dt_s > 0")
    return points, excluded


def torus_points(torus: Torus, window: MapWindow) -> npt.NDArray[np.float64]:
    """(res, res, 3) world positions, metres, of the texel centres of ``window`` on ``torus``."""
    return torus_position(torus, window.theta_centers_rad[:, None], window.phi_centers_rad[None, :])


def torus_point_velocity(torus: Torus, window: MapWindow, previous_torus: Torus | None, dt_s: float) -> npt.NDArray[np.float64]:
    """(res, res, 3) m/s: d/dt of the torus point at each texel's fixed (theta, phi), by finite difference."""
    now = torus_points(torus, window)
    if previous_torus is None:
        return np.zeros_like(now)
    return (now - torus_points(previous_torus, window)) / dt_s


def torus_tangents(torus: Torus, window: MapWindow) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(d pos / d theta, d pos / d phi), each (res, res, 3), metres per radian, at the texel centres.

    The vectorised form of geometry.toric.tangent_frame (the T and B of the paper's TBN; the two are
    orthogonal on a surface of revolution).
    """
    r = torus.arc_radius_m
    t = torus.alpha + window.theta_centers_rad[:, None]
    phi = window.phi_centers_rad[None, :]
    s, c = np.sin(t), np.cos(t)
    sp, cp = np.sin(phi), np.cos(phi)
    radial = torus.center_offset_m - r * c
    zero = np.zeros(np.broadcast_shapes(t.shape, phi.shape))
    d_theta = np.stack(np.broadcast_arrays(-r * c, r * s * cp, r * s * sp), axis=-1) @ torus.basis
    d_phi = np.stack(np.broadcast_arrays(zero, -radial * sp, radial * cp), axis=-1) @ torus.basis
    return d_theta, d_phi


def texture_velocity(
    velocity_world: npt.NDArray[np.float64], d_theta: npt.NDArray[np.float64], d_phi: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """World velocities (..., 3) m/s -> Toric angular rates (..., 2) rad/s.

    TBN^t v keeps the tangent-plane part (section 4.1.2); dividing each component by the length of
    its tangent (metres per radian) turns metres per second into radians per second of theta and
    phi. On the axis (|d pos / d phi| = 0) the phi rate is 0.
    """
    n_theta = np.einsum("...k,...k->...", d_theta, d_theta)
    n_phi = np.einsum("...k,...k->...", d_phi, d_phi)
    v_theta = np.einsum("...k,...k->...", velocity_world, d_theta) / n_theta
    with np.errstate(divide="ignore", invalid="ignore"):
        v_phi = np.where(n_phi > 1e-18, np.einsum("...k,...k->...", velocity_world, d_phi) / n_phi, 0.0)
    return np.stack([v_theta, v_phi], axis=-1)
