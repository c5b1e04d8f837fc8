"""HLTV: the baseline, Valve's SourceTV auto-director rebuilt from its published rules
(hltvdirector.cpp and hltvcamera.cpp of the Source SDK 2013; numbers in settings.HltvSettings).

- Players are ranked every 0.5 s (AnalyzePlayers): for each living player, every other living
  player within 1024 units with a clear line of sight adds WeightedAngle(-forward, other's forward)
  / sqrt(distance), WeightedAngle(u, v) = ((u.v + 1) / 2)^2; the sum is scaled by the length of
  the mean of the others' forwards. Fixed cameras are ranked alike (AnalyzeCameras).
  Lines of sight are checked only at these 0.5 s ranks, never anticipated.
- A shot is chosen when the last one's time is up (StartNewShot). With a delay >= 10 s the
  director reads the next 8 s in four 2-s windows (FindBestGameEvent) and shows the chosen event
  at once, so it cuts 2-4 s before it in the best case, then cuts again 2 s after it; a shot
  that would last under 4 s is not started (the current one is extended). With a shorter delay
  it cannot look ahead (StartInstantBroadcastShot): a random shot every 6 s.
- An event shot (CreateShotFromEvent) is a chase camera behind the victim with the attacker as
  second target, 96 units away, pitch -20, yaw +-30 at random; first person (in the eyes of the
  victim, or of the attacker 70% of the time) for 67% of kills. A random shot (StartRandomShot)
  is a fixed camera 25% of the time, else a chase camera over the best-ranked player's shoulder
  (112 units, pitch 20, yaw +-20) looking toward the player that best faces it.
- The chase camera (C_HLTVCamera::CalcChaseCamView) looks from the first target along the line to
  the second (or along the first's facing), offset by the shot's pitch and yaw, is pulled in
  front of walls (growing back at 32 units/s) and turns its yaw to the two targets' midpoint.

Fixed cameras stand for the level designer's point_viewcontrol entities: the level's camera
graph nodes (at most 64, MAX_NUM_CAMERAS) when there is a level, else a ring around the players'
first bounding box at 4 m and 8 m, placed once per session. A fixed shot looks at its target.
Players' eye points are their aim points; a dead player's is its feet plus 14 units.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import matrix_to_quat
from camdirector.pipeline.inputs import EventKind
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.interest import event_priority
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.plan import Shot
from camdirector.pipeline.match.settings import INCH_M, MatchSettings
from camdirector.pipeline.match.shots import StaticCamera

MAX_FIXED_CAMERAS = 64           # MAX_NUM_CAMERAS
MIN_RANK_DISTANCE_M = 4 * INCH_M  # closer players do not rank each other
DEAD_VIEW_HEIGHT_M = 14 * INCH_M  # VEC_DEAD_VIEWHEIGHT
REGROW_M_S = 32 * INCH_M          # the pulled-in chase camera moves back out this fast
RING_HEIGHTS_M = (4.0, 8.0)
RING_CAMERAS = 8


def weighted_angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """((u.v + 1) / 2)^2 for unit vectors (..., 3): 1 when parallel, 0 when opposite."""
    return ((np.sum(u * v, axis=-1) + 1.0) / 2.0) ** 2


def _direction(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Unit view direction for a Source yaw (about +Y, 0 along +Z) and pitch (positive looks down)."""
    y, p = math.radians(yaw_deg), math.radians(pitch_deg)
    return np.array([math.cos(p) * math.sin(y), -math.sin(p), math.cos(p) * math.cos(y)])


def _angles(direction: np.ndarray) -> tuple[float, float]:
    """(yaw, pitch) deg of a direction (3,), Source convention as _direction."""
    return (math.degrees(math.atan2(direction[0], direction[2])),
            -math.degrees(math.atan2(direction[1], math.hypot(direction[0], direction[2]))))


def look_along(position: np.ndarray, direction: np.ndarray, fov_deg: float) -> CameraPose:
    """The level camera (no roll) at position (3,) m looking along direction (3,); also the
    first-person view of autotrack.py."""
    forward = direction / np.linalg.norm(direction)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= max(np.linalg.norm(right), 1e-9)
    up = np.cross(right, forward)
    return CameraPose(position, matrix_to_quat(np.stack([right, up, -forward], axis=1)), fov_deg)


