"""What the TRACKS rig's frames show of its actor: the frame-aware measure of every tracks
evaluation (`camdirector eval-graph`, `load_tests.tracks_bench`, the TRACKS tests).

The same measure as the Toric evaluation (evaluation/toric/measure.py), on the tracks rig's own frames:

- the actor's body is a capsule `ACTOR_RADIUS_FRACTION` of its height in radius and its height
  tall, standing on its feet (the route's position); its distinct vertices are the sample points,
  as the Toric evaluation samples its targets' mesh vertices. 0.15 of the height is a shoulder
  half-width (a 1.8 m person is about 0.5 m across), and the director frames the same girth
  (DirectorSettings.actor_radius_fraction); the measure keeps its own constant so that it does
  not move with the rig it measures;
- the pose is the rig's (pipeline/tracks/rig.py, `shot_pose`): the director's camera
  looking at its look-at point with no roll, at the lens's vertical field of view, the lens the
  server's default `Lens()` and the director's settings `DirectorSettings(vertical_fov_deg=...)`
  of that lens, as a session without a lens gets them;
- per frame, over the points of the shot size's framed extent (framing.FRAMED_EXTENT: the points
  whose height above the feet is within (low, high) of the height: the whole body for long and
  extreme long, the waist up for medium, whose legs are out of the frame by design and would
  otherwise make every good medium shot count as half hidden): `visible`, the share inside the
  frame (geometry.camera.in_frame: the frustum and the near plane) and unoccluded (rays from the
  camera centre through a RayScene of the level; the body does not occlude itself);
  `line_of_sight`, the share unoccluded, rays only (the paper's number, and what these tools
  counted before); `framed_in_frame`, whether every one of them is inside the frame, whatever
  hides it;
- over a route: the share of frames with `visible` and `line_of_sight` at least
  `VISIBLE_FRACTION`, the share of frames with `framed_in_frame`, cuts (after the first frame,
  which always opens a shot), cuts per minute of route, the per-frame target-update time (cut
  check and target update, ms) and the median framing error (framing.framing_error, normalised
  screen units). A frame where the director has no camera yet (no track near the actor) shows
  nothing: not visible, not framed, its framing error infinite.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from camdirector.evaluation.tracks.route import ActorRoute
from camdirector.geometry.camera import CameraPose, Lens, in_frame, level_look_rotation
from camdirector.geometry.meshes import capsule
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.style import Movement, ShotSize
from camdirector.pipeline.tracks.director import DirectorStyle, GraphDirector
from camdirector.pipeline.tracks.settings import DirectorSettings
from camdirector.pipeline.tracks.shot_sizes import FRAMED_EXTENT, framing_error
from camdirector.precompute.tracks.artifact import LevelArtifact

ACTOR_RADIUS_FRACTION = 0.15  # the measured body's radius, fraction of its height (module docstring)
VISIBLE_FRACTION = 0.5  # a frame counts as showing the actor when this share of its points is seen
_HEIGHT_TOLERANCE_M = 1e-9  # points on an extent's ends (the feet's pole) stay in it despite rounding


@dataclass(frozen=True)
class ActorBody:
    """The measured actor: points_local (n, 3) float64 m, the capsule's distinct vertices with its
    feet at the origin and +Y up; height_m, its height."""

    points_local: np.ndarray
    height_m: float

    @classmethod
    def of_height(cls, height_m: float) -> ActorBody:
        mesh = capsule(ACTOR_RADIUS_FRACTION * height_m, height_m)  # centred on its origin
        return cls(np.unique(mesh.vertices, axis=0) + [0.0, 0.5 * height_m, 0.0], float(height_m))

    def framed(self, shot_size: ShotSize) -> np.ndarray:
        """(n,) bool: the points of the shot size's framed extent."""
        low, high = FRAMED_EXTENT[shot_size]
        y = self.points_local[:, 1]
        return (y >= low * self.height_m - _HEIGHT_TOLERANCE_M) & (y <= high * self.height_m + _HEIGHT_TOLERANCE_M)


@dataclass(frozen=True)
class FrameView:
    """What one frame shows of the actor (module docstring): visible and line_of_sight are shares
    of the body's points in [0, 1]."""

    visible: float
    line_of_sight: float
    framed_in_frame: bool


def shot_pose(position_world: np.ndarray, look_at_world: np.ndarray, lens: Lens) -> CameraPose:
    """The TRACKS rig's pose of a director shot: from position_world (3,) m looking at
    look_at_world (3,) m at the screen centre, no roll, the lens's vertical field of view."""
    return CameraPose(
        np.asarray(position_world, dtype=np.float64),
        level_look_rotation(position_world, look_at_world, (0.0, 0.0), lens),
        lens.vertical_fov_deg,
    )


