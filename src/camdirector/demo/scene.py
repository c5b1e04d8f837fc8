"""The procedural scene of the built-in demo game client.

An avatar (a box-and-capsule humanoid, 1.8 m tall, feet at y = 0) walks a smooth open path with
turns among static columns on a ground slab, while a few moving obstacles cross its path back and
forth. Everything follows from one seed, so a demo run can be replayed exactly.

Frames as everywhere in camdirector: right-handed, +Y up, metres, seconds. Every object's mesh is in
its local frame with its base at local y = 0; `DemoObject.transform` places it. The avatar faces its
local +Z (the glTF convention for assets) and is turned about +Y to face its walking direction.

Layout guarantees (checked while placing, with rejection sampling):
- each column's surface stays at least `COLUMN_CLEARANCE_M` from the avatar's path centre line, and
  at most `COLUMN_REACH_M` from it, so columns come between the avatar and a camera 3-6 m away;
- each obstacle's track keeps its footprint out of every column and away from other tracks
  (checked at 32 samples along the track; the 0.2 m margin covers the <= 0.17 m between samples);
- obstacles cross the avatar's path a second or two before or after the avatar passes, never
  through it (their footprints stay `OBSTACLE_AVATAR_GAP_M` apart over the whole duration).

A 20 s walk (26-32 m) gets 10-17 columns and 3-6 obstacles; longer walks get proportionally more,
and walks much shorter than 20 s fit fewer, because spacing rules win over counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import trimesh
from scipy.interpolate import CubicSpline

from camdirector.geometry.transforms import RigidTransform

if TYPE_CHECKING:  # the scene itself needs no GL; only callers that render import it
    from camdirector.geometry.render import OffscreenRenderer

GROUND_HALF_EXTENT_M = 30.0
GROUND_THICKNESS_M = 0.5
# Waypoints stay inside this square so the path (and a camera a few metres off it) stays on the
# ground with room to spare.
PATH_HALF_EXTENT_M = 18.0
# Horizontal radius of a cylinder that contains the avatar's body (shoulders and arms).
AVATAR_RADIUS_M = 0.36
COLUMN_CLEARANCE_M = 1.0
COLUMN_REACH_M = 3.0
OBSTACLE_AVATAR_GAP_M = 0.3
MAX_DURATION_S = 120.0
# Spacing of the stored path samples; fine enough that linear interpolation between them is smooth.
PATH_STEP_M = 0.05

AVATAR_RGB = (0.93, 0.38, 0.12)
COLUMN_RGB = (0.66, 0.64, 0.62)
GROUND_RGB = (0.50, 0.58, 0.44)
OBSTACLE_RGBS = (
    (0.20, 0.42, 0.80),
    (0.14, 0.60, 0.62),
    (0.50, 0.34, 0.72),
    (0.22, 0.30, 0.55),
)


@dataclass
class DemoObject:
    """One rigid mesh of the demo scene.

    vertices: (n, 3) float64, local frame, metres. faces: (m, 3) int32, counter-clockwise seen from
    outside. color_rgb: 3 floats in [0, 1]. transform: world placement (static objects) or
    placement at t = 0 (dynamic ones). checker_m: a rendering hint, the side of a checker pattern
    that makes motion over this surface visible (0 = plain).
    """

    id: str
    kind: str  # "ground", "column", "obstacle" or "avatar"
    vertices: np.ndarray
    faces: np.ndarray
    color_rgb: tuple[float, float, float]
    dynamic: bool
    transform: RigidTransform = field(default_factory=RigidTransform)
    checker_m: float = 0.0


@dataclass
class ObstacleTrack:
    """Back-and-forth motion of one obstacle along a straight segment of the ground.

    position(t) = center_xz + direction_xz * half_length_m * sin(angular_speed_rad_s * t
    + phase_rad): fastest where it crosses the avatar's path, slowing to a stop at either end.
    """

    object_id: str
    center_xz: np.ndarray  # (2,) metres
    direction_xz: np.ndarray  # (2,) unit
    half_length_m: float
    angular_speed_rad_s: float
    phase_rad: float
    footprint_radius_m: float  # horizontal radius of a circle containing the obstacle

    @property
    def endpoints_xz(self) -> np.ndarray:
        """(2, 2) the two ends of the track, metres."""
        offset = self.direction_xz * self.half_length_m
        return np.stack([self.center_xz - offset, self.center_xz + offset])

    @property
    def yaw_rad(self) -> float:
        """Turn about +Y that points the obstacle's local +Z along the track."""
        return math.atan2(self.direction_xz[0], self.direction_xz[1])

    def position_xz(self, time_s: np.ndarray | float) -> np.ndarray:
        """(2,) for a scalar time, (k, 2) for k times."""
        t = np.asarray(time_s, dtype=np.float64)
        along = self.half_length_m * np.sin(self.angular_speed_rad_s * t + self.phase_rad)
        return self.center_xz + along[..., None] * self.direction_xz


