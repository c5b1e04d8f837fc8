"""Measurement of a directed camera, independent of the rig that directed it.

What the paper measures (section 6, "Comparisons are performed as a post-process"), and what we
add so that a rig that leaves the torus (REACTIVE) is measured on the same terms:

- visibility, per frame: the fraction of target mesh vertices (every distinct vertex of every
  target mesh, in the world frame at that frame) that a viewer of the frame sees: the vertex is
  inside the camera's view frustum (geometry.camera.in_frame: the frame at the scenario's lens,
  vertical field of view of the pose, the lens's aspect, in front of the near plane
  `NEAR_PLANE_M`) and its segment from the camera centre crosses no scene object. Pooled over the
  vertices of all targets, so 1 is both targets fully visible and 0 both hidden.
  The paper counts rays only ("1 ray per vertex on each target"): its three methods all stay on
  the Toric surface, so the targets are always framed and the frustum test changes nothing for
  them. REACTIVE pulls the camera toward A, where the ray test alone scores a close-up of a
  shoulder as fully visible; the frustum test is what a viewer sees, rig-independent and the same
  for every mode. The ray-only fraction is kept as `line_of_sight` (the paper's number).
  A camera inside an object sees nothing: its rays start inside a closed mesh and hit its inner
  faces (Embree culls no back faces).
  Scene objects are every static and dynamic object of the scenario; targets do not occlude
  themselves or each other (as in the server's own estimate). Ray casting with Embree
  (geometry.raycast.RayScene): the static objects in one scene built once; each dynamic object in
  its own scene, moved by its transform, and only queried when its bounding sphere comes within
  reach of a ray (a parked, not yet spawned object never is).
- composition, per frame: how far each framed point lands from where the style puts it, in
  normalised screen units (the frame is [-1, 1] on both axes): A's aim point from screen_a, and
  with two targets B's aim point from screen_b (with one target B is the rig's gaze-room point,
  which is not the scene's to measure). NaN where the point is behind the camera. And the camera's
  distance to A's aim point, m: the shot size, which the toric rigs hold and REACTIVE shortens.
- smoothness: camera speed |p[i] - p[i-1]| / (t[i] - t[i-1]) (m/s, at frame i >= 1) and the
  magnitude of the acceleration by central second differences,
  |v[i, i+1] - v[i-1, i]| / ((t[i+1] - t[i-1]) / 2) (m/s^2, at frames 1 .. n-2). An interval that
  ends on a cut is a teleport, not motion: speeds and accelerations that use it are NaN and left
  out of the statistics; cuts are counted instead.
- cost: the server's compute_ms per frame and diagnostics.stage_ms per pipeline stage.

Stale replies (a frame the server did not advance on) are dropped before measuring.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from camdirector.evaluation.scenario import Actor, Scenario, Timeline, transform_at
from camdirector.geometry.camera import CameraPose, Lens, in_frame, project_to_screen
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.style import Style
from camdirector.v1 import director_pb2 as pb


@dataclass(eq=False)
class CameraTrack:
    """The camera a server answered, frame by frame (stale replies dropped). n frames."""

    frame: np.ndarray  # (n,) int64 frame numbers
    time_s: np.ndarray  # (n,) s
    position: np.ndarray  # (n, 3) m, camera centre
    rotation: np.ndarray  # (n, 4) xyzw camera-to-world
    vertical_fov_deg: np.ndarray  # (n,)
    cut: np.ndarray  # (n,) bool
    shot_id: np.ndarray  # (n,) int64
    rig_visibility: np.ndarray  # (n,) the server's own estimate, [0, 1]
    compute_ms: np.ndarray  # (n,)
    stage_ms: dict[str, np.ndarray]  # stage name -> (n,), NaN where a frame did not report it
    flags: dict[str, int] = field(default_factory=dict)  # diagnostics flag -> frames that raised it
    stale: int = 0  # stale replies dropped

    @classmethod
    def from_updates(cls, updates: list[pb.CameraUpdate]) -> CameraTrack:
        fresh = [u for u in updates if not u.stale]
        stages = sorted({k for u in fresh for k in u.diagnostics.stage_ms})
        flags: dict[str, int] = {}
        for u in fresh:
            for flag in set(u.diagnostics.flags):
                flags[flag] = flags.get(flag, 0) + 1
        p = [u.pose.position for u in fresh]
        q = [u.pose.rotation for u in fresh]
        return cls(
            frame=np.array([u.frame for u in fresh], dtype=np.int64),
            time_s=np.array([u.time_s for u in fresh], dtype=np.float64),
            position=np.array([[v.x, v.y, v.z] for v in p], dtype=np.float64).reshape(-1, 3),
            rotation=np.array([[v.x, v.y, v.z, v.w] for v in q], dtype=np.float64).reshape(-1, 4),
            vertical_fov_deg=np.array([u.pose.vertical_fov_deg for u in fresh], dtype=np.float64),
            cut=np.array([u.cut for u in fresh], dtype=bool),
            shot_id=np.array([u.shot_id for u in fresh], dtype=np.int64),
            rig_visibility=np.array([u.visibility for u in fresh], dtype=np.float64),
            compute_ms=np.array([u.compute_ms for u in fresh], dtype=np.float64),
            stage_ms={s: np.array([u.diagnostics.stage_ms.get(s, math.nan) for u in fresh]) for s in stages},
            flags=flags,
            stale=len(updates) - len(fresh),
        )

    def __len__(self) -> int:
        return len(self.frame)


def _bounding_sphere(mesh: TriMesh) -> tuple[np.ndarray, float]:
    """Centre (3,) of the local bounding box and the radius (m) that holds every vertex."""
    centre = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
    return centre, float(np.linalg.norm(mesh.vertices - centre, axis=1).max())


class VisibilityMeter:
    """Ray casts from a camera centre to every vertex of the targets, against the scenario's objects."""

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.lens = Lens(**scenario.lens)  # the server's defaults where the scenario gives none
        static = [a for a in scenario.objects if not a.dynamic]
        self.static = RayScene(
            [
                TriMesh(RigidTransform(a.position, a.rotation, a.scale).apply(a.shape.mesh.vertices), a.shape.mesh.faces)
                for a in static
            ]
        )
        self.dynamic: list[Actor] = [a for a in scenario.objects if a.dynamic]
        self._dynamic_scenes: list[RayScene] = []
        spheres = []
        for a in self.dynamic:
            scene = RayScene([])
            scene.add_dynamic(a.id, a.shape.mesh, RigidTransform(a.position, a.rotation, a.scale))
            self._dynamic_scenes.append(scene)
            spheres.append(_bounding_sphere(a.shape.mesh))
        self._sphere_centre_local = np.array([c for c, _ in spheres]).reshape(-1, 3)
        self._sphere_radius_local = np.array([r for _, r in spheres])
        self.target_vertices_local = [np.unique(a.shape.mesh.vertices, axis=0) for a in scenario.targets]

    def visible_fractions(self, pose: CameraPose, timeline: Timeline, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Per target (k,) at timeline frame `index`: the fraction of its vertices in the frame of
        `pose` and unobstructed from its centre, and the fraction unobstructed (the paper's rays only)."""
        points = [transform_at(timeline, a, index).apply(v) for a, v in zip(self.scenario.targets, self.target_vertices_local)]
        counts = np.cumsum([len(p) for p in points])[:-1]
        points_world = np.concatenate(points)
        clear = ~self.hidden(pose.position_world, points_world, timeline, index)
        seen = clear & in_frame(pose, self.lens, points_world)
        return (np.array([s.mean() for s in np.split(seen, counts)]), np.array([c.mean() for c in np.split(clear, counts)]))

    def hidden(self, camera_world: np.ndarray, points_world: np.ndarray, timeline: Timeline, index: int) -> np.ndarray:
        """(n,) bool: whether the segment from camera_world (3,) to each point (n, 3) is blocked."""
        camera_world = np.asarray(camera_world, dtype=np.float64)
        hidden = self.static.occluded(camera_world, points_world)
        if not self.dynamic:
            return hidden
        transforms = [transform_at(timeline, a, index) for a in self.dynamic]
        centres = np.array([t.apply(c[None, :])[0] for t, c in zip(transforms, self._sphere_centre_local)])
        radii = self._sphere_radius_local * np.array([np.abs(t.scale).max() for t in transforms])
        d = points_world - camera_world  # (n, 3)
        w = centres - camera_world  # (m, 3)
        along = np.clip((w @ d.T) / np.maximum((d * d).sum(axis=1), 1e-12), 0.0, 1.0)  # (m, n)
        gap = np.linalg.norm(centres[:, None, :] - (camera_world + along[:, :, None] * d[None, :, :]), axis=2)
        near = gap <= radii[:, None]  # (m, n)
        for k in np.flatnonzero(near.any(axis=1)):
            rays = near[k] & ~hidden
            if not rays.any():
                continue
            scene = self._dynamic_scenes[k]
            scene.set_transform(self.dynamic[k].id, transforms[k])
            hidden[rays] = scene.occluded(camera_world, points_world[rays])
        return hidden


@dataclass(eq=False)
class VisibilitySeries:
    """Per-frame visibility of a track (n frames, k targets)."""

    pooled: np.ndarray  # (n,) in frame and unobstructed, pooled over all target vertices
    per_target: np.ndarray  # (n, k) the same per target
    line_of_sight: np.ndarray  # (n,) unobstructed only, pooled (the paper's measure)


def _poses(track: CameraTrack) -> list[CameraPose]:
    return [CameraPose(p, q, float(f)) for p, q, f in zip(track.position, track.rotation, track.vertical_fov_deg)]


def measure_visibility(
    scenario: Scenario, timeline: Timeline, track: CameraTrack, meter: VisibilityMeter | None = None
) -> VisibilitySeries:
    """Visibility at every frame of the track (see the module docstring)."""
    meter = meter or VisibilityMeter(scenario)
    counts = np.array([len(v) for v in meter.target_vertices_local], dtype=np.float64)
    per_target = np.empty((len(track), len(scenario.targets)))
    clear = np.empty_like(per_target)
    for i, (frame, pose) in enumerate(zip(track.frame, _poses(track))):
        per_target[i], clear[i] = meter.visible_fractions(pose, timeline, int(frame) - 1)
    pool = (lambda f: f @ counts / counts.sum()) if len(track) else (lambda f: np.empty(0))
    return VisibilitySeries(pool(per_target), per_target, pool(clear))


def measure_composition(scenario: Scenario, timeline: Timeline, track: CameraTrack) -> tuple[np.ndarray, np.ndarray]:
    """(composition error (n,), distance to A (n,) m) at every frame of the track.

    The error is the largest, over A (and B with two targets), of the distance in normalised
    screen units between where the target's aim point lands and where the style puts it
    (screen_a, screen_b; the server's defaults where the scenario's style gives none); NaN where
    an aim point is behind the camera. The distance is from the camera centre to A's aim point."""
    lens = Lens(**scenario.lens)
    style = Style()
    wanted = [scenario.style.get("screen_a", style.screen_a), scenario.style.get("screen_b", style.screen_b)]
    index = track.frame.astype(np.int64) - 1
    error = np.zeros(len(track))
    distance = np.full(len(track), np.nan)
    for k, (actor, screen) in enumerate(zip(scenario.targets, wanted)):
        aims = np.array([transform_at(timeline, actor, int(i)).apply(actor.aim_offset[None, :])[0] for i in index])
        landed = np.array(
            [
                project_to_screen(pose, Lens(pose.vertical_fov_deg, lens.aspect), aim[None])[0]
                for pose, aim in zip(_poses(track), aims)
            ]
        )
        error = np.maximum(error, np.linalg.norm(landed.reshape(-1, 2) - np.asarray(screen), axis=1))  # NaN stays NaN
        if k == 0:
            distance = np.linalg.norm(track.position - aims.reshape(-1, 3), axis=1)
    return error, distance


def camera_kinematics(time_s: np.ndarray, position: np.ndarray, cut: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Speed (n,) m/s and acceleration magnitude (n,) m/s^2 by finite differences; NaN where
    undefined (speed at frame 0, acceleration at the ends, intervals of zero length or ending on a
    cut). time_s: (n,) s; position: (n, 3) m; cut: (n,) bool, cut[i] = a teleport from i-1 to i."""
    t = np.asarray(time_s, dtype=np.float64)
    p = np.asarray(position, dtype=np.float64)
    n = len(t)
    speed, accel = np.full(n, np.nan), np.full(n, np.nan)
    if n < 2:
        return speed, accel
    dt = np.diff(t)
    ok = dt > 0.0
    if cut is not None:
        ok &= ~np.asarray(cut, dtype=bool)[1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.where(ok[:, None], np.diff(p, axis=0) / dt[:, None], np.nan)  # (n-1, 3), interval i -> i+1
        speed[1:] = np.linalg.norm(v, axis=1)
        if n >= 3:
            accel[1:-1] = np.linalg.norm(v[1:] - v[:-1], axis=1) / (0.5 * (t[2:] - t[:-2]))
    return speed, accel


def summarize(values: np.ndarray) -> dict[str, float | int | None]:
    """Median, quartiles, mean, extremes and p99 of the finite values; None entries when there are none."""
    x = np.asarray(values, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"n": 0, "median": None, "q1": None, "q3": None, "mean": None, "min": None, "max": None, "p99": None}
    q1, med, q3, p99 = np.percentile(x, [25, 50, 75, 99])
    return {
        "n": int(x.size),
        "median": float(med),
        "q1": float(q1),
        "q3": float(q3),
        "mean": float(x.mean()),
        "min": float(x.min()),
        "max": float(x.max()),
        "p99": float(p99),
    }


@dataclass(eq=False)
class Measurement:
    """Per-frame series (n frames answered) and their summary."""

    track: CameraTrack
    visibility: np.ndarray  # (n,) pooled, in frame and unobstructed, [0, 1]
    visibility_per_target: dict[str, np.ndarray]  # target id -> (n,)
    line_of_sight: np.ndarray  # (n,) pooled, unobstructed only (the paper's rays), [0, 1]
    composition_error: np.ndarray  # (n,) normalised screen units, see measure_composition
    distance_to_a_m: np.ndarray  # (n,) m
    speed_m_s: np.ndarray  # (n,)
    accel_m_s2: np.ndarray  # (n,)
    target_position: dict[str, np.ndarray]  # target id -> (n, 3) m, at the answered frames

    @property
    def cuts(self) -> int:
        """Cuts after the first answered frame (which always opens a shot)."""
        return int(self.track.cut[1:].sum())

    def summary(self) -> dict:
        track = self.track
        compute = summarize(track.compute_ms)
        return {
            "frames": len(track),
            "stale": track.stale,
            "simulated_s": float(track.time_s[-1] - track.time_s[0]) if len(track) else 0.0,
            "visibility": summarize(self.visibility),
            "visibility_per_target": {k: summarize(v) for k, v in self.visibility_per_target.items()},
            # share of frames where some target vertex is not seen: tells apart runs whose
            # visibility is 1 in most frames (the median and quartiles then all read 1)
            "occluded_share": float(np.mean(self.visibility < 1.0 - 1e-9)) if len(track) else None,
            "line_of_sight": summarize(self.line_of_sight),
            "composition_error": summarize(self.composition_error),
            "distance_to_a_m": summarize(self.distance_to_a_m),
            "speed_m_s": summarize(self.speed_m_s),
            "accel_m_s2": summarize(self.accel_m_s2),
            "cuts": self.cuts,
            "shots": int(len(np.unique(track.shot_id))),
            "rig_visibility": summarize(track.rig_visibility),
            "compute_ms": {"p50": compute["median"], "p99": compute["p99"], "mean": compute["mean"], "max": compute["max"]},
            "stage_ms_median": {k: summarize(v)["median"] for k, v in track.stage_ms.items()},
            "stage_ms_mean": {k: summarize(v)["mean"] for k, v in track.stage_ms.items()},
            "stage_ms_sd": {k: _sd(v) for k, v in track.stage_ms.items()},  # Table 3 gives mean (sd)
            "flags": dict(track.flags),
        }

    def series(self) -> dict:
        """Per-frame series, JSON-ready (NaN as null)."""
        t = self.track
        return {
            "frame": t.frame.tolist(),
            "time_s": _json_list(t.time_s),
            "visibility": _json_list(self.visibility),
            "visibility_per_target": {k: _json_list(v) for k, v in self.visibility_per_target.items()},
            "line_of_sight": _json_list(self.line_of_sight),
            "composition_error": _json_list(self.composition_error),
            "distance_to_a_m": _json_list(self.distance_to_a_m),
            "rig_visibility": _json_list(t.rig_visibility),
            "speed_m_s": _json_list(self.speed_m_s),
            "accel_m_s2": _json_list(self.accel_m_s2),
            "cut": t.cut.tolist(),
            "shot_id": t.shot_id.tolist(),
            "camera_position": _json_list(t.position),
            "camera_rotation_xyzw": _json_list(t.rotation),
            "target_position": {k: _json_list(v) for k, v in self.target_position.items()},
            "compute_ms": _json_list(t.compute_ms),
            "stage_ms": {k: _json_list(v) for k, v in t.stage_ms.items()},
        }


def _sd(values: np.ndarray) -> float | None:
    x = np.asarray(values, dtype=np.float64)
    x = x[np.isfinite(x)]
    return float(x.std()) if x.size else None


def _json_list(a: np.ndarray) -> list:
    """Nested lists of floats with 6 significant digits, NaN as None."""
    a = np.asarray(a, dtype=np.float64)
    if a.ndim > 1:
        return [_json_list(row) for row in a]
    return [float(f"{x:.6g}") if math.isfinite(x) else None for x in a.tolist()]


def measure(scenario: Scenario, timeline: Timeline, track: CameraTrack, meter: VisibilityMeter | None = None) -> Measurement:
    """Visibility, speed and acceleration of a camera track filmed over the scenario's timeline."""
    if len(track) and (track.frame.min() < 1 or track.frame.max() > len(timeline)):
        raise ValueError(f"track frames {track.frame.min()}..{track.frame.max()} are outside the timeline (1..{len(timeline)})")
    seen = measure_visibility(scenario, timeline, track, meter)
    composition, distance = measure_composition(scenario, timeline, track)
    speed, accel = camera_kinematics(track.time_s, track.position, track.cut)
    index = track.frame - 1
    return Measurement(
        track=track,
        visibility=seen.pooled,
        visibility_per_target={a.id: seen.per_target[:, k] for k, a in enumerate(scenario.targets)},
        line_of_sight=seen.line_of_sight,
        composition_error=composition,
        distance_to_a_m=distance,
        speed_m_s=speed,
        accel_m_s2=accel,
        target_position={a.id: timeline.position[a.id][index] for a in scenario.targets},
    )