def frame_view(
    pose: CameraPose, lens: Lens, feet_world: np.ndarray, body: ActorBody, shot_size: ShotSize, scene: RayScene
) -> FrameView:
    """What the frame of `pose` shows of the body standing on feet_world (3,) m; scene: the level
    (and any occluders) the rays cross."""
    points = body.points_local[body.framed(shot_size)] + np.asarray(feet_world, dtype=np.float64)
    framed = in_frame(pose, lens, points)
    clear = ~scene.occluded(pose.position_world, points)
    return FrameView(
        visible=float((framed & clear).mean()), line_of_sight=float(clear.mean()), framed_in_frame=bool(framed.all())
    )


def visible_share(views: list[FrameView]) -> float:
    """Share of the frames whose view shows the actor: `visible` at least VISIBLE_FRACTION."""
    return float(np.mean([v.visible >= VISIBLE_FRACTION for v in views]))


def measure_route(
    artifact: LevelArtifact,
    route: ActorRoute,
    scene: RayScene,
    rng: np.random.Generator,
    style: DirectorStyle = DirectorStyle(),
    lens: Lens = Lens(),
) -> dict:
    """A GraphDirector of `style` along the route, measured frame by frame (module docstring).
    scene: a RayScene of the artifact's level. Returns the route's numbers, JSON-ready, and
    'camera_path' (k, 3) m, the camera of the k frames that had one."""
    settings = DirectorSettings(vertical_fov_deg=lens.vertical_fov_deg)
    director = GraphDirector(artifact, settings, rng, style)
    body = ActorBody.of_height(artifact.agent_height_m)
    target_list_ms: list[float] = []
    camera_list_ms: list[float] = []
    views: list[FrameView] = []
    errors: list[float] = []
    path: list[np.ndarray] = []
    cuts = 0
    for i, (t, feet, forward) in enumerate(zip(route.time_s, route.position_world, route.forward_world)):
        shot = director.step(float(t), feet, forward, scene)
        if shot is None:
            views.append(FrameView(0.0, 0.0, False))
            errors.append(np.inf)
            continue
        target_list_ms.append(shot.timings_ms["cut_check"] + shot.timings_ms["target_update"])
        camera_list_ms.append(shot.timings_ms["camera_update"])
        cuts += bool(shot.cut and i > 0)
        pose = shot_pose(shot.position_world, shot.look_at_world, lens)
        views.append(frame_view(pose, lens, feet, body, style.shot_size, scene))
        error = framing_error(pose, lens, feet, body.height_m, style.shot_size, director.screen_fraction())
        errors.append(error if np.isfinite(error) else np.inf)  # an end behind the camera: the worst framing
        path.append(shot.position_world)
    target_ms, camera_ms = np.asarray(target_list_ms), np.asarray(camera_list_ms)
    minutes = float(route.time_s[-1] - route.time_s[0]) / 60.0 if len(route.time_s) > 1 else 0.0

    def timing(values: np.ndarray, statistic) -> float | None:
        return float(statistic(values)) if len(values) else None

    return {
        "frames": len(views),
        "visible": visible_share(views),
        "line_of_sight": float(np.mean([v.line_of_sight >= VISIBLE_FRACTION for v in views])),
        "framed_in_frame": float(np.mean([v.framed_in_frame for v in views])),
        "cuts": cuts,
        "cuts_per_min": cuts / minutes if minutes > 0.0 else None,
        "target_update_ms_median": timing(target_ms, np.median),
        "target_update_ms_mean": timing(target_ms, np.mean),
        "target_update_ms_std": timing(target_ms, np.std),
        "camera_update_ms_median": timing(camera_ms, np.median),
        "camera_update_ms_mean": timing(camera_ms, np.mean),
        "camera_update_ms_std": timing(camera_ms, np.std),
        "framing_error_median": float(np.median(errors)),
        "camera_path": np.asarray(path, dtype=np.float64).reshape(-1, 3),
    }


def measure_shot_sizes(
    artifact: LevelArtifact, route: ActorRoute, scene: RayScene, new_rng: Callable[[], np.random.Generator], lens: Lens = Lens()
) -> dict[str, dict]:
    """`measure_route` of the director (dynamic with cuts) in every shot size along one route,
    by ShotSize value, each run with a generator from new_rng (called once per shot size, in
    ShotSize order); the runs' camera paths are left out."""
    out = {}
    for size in ShotSize:
        run = measure_route(artifact, route, scene, new_rng(), DirectorStyle(size, Movement.DYNAMIC_WITH_CUTS), lens)
        out[size.value] = {k: v for k, v in run.items() if k != "camera_path"}
    return out