@dataclass
class DemoScene:
    """The demo scene and its motion.

    avatar_path_xz: (k, 2) the avatar's path centre line, sampled every `PATH_STEP_M`, from its
    start to where it stands at duration_s. avatar_aim_offset: (3,) point in the avatar's local
    frame that a camera should frame (upper chest, 1.5 m). column_centers_xz: (c, 2);
    column_radii_m: (c,).
    """

    static_objects: list[DemoObject]
    dynamic_objects: list[DemoObject]
    avatar: DemoObject
    avatar_aim_offset: np.ndarray
    duration_s: float
    avatar_speed_m_s: float
    avatar_path_xz: np.ndarray
    avatar_heading_rad: np.ndarray  # (k,) unwrapped yaw along avatar_path_xz
    column_centers_xz: np.ndarray
    column_radii_m: np.ndarray
    obstacle_tracks: list[ObstacleTrack]
    seed: int

    def all_objects(self) -> list[DemoObject]:
        """Static objects, then dynamic ones, then the avatar."""
        return [*self.static_objects, *self.dynamic_objects, self.avatar]

    def avatar_position_xz(self, time_s: np.ndarray | float) -> np.ndarray:
        """(2,) for a scalar time, (k, 2) for k times; the avatar stands still after duration_s."""
        s_m = self._path_arclength_m(time_s)
        x = np.interp(s_m, self._path_s_m, self.avatar_path_xz[:, 0])
        z = np.interp(s_m, self._path_s_m, self.avatar_path_xz[:, 1])
        return np.stack([x, z], axis=-1)

    def avatar_yaw_rad(self, time_s: np.ndarray | float) -> np.ndarray:
        """Turn about +Y that points the avatar's local +Z along its walking direction."""
        return np.interp(self._path_arclength_m(time_s), self._path_s_m, self.avatar_heading_rad)

    def aim_point_world(self, time_s: float) -> np.ndarray:
        """(3,) world position of the avatar's aim point at time_s."""
        return self.transforms_at(time_s)[self.avatar.id].apply(self.avatar_aim_offset[None])[0]

    def transforms_at(self, time_s: float) -> dict[str, RigidTransform]:
        """World transforms of the avatar and of every dynamic object at time_s (seconds)."""
        xz = self.avatar_position_xz(time_s)
        out = {
            self.avatar.id: RigidTransform(
                position_world=np.array([xz[0], 0.0, xz[1]]),
                rotation_xyzw=_yaw_quat(float(self.avatar_yaw_rad(time_s))),
            )
        }
        for track in self.obstacle_tracks:
            p = track.position_xz(time_s)
            out[track.object_id] = RigidTransform(
                position_world=np.array([p[0], 0.0, p[1]]),
                rotation_xyzw=_yaw_quat(track.yaw_rad),
            )
        return out

    @property
    def _path_s_m(self) -> np.ndarray:
        return np.arange(len(self.avatar_path_xz)) * PATH_STEP_M

    def _path_arclength_m(self, time_s: np.ndarray | float) -> np.ndarray:
        t = np.clip(np.asarray(time_s, dtype=np.float64), 0.0, self.duration_s)
        return t * self.avatar_speed_m_s


