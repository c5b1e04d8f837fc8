"""HLTV: the baseline, Valve's SourceTV auto-director rebuilt from its published rules
(ValveSoftware/source-sdk-2013: src/game/server/hltvdirector.cpp and src/game/client/hltvcamera.cpp;
numbers in settings.HltvSettings). Source's points are its players' origins, at their feet; its
eyes are 64 units above them (VEC_VIEW), a dead player's 14 (VEC_DEAD_VIEWHEIGHT); here a living
player's eye point is its aim point.

- Players are ranked every 0.5 s (CHLTVDirector::AnalyzePlayers): for each living player, every
  other living player whose feet lie 4 to 1024 units from its feet, in sight, adds
  WeightedAngle(-forward, other's forward) / sqrt(distance), WeightedAngle(u, v) = ((u.v + 1) / 2)^2,
  forwards in 3-D (AngleVectors(EyeAngles())); the sum is scaled by the length of the mean of the
  others' forwards, and the best-facing other player is its target. Fixed cameras are ranked alike
  (AnalyzeCameras): each living player 4 to 1024 units from the camera, in sight, adds
  WeightedAngle(its forward, toward the camera) / sqrt(distance); the closest one is the target.
  "In sight" is Source's UTIL_TraceLine from feet to feet (camera to feet) with MASK_SOLID, which
  ignores only the player traced to: the level and every other living player block it (MASK_SOLID
  holds CONTENTS_MONSTER, which keeps non-brush entities in StandardFilterRules, util_shared.cpp;
  a dead player is not solid, CBasePlayer::Event_Killed, player.cpp:1723), a player as Source's
  32 x 32 x 72-unit hull on its feet (VEC_HULL_MIN/MAX, gamerules.cpp:50). The ranked player's own
  hull, which the trace starts in, does not block (see `rank_players`). Lines of sight are
  checked only at these 0.5 s ranks, never anticipated.
- A shot is chosen when the last one's time is up (StartNewShot). With a delay >= 10 s the
  director reads the next 8 s in four 2-s windows (FindBestGameEvent) and shows the chosen event
  at once, so it cuts 2-4 s before it in the best case, then cuts again 2 s after a kill or a hurt
  (CreateShotFromEvent). It hears only the events it listens for (SetHLTVServer: player_hurt,
  player_death, round_start, round_end, besides its own rank and camera-man events): our DAMAGE,
  KILL and OBJECTIVE, with the SDK's priorities (HltvSettings.priorities) unless the client gave
  one; CUSTOM and UNSPECIFIED events never draw a shot. With a shorter delay it cannot look ahead
  (StartInstantBroadcastShot): a random shot every 6 s.
- An event shot (CreateShotFromEvent): a kill or a hurt is a chase camera behind the victim with
  the attacker as second target, 96 units away, pitch -20, yaw +-30 at random; first person (in
  the eyes of the victim, or of the attacker 70% of the time) for 67% of kills and 33% of hurts.
  A round event is the best fixed camera, unforced. A random shot (StartRandomShot) is the best
  fixed camera, unforced, 25% of the time, else the best player (StartBestPlayerCameraShot): a chase
  over its shoulder (112 units, pitch 20, yaw +-20) looking toward its target. The ranks of the
  shot's 0.5-s ranks are summed in the order Source's event list holds them (each rank in a random
  order of the players, InitRandomOrder); the best is the first to reach the highest sum, from -1,
  so a player ranked 0 is still followed; only with no living player in the whole shot is the
  best fixed camera forced instead. Unforced, a fixed camera whose best sum is 0 gives way to the
  best player (StartBestFixedCameraShot).
- The chase camera (C_HLTVCamera::CalcChaseCamView) looks from the first target along the line to
  the second (or along the first's horizontal facing), offset by the shot's pitch and yaw (a dead
  first target's pitch offset is 15), is pulled in front of walls (a 6-unit box swept back from
  the eye, UTIL_TraceHull; growing back at 32 units/s) and turns its yaw to the two targets'
  midpoint, its pitch clamped to 60, its angles smoothed (SmoothCameraAngle). First person
  (CalcInEyeCamView) is the target's eye point and 3-D view; a dead target is shown by the chase
  view instead. A fixed camera (CalcFixedView) turns, smoothed, toward its living target's eye.

Fixed cameras stand for the level designer's point_viewcontrol entities: the level's camera
graph nodes (at most 64, MAX_NUM_CAMERAS) when there is a level, else a ring around the players'
first bounding box at 4 m and 8 m, placed once per session.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import quat_to_matrix
from camdirector.pipeline.inputs import EventKind, GameEvent
from camdirector.pipeline.match.director_contract import DirectorBase
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.look_along import look_along
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import Shot, ShotCamera
from camdirector.pipeline.match.settings import INCH_M, HltvSettings, MatchSettings

MAX_FIXED_CAMERAS = 64  # MAX_NUM_CAMERAS
MIN_RANK_DISTANCE_M = 4 * INCH_M  # closer players do not rank each other
DEAD_VIEW_HEIGHT_M = 14 * INCH_M  # VEC_DEAD_VIEWHEIGHT
REGROW_M_S = 32 * INCH_M  # the pulled-in chase camera moves back out this fast
HULL_HALF_WIDTH_M = 16 * INCH_M  # VEC_HULL_MIN/MAX: a player blocks traces as a 32 x 32 x 72-unit box
HULL_HEIGHT_M = 72 * INCH_M
# Source's origins rest on the floor and its traces count a point on a plane as outside; a ray
# lying in a floor's plane is a coin toss for Embree, so rank traces run one unit above the feet.
TRACE_LIFT_M = INCH_M
MIN_SMOOTHING = 0.01  # SmoothCameraAngle's least step, of the gap
RING_HEIGHTS_M = (4.0, 8.0)
RING_CAMERAS = 8
BOX_CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))  # (8, 3) of a unit half-width box


def weighted_angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """((u.v + 1) / 2)^2 for unit vectors (..., 3): 1 when parallel, 0 when opposite."""
    weight: np.ndarray = ((np.sum(u * v, axis=-1) + 1.0) / 2.0) ** 2
    return weight


def _direction(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Unit view direction for a Source yaw (about +Y, 0 along +Z) and pitch (positive looks down)."""
    y, p = math.radians(yaw_deg), math.radians(pitch_deg)
    return np.array([math.cos(p) * math.sin(y), -math.sin(p), math.cos(p) * math.cos(y)])