@dataclass
class ChaseParams:
    distance_m: float
    pitch_deg: float
    yaw_deg: float
    in_eye: bool


class ChaseCamera:
    """HLTV's chase camera (module docstring) on target1, looking toward target2 (None: along
    target1's facing); in_eye puts the camera in target1's eyes."""

    def __init__(self, kind: ShotKind, target1: int, target2: int | None, params: ChaseParams, lens: Lens,
                 ray_scene: RayScene, settings: MatchSettings):
        self.kind, self.target1, self.target2, self.params = kind, target1, target2, params
        self.lens, self.ray_scene, self.hltv = lens, ray_scene, settings.hltv
        self.last_distance_m = params.distance_m

    def _eye(self, moment: Moment, i: int) -> np.ndarray:
        if moment.alive[i]:
            return moment.aims_world[i]
        return moment.feet_world[i] + np.array([0.0, DEAD_VIEW_HEIGHT_M, 0.0])

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        self.last_distance_m += dt_s * REGROW_M_S

    def pose(self, moment: Moment) -> CameraPose:
        eye1 = self._eye(moment, self.target1)
        if self.params.in_eye:
            return look_along(eye1, moment.forward_world[self.target1], self.lens.vertical_fov_deg)
        eye2 = None if self.target2 is None else self._eye(moment, self.target2)
        if eye2 is not None and np.linalg.norm(eye2 - eye1) > 1e-6:
            yaw, pitch = _angles(eye2 - eye1)
        else:
            yaw, pitch = _angles(moment.forward_world[self.target1])
            pitch = 0.0
        pitch_offset = self.hltv.dead_pitch_deg if not moment.alive[self.target1] else self.params.pitch_deg
        forward = _direction(yaw + self.params.yaw_deg, pitch + pitch_offset)
        hit = float(self.ray_scene.first_hit(eye1, -forward[None, :])[0])  # metres: forward is a unit vector
        distance = min(self.params.distance_m, max(hit - self.hltv.wall_margin_m, 0.05))
        if distance > self.last_distance_m:
            distance = self.last_distance_m
        self.last_distance_m = distance
        camera = eye1 - distance * forward
        yaw_look, pitch_look = yaw + self.params.yaw_deg, pitch + pitch_offset
        if eye2 is not None:
            yaw_look = _angles((eye1 + eye2) / 2.0 - camera)[0]
            pitch_look = max(-self.hltv.max_pitch_deg, min(self.hltv.max_pitch_deg, pitch_look))
        return look_along(camera, _direction(yaw_look, pitch_look), self.lens.vertical_fov_deg)