def build_demo_scene(seed: int = 7, duration_s: float = 20.0, rng: np.random.Generator | None = None) -> DemoScene:
    """The demo scene for `seed` (or for the given generator, which then overrides seed).

    duration_s: walking time in seconds, in (0, MAX_DURATION_S]; the path is as long as the avatar
    walks in that time (1.3-1.6 m/s).
    """
    if not 0.0 < duration_s <= MAX_DURATION_S:
        raise ValueError(f"duration_s must be in (0, {MAX_DURATION_S}], got {duration_s}")
    if rng is None:
        rng = np.random.default_rng(seed)
    speed_m_s = float(rng.uniform(1.3, 1.6))
    path_xz, heading_rad = _avatar_path(rng, speed_m_s * duration_s)

    ground = _ground_object()
    # Obstacles first: their tracks must cross the path, while columns can stand anywhere beside
    # it, so columns are the ones that make room (the other order rejected ~95% of tracks).
    tracks, obstacles = _place_obstacles(rng, path_xz, speed_m_s, duration_s)
    centers_xz, radii_m, columns = _place_columns(rng, path_xz, tracks)
    avatar_mesh = _avatar_mesh()
    avatar = DemoObject(
        id="avatar",
        kind="avatar",
        vertices=avatar_mesh.vertices.astype(np.float64),
        faces=avatar_mesh.faces.astype(np.int32),
        color_rgb=AVATAR_RGB,
        dynamic=True,
    )
    scene = DemoScene(
        static_objects=[ground, *columns],
        dynamic_objects=obstacles,
        avatar=avatar,
        avatar_aim_offset=np.array([0.0, 1.5, 0.0]),
        duration_s=float(duration_s),
        avatar_speed_m_s=speed_m_s,
        avatar_path_xz=path_xz,
        avatar_heading_rad=heading_rad,
        column_centers_xz=centers_xz,
        column_radii_m=radii_m,
        obstacle_tracks=tracks,
        seed=int(seed),
    )
    for object_id, transform in scene.transforms_at(0.0).items():
        next(o for o in scene.all_objects() if o.id == object_id).transform = transform
    return scene


def add_scene_to_renderer(scene: DemoScene, renderer: OffscreenRenderer) -> None:
    """Upload every mesh of the scene to an `OffscreenRenderer`, placed as at t = 0.

    Per frame, only `renderer.set_transform(id, t.matrix())` for `scene.transforms_at(time_s)`.
    """
    for obj in scene.all_objects():
        renderer.add_mesh(obj.id, obj.vertices, obj.faces, obj.color_rgb, checker_m=obj.checker_m)
        renderer.set_transform(obj.id, obj.transform.matrix())


# -- avatar path ---------------------------------------------------------------------------