def _angles(direction: np.ndarray) -> tuple[float, float]:
    """(yaw, pitch) deg of a direction (3,), Source convention as _direction."""
    return (
        math.degrees(math.atan2(direction[0], direction[2])),
        -math.degrees(math.atan2(direction[1], math.hypot(direction[0], direction[2]))),
    )


def smooth_angles(
    angles: tuple[float, float], goal: tuple[float, float], dt_s: float, inertia_per_s: float
) -> tuple[float, float]:
    """(yaw, pitch) deg moved toward goal by clamp(dt * inertia, 0.01, 1) of the gap, yaw the short
    way round (C_HLTVCamera::SmoothCameraAngle). Source slerps the two rotations
    (InterpolateAngles, cdll_util.cpp); interpolating yaw and pitch instead keeps the view free of roll."""
    step = min(max(dt_s * inertia_per_s, MIN_SMOOTHING), 1.0)
    yaw_gap = (goal[0] - angles[0] + 180.0) % 360.0 - 180.0
    return angles[0] + step * yaw_gap, angles[1] + step * (goal[1] - angles[1])


def eye_forward(moment: Moment) -> np.ndarray:
    """(n, 3) unit 3-D view directions, the transforms' local +Z (AngleVectors(EyeAngles()), pitch
    included; Moment.forward_world is its horizontal part)."""
    rotations = np.array([t.rotation_xyzw for t in moment.transforms], dtype=np.float64).reshape(-1, 4)
    return quat_to_matrix(rotations)[..., 2]