class HltvDirector:
    """The HLTV baseline (module docstring)."""

    def __init__(self, players: list[str], settings: MatchSettings, lens: Lens, ray_scene: RayScene,
                 rng: np.random.Generator, delay_s: float, level_nodes_world: np.ndarray):
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
        return np.array([centre + np.array([radius * math.sin(a), h, radius * math.cos(a)])
                         for h in RING_HEIGHTS_M for a in np.linspace(0.0, math.tau, RING_CAMERAS, endpoint=False)])

    # -- ranking ----------------------------------------------------------------------------
    def _rank_times(self, now_s: float, buffer: MomentBuffer) -> list[float]:
        if not self.look_ahead:
            return [now_s]
        end = min(self.next_shot_s, buffer.horizon_s)
        return list(np.arange(now_s, end, self.hltv.rank_interval_s)) or [now_s]

    def rank_players(self, moment: Moment) -> tuple[np.ndarray, np.ndarray]:
        """(n,) rank and (n,) index of the best-facing other player (-1: none) of one 0.5-s rank."""
        n = len(self.players)
        eyes, forward, alive = moment.aims_world, moment.forward_world, moment.alive
        distance = np.linalg.norm(eyes[:, None] - eyes[None], axis=2)
        pair = alive[:, None] & alive[None, :] & (distance >= MIN_RANK_DISTANCE_M) & (distance <= self.hltv.rank_range_m)
        np.fill_diagonal(pair, False)
        ii, jj = np.nonzero(pair)
        if len(ii):
            pair[ii, jj] = ~self.ray_scene.occluded(eyes[ii], eyes[jj])
        facing = weighted_angle(-forward[:, None, :], forward[None, :, :])          # (n, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            contribution = np.where(pair, facing / np.sqrt(distance / INCH_M), 0.0)
        count = pair.sum(axis=1)
        spread = np.linalg.norm(pair.astype(float) @ forward, axis=1) / np.maximum(count, 1)
        rank = contribution.sum(axis=1) * spread
        best = np.where(count > 0, np.argmax(np.where(pair, facing, -1.0), axis=1), -1)
        return rank, best if n else np.zeros(0, dtype=int)

    def rank_cameras(self, moment: Moment, cameras: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(c,) rank and (c,) index of the closest visible player (-1: none) of fixed cameras (c, 3)."""
        eyes, alive = moment.aims_world, moment.alive
        to_camera = cameras[:, None, :] - eyes[None]                                   # (c, n, 3)
        distance = np.linalg.norm(to_camera, axis=2)
        seen = alive[None, :] & (distance >= MIN_RANK_DISTANCE_M) & (distance <= self.hltv.rank_range_m)
        cc, pp = np.nonzero(seen)
        if len(cc):
            seen[cc, pp] = ~self.ray_scene.occluded(cameras[cc], eyes[pp])
        unit = to_camera / np.maximum(distance, 1e-9)[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            contribution = np.where(seen, weighted_angle(moment.forward_world[None], unit) / np.sqrt(distance / INCH_M),
                                    0.0)
        count = seen.sum(axis=1)
        spread = np.linalg.norm(np.einsum("cn,cnk->ck", seen.astype(float), unit), axis=1) / np.maximum(count, 1)
        closest = np.where(count > 0, np.argmin(np.where(seen, distance, np.inf), axis=1), -1)
        return contribution.sum(axis=1) * spread, closest

    # -- shots ------------------------------------------------------------------------------
    def decide(self, moment: Moment, buffer: MomentBuffer, current: Shot | None,
               current_pose: CameraPose | None, flags: list[str]) -> Shot | None:
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
        if event is not None:
            shot = self._event_shot(event, moment, now)
            if shot is not None:
                self.next_shot_s = min(self.next_shot_s, event.time_s + self.hltv.after_event_s)
                return shot
            flags.append("hltv_no_shot_for_event")
            return None
        return self._random_shot(moment, buffer)

    def _best_event(self, now_s: float, buffer: MomentBuffer):
        """FindBestGameEvent: the best of four 2-s windows by the SDK's cut rules, or None."""
        best, best_priority = [None] * 4, [0] * 4
        for w in range(4):
            till = now_s + self.hltv.event_window_s * (w + 1)
            if till > self.next_shot_s:
                break
            for event in buffer.events_between(now_s + self.hltv.event_window_s * w, till):
                priority = event_priority(event, self.settings)
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

    def _event_shot(self, event, moment: Moment, now_s: float) -> Shot | None:
        """CreateShotFromEvent: kills and damage as a chase on the victim; objectives as a fixed camera."""
        if event.kind == EventKind.OBJECTIVE:
            return self._fixed_shot(moment, force=True, reason="hltv: objective, fixed camera")
        victim, attacker = self.index.get(event.other_actor_id), self.index.get(event.actor_id)
        if event.kind not in (EventKind.KILL, EventKind.DAMAGE) or victim is None:
            return None
        h = self.hltv
        if attacker is None or attacker == victim:
            params = ChaseParams(h.kill_chase_distance_m, -h.kill_chase_pitch_deg, 0.0, False)
            camera = ChaseCamera(ShotKind.FOLLOW, victim, None, params, self.lens, self.ray_scene, self.settings)
            return self._shot(camera, (victim,), ShotKind.FOLLOW, "hltv: death, chase on the victim", now_s)
        in_eye = bool(self.rng.random() < (h.in_eye_kill_chance if event.kind == EventKind.KILL
                                           else 1.0 - h.in_eye_kill_chance))
        if self.rng.random() < (h.swap_chance_in_eye if in_eye else h.swap_chance_chase):
            victim, attacker = attacker, victim
        yaw = h.kill_chase_yaw_deg if self.rng.random() > 0.5 else -h.kill_chase_yaw_deg
        params = ChaseParams(h.kill_chase_distance_m, h.kill_chase_pitch_deg, yaw, in_eye)
        camera = ChaseCamera(ShotKind.DUEL, victim, attacker, params, self.lens, self.ray_scene, self.settings)
        how = "first person of" if in_eye else "chase behind"
        return self._shot(camera, (victim, attacker), ShotKind.DUEL,
                          f"hltv: {event.kind.name.lower()} in {event.time_s - now_s:.1f} s, {how} "
                          f"{self.players[victim]} toward {self.players[attacker]}", now_s)

    def _random_shot(self, moment: Moment, buffer: MomentBuffer) -> Shot | None:
        """StartRandomShot: a fixed camera 25% of the time, else a chase on the best-ranked player."""
        self.next_shot_s = min(self.next_shot_s, moment.time_s + self.hltv.default_shot_s)
        if self.rng.random() < self.hltv.fixed_camera_share:
            return self._fixed_shot(moment, force=False, reason="hltv: random fixed camera", buffer=buffer)
        return self._player_shot(moment, buffer)

    def _player_shot(self, moment: Moment, buffer: MomentBuffer) -> Shot | None:
        """StartBestPlayerCameraShot: the ranks summed over the shot's 0.5-s ranks."""
        total = np.zeros(len(self.players))
        best_rank, best_player, best_target = -1.0, -1, -1
        for t in self._rank_times(moment.time_s, buffer):
            rank, facing = self.rank_players(buffer.at(t))
            total += rank
            i = int(np.argmax(total))
            if total[i] > best_rank and rank[i] > 0.0:
                best_rank, best_player, best_target = float(total[i]), i, int(facing[i])
        if best_player < 0:
            return self._fixed_shot(moment, force=True, reason="hltv: nobody ranked, fixed camera", buffer=buffer)
        h = self.hltv
        yaw = h.player_chase_yaw_deg if self.rng.random() > 0.5 else -h.player_chase_yaw_deg
        params = ChaseParams(h.player_chase_distance_m, h.player_chase_pitch_deg, yaw, False)
        target2 = best_target if best_target >= 0 else None
        camera = ChaseCamera(ShotKind.FOLLOW, best_player, target2, params, self.lens, self.ray_scene, self.settings)
        shot = self._shot(camera, (best_player,), ShotKind.FOLLOW,
                          f"hltv: best-ranked player {self.players[best_player]}", moment.time_s)
        shot.scores = {"rank": best_rank}
        return shot

    def _fixed_shot(self, moment: Moment, force: bool, reason: str, buffer: MomentBuffer | None = None) -> Shot | None:
        """StartBestFixedCameraShot: unforced and nobody seen, a player chase instead."""
        total = np.zeros(len(self.fixed_cameras))
        times = [moment.time_s] if buffer is None else self._rank_times(moment.time_s, buffer)
        target = np.full(len(self.fixed_cameras), -1)
        for t in times:
            rank, closest = self.rank_cameras(buffer.at(t) if buffer is not None else moment, self.fixed_cameras)
            total += rank
            target = np.where(closest >= 0, closest, target)
        best = int(np.argmax(total))
        if not force and total[best] == 0.0 and buffer is not None:
            return self._player_shot(moment, buffer)
        look_at = moment.aims_world[target[best]] if target[best] >= 0 else moment.aims_world.mean(axis=0)
        position = self.fixed_cameras[best]
        if np.linalg.norm(look_at - position) < 1e-6:
            look_at = position + np.array([0.0, 0.0, 1.0])
        pose = look_along(position, look_at - position, self.lens.vertical_fov_deg)
        subjects = (int(target[best]),) if target[best] >= 0 else ()
        shot = self._shot(StaticCamera(pose), subjects, ShotKind.OVERVIEW, reason, moment.time_s)
        shot.scores = {"rank": float(total[best])}
        return shot

    def _shot(self, camera, subjects: tuple[int, ...], kind: ShotKind, reason: str, now_s: float) -> Shot:
        return Shot(ShotChoice(tuple(self.players[i] for i in subjects), kind, reason), subjects, camera, now_s)