def _avatar_path(rng: np.random.Generator, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Path of exactly length_m sampled every PATH_STEP_M: ((k, 2) xz, (k,) unwrapped yaw)."""
    start = rng.uniform(-6.0, 6.0, size=2)
    heading = float(rng.uniform(-math.pi, math.pi))
    waypoints = [start - 3.0 * _unit(heading), start]  # a lead-in point fixes the first tangent
    turn_sign = 1.0 if rng.random() < 0.5 else -1.0
    chord_m = 0.0
    # Chords understate the spline's length; stop once they cover the walk plus a margin.
    while chord_m < length_m + 8.0:
        step_m = float(rng.uniform(5.0, 8.0))
        # Mostly alternating turns give S-bends that a follow camera has to work through.
        if rng.random() < 0.7:
            turn_sign = -turn_sign
        turn = turn_sign * float(rng.uniform(0.35, 1.1))
        candidate = waypoints[-1] + step_m * _unit(heading + turn)
        if np.max(np.abs(candidate)) > PATH_HALF_EXTENT_M:
            turn = -turn
            candidate = waypoints[-1] + step_m * _unit(heading + turn)
        if np.max(np.abs(candidate)) > PATH_HALF_EXTENT_M:
            # Both turns leave the area: head back towards the centre, at most 1.2 rad at once.
            to_center = math.atan2(-waypoints[-1][1], -waypoints[-1][0])
            turn = float(np.clip(_wrap(to_center - heading), -1.2, 1.2))
            candidate = waypoints[-1] + step_m * _unit(heading + turn)
        heading += turn
        waypoints.append(candidate)
        chord_m += step_m
    points = np.asarray(waypoints)
    chord_m_each = np.linalg.norm(np.diff(points, axis=0), axis=1)
    chord_param = np.concatenate([[0.0], np.cumsum(chord_m_each)])
    spline = CubicSpline(chord_param, points, axis=0)
    dense = spline(np.linspace(chord_param[1], chord_param[-1], int(chord_param[-1] * 40)))
    arclength = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    s_m = np.arange(0.0, length_m + 0.5 * PATH_STEP_M, PATH_STEP_M)
    path_xz = np.stack([np.interp(s_m, arclength, dense[:, i]) for i in range(2)], axis=1)
    tangent = np.gradient(path_xz, axis=0)
    heading_rad = np.unwrap(np.arctan2(tangent[:, 0], tangent[:, 1]))  # yaw of local +Z
    return path_xz, heading_rad


def _density_scale(path_length_m: float) -> float:
    """Counts of columns and obstacles are set for a ~30 m walk (20 s); longer walks get more so
    the avatar meets as many per metre. Shorter ones keep the counts but fit fewer of them."""
    return max(1.0, path_length_m / 30.0)


def _unit(angle_rad: float) -> np.ndarray:
    return np.array([math.cos(angle_rad), math.sin(angle_rad)])


def _wrap(angle_rad: float) -> float:
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def _yaw_quat(yaw_rad: float) -> np.ndarray:
    """(x, y, z, w) turn of yaw_rad about +Y (w >= 0 like quat_normalize)."""
    q = np.array([0.0, math.sin(yaw_rad / 2.0), 0.0, math.cos(yaw_rad / 2.0)])
    return -q if q[3] < 0.0 else q


def distance_to_polyline(points_xz: np.ndarray, polyline_xz: np.ndarray) -> np.ndarray:
    """(n,) distances from points (n, 2) to the polyline (k, 2), k >= 2, metres."""
    p = np.atleast_2d(points_xz)[:, None, :]  # (n, 1, 2)
    a, b = polyline_xz[:-1], polyline_xz[1:]  # (k-1, 2) segment ends
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=2) / np.maximum(np.sum(ab * ab, axis=1), 1e-18), 0, 1)
    closest = a + t[..., None] * ab  # (n, k-1, 2)
    return np.min(np.linalg.norm(p - closest, axis=2), axis=1)


# -- static geometry -----------------------------------------------------------------------


def _ground_object() -> DemoObject:
    slab = trimesh.creation.box(extents=(2 * GROUND_HALF_EXTENT_M, GROUND_THICKNESS_M, 2 * GROUND_HALF_EXTENT_M))
    slab.apply_translation((0.0, -GROUND_THICKNESS_M / 2.0, 0.0))  # top face at y = 0
    return DemoObject(
        id="ground",
        kind="ground",
        vertices=slab.vertices.astype(np.float64),
        faces=slab.faces.astype(np.int32),
        color_rgb=GROUND_RGB,
        dynamic=False,
        checker_m=2.0,
    )


def _upright_cylinder(radius_m: float, height_m: float, sections: int = 24) -> trimesh.Trimesh:
    """Cylinder along +Y with its base at y = 0 (trimesh builds them along Z, centred)."""
    mesh = trimesh.creation.cylinder(radius=radius_m, height=height_m, sections=sections)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-math.pi / 2, (1, 0, 0)))
    mesh.apply_translation((0.0, height_m / 2.0, 0.0))
    return mesh


def _place_columns(
    rng: np.random.Generator, path_xz: np.ndarray, tracks: list[ObstacleTrack]
) -> tuple[np.ndarray, np.ndarray, list[DemoObject]]:
    """Columns beside the path, off obstacle tracks: ((c, 2) centres, (c,) radii, objects)."""
    track_points = [_sample_segment(track) for track in tracks]  # (32, 2) each
    length_m = (len(path_xz) - 1) * PATH_STEP_M
    count = round(int(rng.integers(12, 17)) * _density_scale(length_m))
    centers: list[np.ndarray] = []
    radii: list[float] = []
    for i in range(count):
        for _attempt in range(60):
            # Spread along the path: column i is drawn beside the i-th stretch of it.
            s_m = rng.uniform(i, i + 1) * length_m / count
            k = min(int(s_m / PATH_STEP_M), len(path_xz) - 2)
            tangent = path_xz[k + 1] - path_xz[k]
            normal = np.array([-tangent[1], tangent[0]]) / np.linalg.norm(tangent)
            radius_m = float(rng.uniform(0.35, 0.5))
            offset_m = radius_m + float(rng.uniform(COLUMN_CLEARANCE_M + 0.2, COLUMN_REACH_M))
            center = path_xz[k] + rng.choice((-1.0, 1.0)) * offset_m * normal
            # The offset is from one path point; on a bend another stretch may come closer.
            if distance_to_polyline(center, path_xz)[0] < radius_m + COLUMN_CLEARANCE_M:
                continue
            if any(np.linalg.norm(center - c) < radius_m + r + 1.5 for c, r in zip(centers, radii)):
                continue
            if any(
                np.min(np.linalg.norm(points - center, axis=1)) < radius_m + track.footprint_radius_m + 0.2
                for points, track in zip(track_points, tracks)
            ):
                continue
            centers.append(center)
            radii.append(radius_m)
            break
    objects = []
    for i, (center, radius_m) in enumerate(zip(centers, radii)):
        mesh = _upright_cylinder(radius_m, float(rng.uniform(3.5, 4.5)))
        objects.append(
            DemoObject(
                id=f"column_{i:02d}",
                kind="column",
                vertices=mesh.vertices.astype(np.float64),
                faces=mesh.faces.astype(np.int32),
                color_rgb=COLUMN_RGB,
                dynamic=False,
                transform=RigidTransform(position_world=np.array([center[0], 0.0, center[1]])),
            )
        )
    return np.asarray(centers).reshape(-1, 2), np.asarray(radii), objects


# -- moving obstacles ----------------------------------------------------------------------


def _place_obstacles(
    rng: np.random.Generator,
    path_xz: np.ndarray,
    speed_m_s: float,
    duration_s: float,
) -> tuple[list[ObstacleTrack], list[DemoObject]]:
    length_m = (len(path_xz) - 1) * PATH_STEP_M
    count = round(int(rng.integers(3, 7)) * _density_scale(length_m))
    times_s = np.linspace(0.0, duration_s, int(duration_s * 20) + 1)  # 50 ms checks
    avatar_xz = np.stack(
        [np.interp(times_s * speed_m_s, np.arange(len(path_xz)) * PATH_STEP_M, path_xz[:, i]) for i in range(2)],
        axis=1,
    )
    tracks: list[ObstacleTrack] = []
    objects: list[DemoObject] = []
    for i in range(count):
        for _attempt in range(80):
            mesh, footprint_m = _obstacle_mesh(rng)
            # Crossing points spread along the path, skipping the first 10% so the start is clear.
            s_m = length_m * (0.1 + 0.9 * rng.uniform(i, i + 1) / count)
            k = min(int(s_m / PATH_STEP_M), len(path_xz) - 2)
            tangent = path_xz[k + 1] - path_xz[k]
            across = math.atan2(tangent[0], -tangent[1]) + rng.uniform(-0.5, 0.5)
            direction = _unit(across)
            half_length_m = float(rng.uniform(3.0, 5.0))
            peak_speed_m_s = float(rng.uniform(0.9, 1.6))
            angular_speed = peak_speed_m_s / half_length_m
            # Cross the path this long before or after the avatar gets there: close enough to
            # come between it and the camera, far enough not to walk through it.
            lead_s = rng.choice((-1.0, 1.0)) * rng.uniform(1.6, 2.6)
            crossing_time_s = s_m / speed_m_s + lead_s
            track = ObstacleTrack(
                object_id=f"obstacle_{i}",
                center_xz=path_xz[k] + rng.uniform(-1.0, 1.0) * direction,
                direction_xz=direction,
                half_length_m=half_length_m,
                angular_speed_rad_s=angular_speed,
                phase_rad=float(-angular_speed * crossing_time_s) % (2 * math.pi),
                footprint_radius_m=footprint_m,
            )
            if _track_is_clear(track, tracks, times_s, avatar_xz):
                tracks.append(track)
                objects.append(
                    DemoObject(
                        id=track.object_id,
                        kind="obstacle",
                        vertices=mesh.vertices.astype(np.float64),
                        faces=mesh.faces.astype(np.int32),
                        color_rgb=OBSTACLE_RGBS[i % len(OBSTACLE_RGBS)],
                        dynamic=True,
                    )
                )
                break
    return tracks, objects


def _obstacle_mesh(rng: np.random.Generator) -> tuple[trimesh.Trimesh, float]:
    """A tall box or cylinder, base at y = 0, and the radius of its footprint's enclosing circle.

    At least 2 m tall so it hides the avatar's chest (1.5 m) from a camera at head height.
    """
    if rng.random() < 0.5:
        width_m, depth_m = rng.uniform(0.7, 1.3, size=2)
        height_m = float(rng.uniform(2.0, 2.8))
        mesh = trimesh.creation.box(extents=(width_m, height_m, depth_m))
        mesh.apply_translation((0.0, height_m / 2.0, 0.0))
        return mesh, float(math.hypot(width_m, depth_m) / 2.0)
    radius_m = float(rng.uniform(0.35, 0.6))
    return _upright_cylinder(radius_m, float(rng.uniform(2.4, 3.2))), radius_m


def _track_is_clear(track: ObstacleTrack, tracks: list[ObstacleTrack], times_s: np.ndarray, avatar_xz: np.ndarray) -> bool:
    """Whether the track stays on the ground, off the other tracks, and off the avatar."""
    segment = _sample_segment(track)  # (32, 2)
    if np.max(np.abs(segment)) > GROUND_HALF_EXTENT_M - 2.0:
        return False
    for other in tracks:
        gap = np.linalg.norm(segment[:, None] - _sample_segment(other)[None], axis=2)
        if np.min(gap) < track.footprint_radius_m + other.footprint_radius_m + 0.3:
            return False
    gap = np.linalg.norm(track.position_xz(times_s) - avatar_xz, axis=1)
    return bool(np.min(gap) >= track.footprint_radius_m + AVATAR_RADIUS_M + OBSTACLE_AVATAR_GAP_M)


def _sample_segment(track: ObstacleTrack) -> np.ndarray:
    """(32, 2) points along the track, at most 0.33 m apart for the 10 m longest track."""
    ends = track.endpoints_xz
    return ends[0] + np.linspace(0.0, 1.0, 32)[:, None] * (ends[1] - ends[0])


# -- avatar --------------------------------------------------------------------------------


def _avatar_mesh() -> trimesh.Trimesh:
    """A 1.8 m humanoid of boxes, capsules and a sphere: feet at y = 0, facing local +Z."""
    parts = []
    for side in (-1.0, 1.0):
        leg = trimesh.creation.box(extents=(0.16, 0.86, 0.20))
        leg.apply_translation((side * 0.11, 0.43, 0.0))
        foot = trimesh.creation.box(extents=(0.14, 0.08, 0.26))
        foot.apply_translation((side * 0.11, 0.04, 0.05))  # toes forward: shows facing
        arm = trimesh.creation.capsule(height=0.52, radius=0.06, count=[8, 8])
        arm.apply_transform(trimesh.transformations.rotation_matrix(-math.pi / 2, (1, 0, 0)))
        arm.apply_translation((side * 0.29, 1.14, 0.0))
        parts += [leg, foot, arm]
    torso = trimesh.creation.box(extents=(0.44, 0.60, 0.24))
    torso.apply_translation((0.0, 1.16, 0.0))
    neck = trimesh.creation.box(extents=(0.10, 0.10, 0.10))
    neck.apply_translation((0.0, 1.50, 0.0))
    head = trimesh.creation.icosphere(subdivisions=2, radius=0.13)
    head.apply_translation((0.0, 1.67, 0.0))
    nose = trimesh.creation.box(extents=(0.05, 0.05, 0.06))
    nose.apply_translation((0.0, 1.66, 0.14))
    parts += [torso, neck, head, nose]
    # trimesh annotates concatenate as returning any Geometry; of Trimesh parts it makes one Trimesh
    return trimesh.util.concatenate(parts)  # type: ignore[return-value]