def player_hulls(feet_world: np.ndarray, grow_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Low and high corners (n, 3) m of the players' hulls (HULL_*) standing on feet (n, 3),
    grown by grow_m on every side (a box swept against a hull: the hull grown by the box)."""
    half = np.array([HULL_HALF_WIDTH_M + grow_m, grow_m, HULL_HALF_WIDTH_M + grow_m])
    return feet_world - half, feet_world + half + np.array([0.0, HULL_HEIGHT_M, 0.0])


def box_entry(origins: np.ndarray, deltas: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Ray parameter t >= 0 (in units of delta) where each ray origin + t delta enters each axis-
    aligned box [low, high], all (..., 3) broadcast together: 0 when it starts inside (Source's
    startsolid), inf when it misses. The slab method."""
    inside_slab = (origins >= low) & (origins <= high)
    parallel = deltas == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        t_low, t_high = (low - origins) / deltas, (high - origins) / deltas
    near = np.where(parallel, np.where(inside_slab, -np.inf, np.inf), np.minimum(t_low, t_high)).max(axis=-1)
    far = np.where(parallel, np.where(inside_slab, np.inf, -np.inf), np.maximum(t_low, t_high)).min(axis=-1)
    entry: np.ndarray = np.where((near <= far) & (far >= 0.0), np.maximum(near, 0.0), np.inf)
    return entry


def _eye(moment: Moment, i: int) -> np.ndarray:
    """A player's eye point (3,) m: its aim point, or its feet plus VEC_DEAD_VIEWHEIGHT when dead."""
    eye: np.ndarray = moment.aims_world[i] if moment.alive[i] else moment.feet_world[i] + np.array([0.0, DEAD_VIEW_HEIGHT_M, 0.0])
    return eye


@dataclass
class ChaseParams:
    distance_m: float
    pitch_deg: float
    yaw_deg: float
    in_eye: bool


class ChaseCamera:
    """HLTV's chase camera (module docstring) on target1, looking toward target2 (None: along
    target1's facing); in_eye puts the camera in target1's eyes while it lives. `advance` runs
    one frame of C_HLTVCamera::CalcChaseCamView (or CalcInEyeCamView); `pose` reads it."""

    def __init__(
        self,
        kind: ShotKind,
        target1: int,
        target2: int | None,
        params: ChaseParams,
        lens: Lens,
        ray_scene: RayScene,
        settings: MatchSettings,
    ):
        self.kind, self.target1, self.target2, self.params = kind, target1, target2, params
        self.lens, self.ray_scene, self.hltv = lens, ray_scene, settings.hltv
        self.last_distance_m = params.distance_m
        self.angles: tuple[float, float] | None = None  # the shown (yaw, pitch), deg; None: snap at the next frame
        self._pose: CameraPose | None = None
        self._time_s: float | None = None

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        self._pose, self._time_s = self._frame(moment, dt_s), moment.time_s

    def pose(self, moment: Moment) -> CameraPose:
        if self._pose is None or self._time_s != moment.time_s:
            self.advance(moment, 0.0, 0.0)
        assert self._pose is not None  # advanced to the moment
        return self._pose

    def _frame(self, moment: Moment, dt_s: float) -> CameraPose:
        t1, fov = self.target1, self.lens.vertical_fov_deg
        eye1 = _eye(moment, t1)
        if self.params.in_eye and moment.alive[t1]:
            self.angles = None  # back in the chase view (the target died) the angles are set anew
            return look_along(eye1, eye_forward(moment)[t1], fov)
        eye2 = None if self.target2 is None else _eye(moment, self.target2)
        if eye2 is not None and np.linalg.norm(eye2 - eye1) > 1e-6:
            yaw, pitch = _angles(eye2 - eye1)
        else:
            yaw, pitch = _angles(moment.forward_world[t1])
            pitch = 0.0
        pitch_offset = self.hltv.dead_pitch_deg if not moment.alive[t1] else self.params.pitch_deg
        yaw, pitch = yaw + self.params.yaw_deg, pitch + pitch_offset
        forward = _direction(yaw, pitch)
        distance = self._clear_distance(moment, eye1, -forward)
        self.last_distance_m += dt_s * REGROW_M_S
        if distance > self.last_distance_m:
            distance = self.last_distance_m
        self.last_distance_m = distance
        camera = eye1 - distance * forward
        if eye2 is None:
            self.angles = (yaw, pitch)  # SetCameraAngle: no smoothing with one target
        else:
            goal = (_angles((eye1 + eye2) / 2.0 - camera)[0], max(-self.hltv.max_pitch_deg, min(self.hltv.max_pitch_deg, pitch)))
            self.angles = goal if self.angles is None else smooth_angles(self.angles, goal, dt_s, self.hltv.angle_inertia_per_s)
        return look_along(camera, _direction(*self.angles), fov)

    def _clear_distance(self, moment: Moment, eye: np.ndarray, back: np.ndarray) -> float:
        """How far m the camera may stand from eye (3,) along the unit direction back (3,): the
        shot's distance, or where a box of half width wall_hull_half_m swept from the eye first
        touches the level or another living player (UTIL_TraceHull ignoring target1, MASK_SOLID).
        The level is cast with nine parallel rays, from the box's centre and corners, which is exact
        for flat walls (a box first touches a plane with a corner) and may miss an edge poking
        between them; a player's hull grown by the box is exact."""
        h = self.hltv.wall_hull_half_m
        starts = eye + np.vstack([np.zeros((1, 3)), h * BOX_CORNERS])
        level_m = float(self.ray_scene.first_hit(starts, np.tile(back, (len(starts), 1))).min())
        low, high = player_hulls(moment.feet_world, grow_m=h)
        solid = moment.alive.copy()
        solid[self.target1] = False
        players_m = box_entry(eye, back, low[solid], high[solid])
        return min(self.params.distance_m, level_m, float(players_m.min()) if len(players_m) else math.inf)


class FixedCamera:
    """A fixed camera's shot (C_HLTVCamera::CalcFixedView): at position (3,) m, with no roll; while
    its target (a player index, or None) lives it turns toward the target's eye point, smoothed by
    SmoothCameraAngle (snapping at its first frame, as a new target does in SetPrimaryTarget);
    while the target is dead it holds its last direction. It starts looking at look_at (3,) m (the
    level's camera entity would bring its own angles; ours have none). Implements the camera
    interface of shots.StaticCamera."""

    kind = ShotKind.OVERVIEW

    def __init__(self, position: np.ndarray, target: int | None, look_at: np.ndarray, lens: Lens, hltv: HltvSettings):
        self.position, self.target, self.lens, self.hltv = position, target, lens, hltv
        toward = look_at - position
        self.angles = _angles(toward) if np.linalg.norm(toward) > 1e-6 else (0.0, 0.0)
        self._turned = False

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        if self.target is None or not moment.alive[self.target]:
            return
        toward = moment.aims_world[self.target] - self.position
        if np.linalg.norm(toward) < 1e-6:
            return
        goal = _angles(toward)
        self.angles = smooth_angles(self.angles, goal, dt_s, self.hltv.angle_inertia_per_s) if self._turned else goal
        self._turned = True

    def pose(self, moment: Moment) -> CameraPose:
        if not self._turned:
            self.advance(moment, 0.0, 0.0)
        return look_along(self.position, _direction(*self.angles), self.lens.vertical_fov_deg)


class HltvDirector(DirectorBase):
    """The HLTV baseline (module docstring)."""

    def __init__(
        self,
        players: list[str],
        settings: MatchSettings,
        lens: Lens,
        ray_scene: RayScene,
        rng: np.random.Generator,
        delay_s: float,
        level_nodes_world: np.ndarray,
    ):
        self.players, self.settings, self.hltv = players, settings, settings.hltv
        self.index = {p: i for i, p in enumerate(players)}
        self.lens, self.ray_scene, self.rng = lens, ray_scene, rng
        self.look_ahead = delay_s >= self.hltv.min_director_delay_s
        self.next_shot_s = -math.inf
        nodes = np.asarray(level_nodes_world, dtype=np.float64).reshape(-1, 3)
        step = max(1, math.ceil(len(nodes) / MAX_FIXED_CAMERAS))
        self.fixed_cameras: np.ndarray | None = nodes[::step] if len(nodes) else None

    def _ring(self, moment: Moment) -> np.ndarray:
        centre = moment.feet_world.mean(axis=0)
        radius = float(np.max(np.linalg.norm((moment.feet_world - centre)[:, [0, 2]], axis=1))) + 2.0
        return np.array(
            [
                centre + np.array([radius * math.sin(a), h, radius * math.cos(a)])
                for h in RING_HEIGHTS_M
                for a in np.linspace(0.0, math.tau, RING_CAMERAS, endpoint=False)
            ]
        )

    # -- ranking ----------------------------------------------------------------------------
    def _rank_times(self, now_s: float, buffer: MomentBuffer) -> list[float]:
        if not self.look_ahead:
            return [now_s]
        end = min(self.next_shot_s, buffer.horizon_s)
        return list(np.arange(now_s, end, self.hltv.rank_interval_s)) or [now_s]

    def _in_sight(self, moment: Moment, starts: np.ndarray, ends: np.ndarray, passable: np.ndarray) -> np.ndarray:
        """(m,) bool: whether each segment starts (m, 3) -> ends (m, 3) m crosses neither the level
        nor the hull of a living player other than those marked in passable (m, n) bool."""
        clear = ~self.ray_scene.occluded(starts, ends)
        low, high = player_hulls(moment.feet_world)
        entry = box_entry(starts[:, None], (ends - starts)[:, None], low[None], high[None])  # (m, n)
        seen: np.ndarray = clear & ~((entry < 1.0) & moment.alive[None, :] & ~passable).any(axis=1)
        return seen

    def rank_players(self, moment: Moment) -> tuple[np.ndarray, np.ndarray]:
        """(n,) rank and (n,) index of the best-facing other player (-1: none) of one 0.5-s rank
        (CHLTVDirector::AnalyzePlayers; a dead player has no rank). The trace from a player's feet
        starts inside its own hull, which Source's box clip would call solid from the start
        (IntersectRayWithBox, collisionutils.cpp) and every rank 0; whether the engine skips it is
        not in the SDK, and the director's ranking means something only if it does, so it is skipped."""
        n = len(self.players)
        feet, alive = moment.feet_world + np.array([0.0, TRACE_LIFT_M, 0.0]), moment.alive
        forward = eye_forward(moment)
        distance = np.linalg.norm(feet[:, None] - feet[None], axis=2)
        pair = alive[:, None] & alive[None, :] & (distance >= MIN_RANK_DISTANCE_M) & (distance <= self.hltv.rank_range_m)
        np.fill_diagonal(pair, False)
        ii, jj = np.nonzero(pair)
        if len(ii):
            passable = np.zeros((len(ii), n), dtype=bool)
            passable[np.arange(len(ii)), ii] = passable[np.arange(len(ii)), jj] = True
            pair[ii, jj] = self._in_sight(moment, feet[ii], feet[jj], passable)
        facing = weighted_angle(-forward[:, None, :], forward[None, :, :])  # (n, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            contribution = np.where(pair, facing / np.sqrt(distance / INCH_M), 0.0)
        count = pair.sum(axis=1)
        spread = np.linalg.norm(pair.astype(float) @ forward, axis=1) / np.maximum(count, 1)
        rank = contribution.sum(axis=1) * spread
        faced = np.where(pair, facing, 0.0)
        best = np.where(faced.max(axis=1, initial=0.0) > 0.0, np.argmax(faced, axis=1), -1)  # facing > 0, first of ties
        return rank, best

    def rank_cameras(self, moment: Moment, cameras: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(c,) rank and (c,) index of the closest visible player (-1: none) of fixed cameras (c, 3)
        (CHLTVDirector::AnalyzeCameras)."""
        n = len(self.players)
        feet, alive = moment.feet_world + np.array([0.0, TRACE_LIFT_M, 0.0]), moment.alive
        to_camera = cameras[:, None, :] - feet[None]  # (c, n, 3)
        distance = np.linalg.norm(to_camera, axis=2)
        seen = alive[None, :] & (distance >= MIN_RANK_DISTANCE_M) & (distance <= self.hltv.rank_range_m)
        cc, pp = np.nonzero(seen)
        if len(cc):
            passable = np.zeros((len(cc), n), dtype=bool)
            passable[np.arange(len(cc)), pp] = True
            seen[cc, pp] = self._in_sight(moment, cameras[cc], feet[pp], passable)
        unit = to_camera / np.maximum(distance, 1e-9)[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            contribution = np.where(seen, weighted_angle(eye_forward(moment)[None], unit) / np.sqrt(distance / INCH_M), 0.0)
        count = seen.sum(axis=1)
        spread = np.linalg.norm(np.einsum("cn,cnk->ck", seen.astype(float), unit), axis=1) / np.maximum(count, 1)
        closest = np.where(count > 0, np.argmin(np.where(seen, distance, np.inf), axis=1), -1)
        return contribution.sum(axis=1) * spread, closest

    def _best_ranked(self, ranks: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> tuple[int, float, int]:
        """(best, its summed rank, its target) of ranks, one (rank (k,), target (k,), fired (k,) bool)
        per 0.5-s rank in time order, as StartBestPlayerCameraShot / StartBestFixedCameraShot sum
        the rank events: each rank's events in a random order (AnalyzePlayers' InitRandomOrder), the
        best the first to pass the best sum so far, which starts at -1 (so a 0 counts), its target
        that of the event that made it best. (-1, -1.0, -1) when no event fired."""
        best, best_rank, best_target = -1, -1.0, -1
        total = np.zeros(len(ranks[0][0])) if ranks else np.zeros(0)
        for rank, target, fired in ranks:
            for i in self.rng.permutation(np.flatnonzero(fired)):
                total[i] += rank[i]
                if total[i] > best_rank:
                    best, best_rank, best_target = int(i), float(total[i]), int(target[i])
        return best, best_rank, best_target

    # -- shots ------------------------------------------------------------------------------
    def decide(
        self, moment: Moment, buffer: MomentBuffer, current: Shot | None, current_pose: CameraPose | None, flags: list[str]
    ) -> Shot | None:
        now = moment.time_s
        if self.fixed_cameras is None:
            self.fixed_cameras = self._ring(moment)
        if current is not None and now < self.next_shot_s:
            return None
        if not self.look_ahead:  # StartInstantBroadcastShot
            self.next_shot_s = now + self.hltv.max_shot_s
            return self._random_shot(moment, buffer)
        self.next_shot_s = now + self.hltv.max_shot_s
        event = self._best_event(now, buffer)
        if event is None:
            return self._random_shot(moment, buffer)
        shot = self._event_shot(event, moment, buffer)
        if shot is None:
            flags.append("hltv_no_shot_for_event")
        return shot

    def event_priority(self, event: GameEvent) -> int:
        """The event's priority to this director: 0 (never heard) unless its kind is one of
        HltvSettings.priorities; then the client's when it gave one, else the SDK's."""
        if event.kind not in self.hltv.priorities:
            return 0
        return event.priority if event.priority > 0 else self.hltv.priorities[event.kind]

    def _best_event(self, now_s: float, buffer: MomentBuffer) -> GameEvent | None:
        """FindBestGameEvent: the best of four 2-s windows by the SDK's cut rules, or None."""
        best: list[GameEvent | None] = [None] * 4
        best_priority = [0] * 4
        for w in range(4):
            till = now_s + self.hltv.event_window_s * (w + 1)
            if till > self.next_shot_s:
                break
            for event in buffer.events_between(now_s + self.hltv.event_window_s * w, till):
                priority = self.event_priority(event)
                if priority > best_priority[w]:
                    best[w], best_priority[w] = event, priority
        p = best_priority
        if not (p[0] or p[1] or p[2]):
            return None
        if p[1] >= p[0] and p[1] >= p[2] and p[1] >= p[3]:
            return best[1]
        if p[0] > p[1] and p[0] > p[2]:
            return best[0]
        if p[2] > p[3]:
            return best[2]
        return best[0]

    def _event_shot(self, event: GameEvent, moment: Moment, buffer: MomentBuffer) -> Shot | None:
        """CreateShotFromEvent: a round event as the best fixed camera, unforced (the next cut stays
        8 s away); a kill or a hurt as a chase on the victim, the next cut 2 s after it."""
        now_s = moment.time_s
        if event.kind == EventKind.OBJECTIVE:
            return self._fixed_shot(moment, force=False, reason="hltv: objective, fixed camera", buffer=buffer)
        victim, attacker = self.index.get(event.other_actor_id), self.index.get(event.actor_id)
        if victim is None:
            return None
        self.next_shot_s = min(self.next_shot_s, event.time_s + self.hltv.after_event_s)
        h = self.hltv
        if attacker is None or attacker == victim:
            params = ChaseParams(h.kill_chase_distance_m, -h.kill_chase_pitch_deg, 0.0, False)
            camera = ChaseCamera(ShotKind.FOLLOW, victim, None, params, self.lens, self.ray_scene, self.settings)
            return self._shot(camera, (victim,), ShotKind.FOLLOW, "hltv: death, chase on the victim", now_s)
        in_eye = bool(self.rng.random() < (h.in_eye_kill_chance if event.kind == EventKind.KILL else 1.0 - h.in_eye_kill_chance))
        if self.rng.random() < (h.swap_chance_in_eye if in_eye else h.swap_chance_chase):
            victim, attacker = attacker, victim
        yaw = h.kill_chase_yaw_deg if self.rng.random() > 0.5 else -h.kill_chase_yaw_deg
        params = ChaseParams(h.kill_chase_distance_m, h.kill_chase_pitch_deg, yaw, in_eye)
        camera = ChaseCamera(ShotKind.DUEL, victim, attacker, params, self.lens, self.ray_scene, self.settings)
        how = "first person of" if in_eye else "chase behind"
        return self._shot(
            camera,
            (victim, attacker),
            ShotKind.DUEL,
            f"hltv: {event.kind.name.lower()} in {event.time_s - now_s:.1f} s, {how} "
            f"{self.players[victim]} toward {self.players[attacker]}",
            now_s,
        )

    def _random_shot(self, moment: Moment, buffer: MomentBuffer) -> Shot | None:
        """StartRandomShot: the best fixed camera (unforced) 25% of the time, else the best player."""
        self.next_shot_s = min(self.next_shot_s, moment.time_s + self.hltv.default_shot_s)
        if self.rng.random() < self.hltv.fixed_camera_share:
            return self._fixed_shot(moment, force=False, reason="hltv: random fixed camera", buffer=buffer)
        return self._player_shot(moment, buffer)

    def _player_shot(self, moment: Moment, buffer: MomentBuffer) -> Shot | None:
        """StartBestPlayerCameraShot: the best of the shot's 0.5-s ranks (_best_ranked), however
        low; with no living player in them, the best fixed camera, forced."""
        ranks = []
        for t in self._rank_times(moment.time_s, buffer):
            ranked = buffer.at(t)
            ranks.append((*self.rank_players(ranked), ranked.alive))
        best_player, best_rank, best_target = self._best_ranked(ranks)
        if best_player < 0:
            return self._fixed_shot(moment, force=True, reason="hltv: nobody alive, fixed camera", buffer=buffer)
        h = self.hltv
        yaw = h.player_chase_yaw_deg if self.rng.random() > 0.5 else -h.player_chase_yaw_deg
        params = ChaseParams(h.player_chase_distance_m, h.player_chase_pitch_deg, yaw, False)
        target2 = best_target if best_target >= 0 else None
        camera = ChaseCamera(ShotKind.FOLLOW, best_player, target2, params, self.lens, self.ray_scene, self.settings)
        shot = self._shot(
            camera, (best_player,), ShotKind.FOLLOW, f"hltv: best-ranked player {self.players[best_player]}", moment.time_s
        )
        shot.scores = {"rank": best_rank}
        return shot

    def _fixed_shot(self, moment: Moment, force: bool, reason: str, buffer: MomentBuffer) -> Shot | None:
        """StartBestFixedCameraShot: the best of the shot's 0.5-s camera ranks (_best_ranked);
        unforced and its sum 0 (no camera sees anyone), the best player instead."""
        cameras = self.fixed_cameras
        assert cameras is not None  # placed at the first decision
        ranks = []
        for t in self._rank_times(moment.time_s, buffer):
            rank, closest = self.rank_cameras(buffer.at(t), cameras)
            ranks.append((rank, closest, np.ones(len(cameras), dtype=np.bool_)))
        best, best_rank, target = self._best_ranked(ranks)
        if not force and best_rank == 0.0:
            return self._player_shot(moment, buffer)
        subject = target if target >= 0 else None
        look_at = _eye(moment, subject) if subject is not None else moment.aims_world.mean(axis=0)
        camera = FixedCamera(cameras[best], subject, look_at, self.lens, self.hltv)
        shot = self._shot(camera, () if subject is None else (subject,), ShotKind.OVERVIEW, reason, moment.time_s)
        shot.scores = {"rank": best_rank}
        return shot

    def _shot(self, camera: ShotCamera, subjects: tuple[int, ...], kind: ShotKind, reason: str, now_s: float) -> Shot:
        return Shot(ShotChoice(tuple(self.players[i] for i in subjects), kind, reason), subjects, camera, now_s)
