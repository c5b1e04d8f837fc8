"""The camera of each shot kind, and where on its manifold a shot's camera is placed.

DUEL, FOLLOW and GROUP use the Toric framing (toric-space-primer.md; the occlusion-anticipation
paper, section 3): the camera stays on the torus of the two framed points every frame, at a place
(theta as a ratio along the arc, phi about the A-B axis) chosen at the cut:
- DUEL frames the two players, the screen-left one given by the line of action (grammar.py);
- FOLLOW frames one player and a gaze-room point `gaze_room_m` ahead of its smoothed facing,
  horizon level (the level's camera tracks are not used: the Toric rig serves every level);
- GROUP frames the two players of the group farthest apart, at screen points 1.5 times wider than
  the style's, so the others, between them, are in frame too.
OVERVIEW is a static camera high above the players' bounding box looking at its centre.

The place is chosen by ray casting the subjects' sample points from a grid of places, at the cut
and at the moments the shot must cover (with a delay these are buffered future moments: the
occlusion is anticipated by looking at it, section 5's look-ahead done with the real future),
scoring each place by its worst-seen subject (a point counts when it is unoccluded and inside
the frame). While the shot runs, a place that falls under
`min_visible` is replaced by the best one on the same side, and the camera glides there with the
style's response time, so the composition never jumps inside a shot.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens, level_look_rotation, project_to_screen
from camdirector.geometry.toric import (
    DegenerateTorus,
    Torus,
    composition_angle,
    look_rotation,
    make_torus,
    theta_max,
    torus_position,
)
from camdirector.geometry.transforms import UP_WORLD
from camdirector.server.pipeline.match.moments import Moment
from camdirector.server.pipeline.match.visibility import SubjectVisibility
from camdirector.server.pipeline.stages import ShotKind
from camdirector.server.pipeline.style import Style

THETA_MARGIN = 0.04                                     # keep the camera off A and B, ratio of the arc
# The place grid along the arc (the ends are over a shoulder) and about the axis (0 above, 90 level beside).
PLACE_RATIOS = np.array([0.08, 0.15, 0.3, 0.45, 0.6, 0.75, 0.9, 0.95])
PLACE_PHI_RAD = np.radians([30.0, 45.0, 65.0, 80.0, 95.0])
HEADING_TIME_CONSTANT_S = 0.6                           # FOLLOW: smoothing of the facing, as framing.py
GROUP_SCREEN_SCALE = 1.5                                # GROUP: screen points this much wider than the style's
OVERVIEW_HEIGHTS_M = (4.0, 8.0)                         # overview heights tried below overview_height_m
OVERVIEW_AZIMUTHS = 8


@dataclass(frozen=True)
class Place:
    theta_ratio: float  # along the arc, 0 at A .. 1 at B, [0, 1]
    phi_rad: float      # about the A-B axis, rad


class ToricCamera:
    """DUEL, FOLLOW or GROUP: the camera on the torus of points A and B (module docstring).
    a_index, b_index: players; b_index None frames A with gaze room."""

    def __init__(self, kind: ShotKind, a_index: int, b_index: int | None, style: Style, lens: Lens, place: Place):
        self.kind, self.a_index, self.b_index = kind, a_index, b_index
        scale = GROUP_SCREEN_SCALE if kind == ShotKind.GROUP else 1.0
        self.screen_a = tuple(max(-0.9, min(0.9, c * scale)) for c in style.screen_a)
        self.screen_b = tuple(max(-0.9, min(0.9, c * scale)) for c in style.screen_b)
        self.lens, self.gaze_room_m = lens, style.gaze_room_m
        self.alpha = composition_angle(self.screen_a, self.screen_b, lens)
        self.place = self.goal = place
        self.heading: np.ndarray | None = None

    @property
    def side(self) -> float:
        return math.copysign(1.0, self.place.phi_rad)

    def points(self, moment: Moment) -> tuple[np.ndarray, np.ndarray]:
        """The framed points A and B, (3,) each, at the moment."""
        a = moment.aims_world[self.a_index]
        if self.b_index is not None:
            return a, moment.aims_world[self.b_index]
        heading = moment.forward_world[self.a_index] if self.heading is None else self.heading
        return a, a + self.gaze_room_m * heading

    def torus(self, moment: Moment) -> Torus | None:
        try:
            return make_torus(*self.points(moment), self.alpha, UP_WORLD)
        except DegenerateTorus:
            return None

    def positions(self, moment: Moment, places: list[Place]) -> np.ndarray | None:
        """(len(places), 3) camera centres at the moment, None when the framing is degenerate."""
        torus = self.torus(moment)
        if torus is None:
            return None
        span = theta_max(self.alpha) * (1.0 - 2.0 * THETA_MARGIN)
        theta = theta_max(self.alpha) * THETA_MARGIN + span * np.array([p.theta_ratio for p in places])
        return torus_position(torus, theta, np.array([p.phi_rad for p in places]))

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        """Glides the place toward the goal and smooths the FOLLOW heading (time constants, s)."""
        keep = math.exp(-dt_s / response_time_s) if dt_s > 0.0 else 1.0
        dphi = math.remainder(self.goal.phi_rad - self.place.phi_rad, math.tau)
        self.place = Place(self.goal.theta_ratio + keep * (self.place.theta_ratio - self.goal.theta_ratio),
                           self.goal.phi_rad - keep * dphi)
        forward = moment.forward_world[self.a_index]
        if self.heading is None:
            self.heading = forward
        elif dt_s > 0.0:
            blend = self.heading + (1.0 - math.exp(-dt_s / HEADING_TIME_CONSTANT_S)) * (forward - self.heading)
            norm = np.linalg.norm(blend)
            self.heading = blend / norm if norm > 1e-6 else forward

    def pose(self, moment: Moment) -> CameraPose | None:
        positions = self.positions(moment, [self.place])
        return None if positions is None else self.pose_from(moment, positions[0])

    def pose_from(self, moment: Moment, position_world: np.ndarray) -> CameraPose:
        """The camera at a torus point (3,) composing A and B (FOLLOW: A exact, horizon level)."""
        a, b = self.points(moment)
        if self.b_index is None:
            rotation = level_look_rotation(position_world, a, self.screen_a, self.lens)
        else:
            rotation = look_rotation(position_world, a, b, self.screen_a, self.screen_b, self.lens)
        return CameraPose(position_world, rotation, self.lens.vertical_fov_deg)


class StaticCamera:
    """OVERVIEW (and the HLTV baseline's fixed cameras): a pose that does not move during the shot."""

    kind = ShotKind.OVERVIEW

    def __init__(self, pose: CameraPose):
        self.fixed_pose = pose

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        """Nothing moves."""

    def pose(self, moment: Moment) -> CameraPose:
        return self.fixed_pose


def place_grid(side: float | None) -> list[Place]:
    """The places tried: every ratio and phi, on one side (sign of phi) or both when side is None."""
    signs = (1.0, -1.0) if side is None else (side,)
    return [Place(float(r), s * float(p)) for s in signs for r in PLACE_RATIOS for p in PLACE_PHI_RAD]


def best_place(camera: ToricCamera, places: list[Place], moments: list[Moment], subjects: tuple[int, ...],
               visibility: SubjectVisibility, allowed: Callable[[np.ndarray], np.ndarray] | None = None,
               cut_moment: Moment | None = None) -> tuple[Place, float]:
    """The place of `places` whose worst-seen subject is best seen, averaged over `moments`, and
    that score in [0, 1]. allowed: (m, 3) positions at cut_moment -> (m,) bool (the cut's
    grammar); places it refuses score -1. Ties go to the earlier place in the list."""
    score = np.zeros(len(places))
    for moment in moments:
        positions = camera.positions(moment, places)
        if positions is None:
            continue
        seen = visibility.seen_points(positions, moment, subjects)           # (m, s, k)
        points = visibility.points_world(moment, subjects)                  # (s * k, 3)
        for row, position in enumerate(positions):  # a point out of the frame is not seen either
            xy = project_to_screen(camera.pose_from(moment, position), camera.lens, points)
            seen[row] &= (np.abs(xy) <= 1.0).all(axis=1).reshape(seen.shape[1:])
        score += seen.mean(axis=2).min(axis=1)
    score /= max(len(moments), 1)
    if allowed is not None:
        first = camera.positions(cut_moment, places)
        if first is not None:
            score = np.where(allowed(first), score, -1.0)
    best = int(np.argmax(score))
    return places[best], float(score[best])


def overview_pose(moment: Moment, subjects: tuple[int, ...], lens: Lens, visibility: SubjectVisibility,
                  top_height_m: float, extra_cameras_world: np.ndarray) -> tuple[CameraPose, float]:
    """A high view of the subjects' bounding box, looking at its centre, and the share of subjects
    whose aim point it sees. Tries OVERVIEW_AZIMUTHS directions at each height up to top_height_m,
    and the (k, 3) extra camera places (the level's graph nodes, when there is a level) within
    twice the box's viewing distance."""
    aims = moment.aims_world[list(subjects)]
    centre = aims.mean(axis=0)
    radius_m = float(np.max(np.linalg.norm((aims - centre)[:, [0, 2]], axis=1))) + 2.0
    distance_m = radius_m / lens.tan_half_fov_y
    cameras = []
    for height in (*OVERVIEW_HEIGHTS_M, top_height_m):
        for k in range(OVERVIEW_AZIMUTHS):
            azimuth = math.tau * k / OVERVIEW_AZIMUTHS
            horizontal = max(distance_m * math.cos(math.atan2(height, distance_m)), 1.0)
            cameras.append(centre + np.array([horizontal * math.sin(azimuth), height, horizontal * math.cos(azimuth)]))
    cameras = np.array(cameras)
    if len(extra_cameras_world):
        near = np.linalg.norm(extra_cameras_world - centre, axis=1) <= 2.0 * max(distance_m, top_height_m)
        cameras = np.concatenate([cameras, extra_cameras_world[near]])
    targets = np.repeat(aims[None], len(cameras), axis=0).reshape(-1, 3)
    hidden = visibility.ray_scene.occluded(np.repeat(cameras, len(aims), axis=0), targets)
    seen = 1.0 - hidden.reshape(len(cameras), len(aims)).mean(axis=1)
    best = int(np.argmax(seen))
    rotation = level_look_rotation(cameras[best], centre, (0.0, 0.0), lens)
    return CameraPose(cameras[best], rotation, lens.vertical_fov_deg), float(seen[best])
