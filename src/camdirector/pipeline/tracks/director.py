"""Runtime graph director (Section 5): per frame, a camera position, look-at point and cut flag
for one actor on a precomputed level.

Each frame (Section 5's loop):
1. direct visibility of the actor from the current camera (rays to points up the actor through
   the caller's RayScene, dynamic occluders included) and the framing check feed the cutting
   strategy (cutting.py); styles without cuts skip it. The framing holds at a place within
   `framing_violation_log` of the optimal distance from which the shot size's framed extent
   fits in the frame (framing.py), and it is violated when neither the camera nor the target it
   is moving to holds it (a camera still gliding to a good target is not cut away from);
2. on a cut, a new target is searched among all POIs near the actor without the edge filter,
   scored by shot size, direct and indirect visibility and the two continuity sub-scores, and
   only cuts that keep the 30-degree rule and the line of action are taken (continuity.py), and
   only to a POI that sees the actor (direct visibility at least `occluded_below_fraction`, now,
   midway and ahead). Cuts go first to POIs that hold the framing with room to spare, now and
   ahead; then, for a static camera that crops the actor, to POIs where its framed extent fits
   (a shot too wide beats a cropped one); only a cut for occlusion or for want of a target
   falls back to any other. If none qualifies the cut waits for a later frame (a cut to a place as bad
   cut again a second later: 83-118 cuts a minute in medium shots, framing cuts into walls,
   and a cut at the framing tolerance's edge followed by another 0.3 s later). Direct
   visibility, here and in the moving strategy, is the worse of what a place sees of the actor
   now and `visibility_lookahead_s` ahead on its velocity: a place the actor is about to walk
   out of sight of is not chosen. Without a cut the target moves by the target moving strategy
   (target_search.py): POIs strongly connected to the current target, four weighted
   sub-scores, then a local descent along the POI's edge in steps of `descent_step_m`. No POI
   at all is a reason to cut;
3. the camera jumps to the target on a cut, else follows it by the force model
   (camera_motion.py, with the target's velocity, never nearer than its shot size fits: it goes
   round the actor); static cameras stay on their node and only pan. The camera aims at the
   shot size's framed extent, centred (framing.py's `aim_point`): the look-at point it returns
   is that aim, not the fixed point up the actor the scores use.

Styles (Section 6.1), switchable between frames by `set_style`: the shot size (medium, long,
extreme long: the actor's on-screen height) and the movement (dynamic without cuts, dynamic with
cuts, static cameras with cuts). The candidate radius is the larger of `candidate_radius_m` and
1.5 times the style's optimal distance, so an extreme long shot finds tracks far enough away.

The shot-size sub-score is the paper's Gaussian in the log distance ratio, times a factor that
falls from 1 to 0 as the framed extent's fit ratio (framing.py, with `frame_margin`) goes past 1
by `fit_softness`: a place too close to frame the shot size scores as a wrong shot size.

Scores are averages weighted by the settings' weights; to keep a frame cheap only the
`_SCORED_POIS` POIs best on the two sub-scores that need no ray or search (shot size, indirect
visibility) get the direct-visibility rays and the A* distance.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import UP_WORLD
from camdirector.infra.stage_clock import StageClock
from camdirector.pipeline.stages import TracksStage
from camdirector.pipeline.style import Movement, ShotSize
from camdirector.pipeline.tracks.camera_motion import move_camera
from camdirector.pipeline.tracks.continuity import (
    action_direction,
    cut_angle_deg,
    keeps_line_of_action,
    line_of_action_score,
    screen_motion,
    thirty_degree_score,
)
from camdirector.pipeline.tracks.cutting import CutClock, CutReason, draw_shot_duration_s
from camdirector.pipeline.tracks.graph_search import RuntimeGraph
from camdirector.pipeline.tracks.settings import DirectorSettings
from camdirector.pipeline.tracks.shot_sizes import FRAMED_EXTENT, aim_point, fit_ratio, framed_ends_world
from camdirector.pipeline.tracks.target_search import (
    IndirectVisibility,
    Pois,
    candidate_pois,
    direct_visibility,
    graph_distance,
    optimal_distance_m,
    shot_size_score,
)
from camdirector.precompute.tracks.artifact import LevelArtifact

_Floats = npt.NDArray[np.float64]  # points (3,) and (k, 3), scores (k,) and (N,)
_SCORED_POIS = 48
# cuts that cannot wait for a place that frames: the actor is hidden, or the camera has no track left
_MUST_LEAVE = (CutReason.OCCLUSION, CutReason.NO_TARGET)


@dataclass(frozen=True)
class DirectorStyle:
    shot_size: ShotSize = ShotSize.LONG
    movement: Movement = Movement.DYNAMIC_WITH_CUTS


@dataclass(frozen=True)
class TrackShot:
    """One frame's camera: position_world and look_at_world (3,) metres (look_at_world: the point
    to put at the screen centre, which centres the shot size's framed extent); cut: this frame starts a
    new shot; shot_id: counts shots from 0; visible_fraction: share of the actor's sample points
    seen from position_world; cut_reason: why the shot started (None inside a shot); timings_ms:
    'cut_check', 'target_update', 'camera_update'; scores: the sub-scores in [0, 1] of the target
    chosen this frame and their weighted 'total' (the target moving strategy's shot_size,
    direct_visibility, indirect_visibility and graph_distance; on a cut, the continuity search's,
    with thirty_degree and line_of_action after the first shot); empty when no target was chosen."""

    position_world: _Floats
    look_at_world: _Floats
    cut: bool
    shot_id: int
    visible_fraction: float
    cut_reason: CutReason | None
    timings_ms: dict[str, float]
    scores: dict[str, float] = field(default_factory=dict)


def _scored(index: int, **scores: _Floats) -> dict[str, float]:
    """Each sub-score array's value for the candidate at `index`, rounded for reports."""
    return {name: round(float(values[index]), 4) for name, values in scores.items()}


class GraphDirector:
    """Follows one actor on a level's camera navigation graph (module docstring). clock: seconds,
    any origin, for the step's timings (the session's injected clock in the server)."""

    def __init__(
        self,
        artifact: LevelArtifact,
        settings: DirectorSettings,
        rng: np.random.Generator,
        style: DirectorStyle = DirectorStyle(),
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.graph = RuntimeGraph(artifact.nodes_world, artifact.edges)
        centroids = (
            artifact.refined_vertices[artifact.refined_faces].mean(axis=1) if len(artifact.refined_faces) else np.empty((0, 3))
        )
        self._indirect = IndirectVisibility(centroids, artifact.visibility)
        self._actor_height_m = artifact.agent_height_m
        self._actor_radius_m = settings.actor_radius_fraction * artifact.agent_height_m
        self._settings = settings
        self._rng = rng
        self._now = clock
        self._style = style
        self._fractions = np.asarray(settings.actor_sample_fractions, dtype=np.float64)
        self._target: tuple[int, int, float] | None = None
        self._camera: _Floats | None = None
        self._velocity = np.zeros(3)
        self._last_target: _Floats | None = None  # (3,) the target of the last frame, for its velocity
        self._clock: CutClock | None = None
        self._shot_id = -1
        self._last_time_s: float | None = None
        self._last_actor: _Floats | None = None
        self._actor_velocity = np.zeros(3)
        self._scores: dict[str, float] = {}  # of the target chosen in the current step

    @property
    def style(self) -> DirectorStyle:
        return self._style

    def set_style(self, style: DirectorStyle) -> None:
        """Takes effect from the next frame; the current shot goes on."""
        self._style = style

    def screen_fraction(self) -> float:
        s = self._settings
        return {
            ShotSize.MEDIUM: s.medium_shot_screen_fraction,
            ShotSize.LONG: s.long_shot_screen_fraction,
            ShotSize.EXTREME_LONG: s.extreme_long_shot_screen_fraction,
        }[self._style.shot_size]

    def nearest_m(self, frame_margin: float) -> float:
        """The distance under which the shot size's framed extent, centred, no longer fits with
        frame_margin (normalised screen units): its span over twice the margin's tangent, plus the
        actor's girth, m."""
        low, high = FRAMED_EXTENT[self._style.shot_size]
        tangent = (1.0 - frame_margin) * np.tan(np.radians(self._settings.vertical_fov_deg) / 2.0)
        return float((high - low) * self._actor_height_m / (2.0 * tangent) + self._actor_radius_m)

    def repulsion_radius_m(self) -> float:
        """How near the actor pushes the moving camera away, m: the settings' radius, or farther,
        where the shot size no longer fits with the frame margin (a medium camera kept 1 m away
        stood too close for the waist-up to fit); the camera never comes nearer than where it
        fits with none (camera_motion.py)."""
        return max(self._settings.repulsion_radius_m, self.nearest_m(self._settings.frame_margin))

    def optimal_distance_m(self) -> float:
        return optimal_distance_m(self._actor_height_m, self.screen_fraction(), self._settings.vertical_fov_deg)

    def step(
        self, time_s: float, actor_position_world: npt.ArrayLike, actor_forward: npt.ArrayLike, ray_scene: RayScene
    ) -> TrackShot | None:
        """One frame. actor_position_world (3,): the actor's feet, metres; actor_forward (3,): its
        facing (any length); ray_scene: the level and its dynamic occluders, current transforms.
        Frames must come in time order; a repeated or older time moves nothing. None until a first
        shot is found (no track near the actor yet); the next frame tries again."""
        s = self._settings
        stages = StageClock(clock=self._now)
        actor = np.asarray(actor_position_world, dtype=np.float64).reshape(3)
        forward = np.asarray(actor_forward, dtype=np.float64).reshape(3)
        dt = 0.0 if self._last_time_s is None else max(0.0, time_s - self._last_time_s)
        if self._last_actor is not None and dt > 0.0:
            self._actor_velocity = (actor - self._last_actor) / dt
        self._last_time_s = time_s if self._last_time_s is None else max(self._last_time_s, time_s)
        self._last_actor = actor
        actor_points = actor + np.outer(self._fractions * self._actor_height_m, UP_WORLD)
        look_at = actor + s.look_at_fraction * self._actor_height_m * UP_WORLD
        ends = framed_ends_world(actor, self._actor_height_m, self._style.shot_size)
        distance = self.optimal_distance_m()
        movement = self._style.movement
        # places are scored on what they see of the actor now and where it walks to in visibility_lookahead_s;
        # faster than the camera may move is a teleport (a respawn, a first frame far away), not a walk
        walk = np.array([self._actor_velocity[0], 0.0, self._actor_velocity[2]])
        ahead = walk * s.visibility_lookahead_s if np.linalg.norm(walk) <= s.max_speed_m_s else np.zeros(3)
        scored_points = np.stack([actor_points, actor_points + ahead])

        reason: CutReason | None = None
        if self._camera is None:
            reason = CutReason.FIRST_SHOT
        elif movement != Movement.DYNAMIC_NO_CUTS:
            seen = float(direct_visibility(self._camera[None], actor_points, ray_scene)[0])
            # violated when neither the camera nor the target it is on its way to frames the actor
            framed = self._frames(np.stack([self._camera, self._target_position()]), look_at, ends, distance)
            clock = self._clock
            assert clock is not None  # started by the cut that placed the camera
            clock.observe(time_s, seen < s.occluded_below_fraction, not framed.any())
            reason = clock.reason(time_s, s)
        stages.done(TracksStage.CUT_CHECK)

        cut = False
        indirect = None
        self._scores = {}
        if reason is None and movement != Movement.STATIC:
            indirect = self._indirect.per_node(actor, s.surroundings_radius_m)
            moved = self._move_target(actor, look_at, ends, scored_points, distance, indirect, ray_scene)
            if not moved and movement == Movement.DYNAMIC_WITH_CUTS:
                reason = CutReason.NO_TARGET
        if reason is not None:
            if indirect is None:
                indirect = self._indirect.per_node(actor, s.surroundings_radius_m)
            cut = self._cut(actor, look_at, ends, scored_points, forward, distance, indirect, ray_scene, reason)
            if cut:
                self._shot_id += 1
                self._clock = CutClock(time_s, draw_shot_duration_s(self._rng, s))
        stages.done(TracksStage.TARGET_UPDATE)
        if self._target is None:  # no track near the actor for a first shot yet: no camera to give
            return None

        target = self._target_position()
        if cut or self._last_target is None or dt <= 0.0:
            target_velocity = np.zeros(3)
        else:  # a target that jumps to another edge is not a speed to match: capped as the camera's
            target_velocity = (target - self._last_target) / dt
            speed = float(np.linalg.norm(target_velocity))
            if speed > s.max_speed_m_s:
                target_velocity *= s.max_speed_m_s / speed
        self._last_target = target
        if cut:
            self._camera, self._velocity = target.copy(), np.zeros(3)
        elif movement != Movement.STATIC and self._camera is not None:
            self._camera, self._velocity = move_camera(
                self._camera,
                self._velocity,
                target,
                target_velocity,
                look_at,
                dt,
                s,
                self.repulsion_radius_m(),
                self.nearest_m(0.0),
            )
        camera = self._camera
        assert camera is not None  # a target comes with a camera: the cut that chose the first one placed it
        visible = float(direct_visibility(camera[None], actor_points, ray_scene)[0])
        stages.done(TracksStage.CAMERA_UPDATE)
        aim = aim_point(camera, ends, self._actor_radius_m)
        return TrackShot(
            position_world=camera.copy(),
            look_at_world=aim,
            cut=cut,
            shot_id=self._shot_id,
            visible_fraction=visible,
            cut_reason=reason if cut else None,
            timings_ms=stages.timings_ms,
            scores=self._scores,
        )

    # --- target search -------------------------------------------------------------------------

    def _target_position(self) -> npt.NDArray[np.float64]:
        assert self._target is not None  # asked only once a first shot has a target
        a, b, t = self._target
        position: npt.NDArray[np.float64] = self.graph.nodes_world[a] + t * (
            self.graph.nodes_world[b] - self.graph.nodes_world[a]
        )
        return position

    def _radius(self, distance: float) -> float:
        return max(self._settings.candidate_radius_m, 1.5 * distance)

    def _frames(
        self, positions_world: _Floats, look_at: _Floats, ends: _Floats, distance: float, tolerance_log: float | None = None
    ) -> npt.NDArray[np.bool_]:
        """(k,) bool for positions (k, 3): within `tolerance_log` (default: the framing tolerance,
        Section 5.1's framing check) of the optimal distance, in log ratio, and the framed extent
        fits in the frame (framing.py)."""
        tolerance = self._settings.framing_violation_log if tolerance_log is None else tolerance_log
        d = np.maximum(np.linalg.norm(positions_world - look_at, axis=1), 1e-6)
        frames: npt.NDArray[np.bool_] = (np.abs(np.log(d / distance)) <= tolerance) & self._fits(positions_world, ends)
        return frames

    def _fits(self, positions_world: _Floats, ends: _Floats) -> npt.NDArray[np.bool_]:
        """(k,) bool for positions (k, 3): the framed extent fits in the frame (framing.py, no margin)."""
        return fit_ratio(positions_world, ends, self._actor_radius_m, self._settings.vertical_fov_deg, 0.0) <= 1.0

    def _cheap_scores(
        self,
        pois: Pois,
        look_at: npt.NDArray[np.float64],
        ends: npt.NDArray[np.float64],
        distance: float,
        indirect: npt.NDArray[np.float64],
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Shot size (the distance's Gaussian, down to 0 where the framed extent cannot fit:
        framing.py) and indirect visibility, (k,) each."""
        s = self._settings
        fit = fit_ratio(pois.position_world, ends, self._actor_radius_m, s.vertical_fov_deg, s.frame_margin)
        size = shot_size_score(pois.position_world, look_at, distance, s.shot_size_tolerance_log) * np.clip(
            1.0 - (fit - 1.0) / s.fit_softness, 0.0, 1.0
        )
        ind = (1.0 - pois.t) * indirect[pois.node_a] + pois.t * indirect[pois.node_b]
        return size, ind

    def _move_target(
        self,
        actor: _Floats,
        look_at: _Floats,
        ends: _Floats,
        scored_points: _Floats,
        distance: float,
        indirect: _Floats,
        scene: RayScene,
    ) -> bool:
        """Target moving strategy; False when no POI is reachable from the current target."""
        s = self._settings
        pois = candidate_pois(self.graph, actor, look_at, distance, self._radius(distance), nodes_only=False)
        current = self._target
        assert current is not None  # the target moves only once a first shot has one
        cur_pos = self._target_position()
        pois = Pois(
            np.append(pois.node_a, current[0]),
            np.append(pois.node_b, current[1]),
            np.append(pois.t, current[2]),
            np.vstack([pois.position_world, cur_pos]),
        )
        size, ind = self._cheap_scores(pois, look_at, ends, distance, indirect)
        partial = s.weight_shot_size * size + s.weight_indirect_visibility * ind
        keep = np.argsort(-partial, kind="stable")[:_SCORED_POIS]
        pois, size, ind = pois.take(keep), size[keep], ind[keep]
        dist = graph_distance(self.graph, current, pois, s.max_graph_distance_m)
        reach = np.isfinite(dist)
        if not reach.any():
            return False
        pois, size, ind, dist = pois.take(reach), size[reach], ind[reach], dist[reach]
        direct = direct_visibility(pois.position_world, scored_points, scene).min(axis=1)  # the worse of now and ahead
        near = np.clip(1.0 - dist / s.max_graph_distance_m, 0.0, 1.0)
        total = (
            s.weight_shot_size * size
            + s.weight_direct_visibility * direct
            + s.weight_indirect_visibility * ind
            + s.weight_distance * near
        )
        total /= s.weight_shot_size + s.weight_direct_visibility + s.weight_indirect_visibility + s.weight_distance
        best = int(np.argmax(total))
        self._scores = _scored(
            best, shot_size=size, direct_visibility=direct, indirect_visibility=ind, graph_distance=near, total=total
        )
        self._target = self._descend(
            pois.take([best]), float(total[best]), float(dist[best]), look_at, ends, scored_points, distance, indirect, scene
        )
        return True

    def _descend(
        self,
        poi: Pois,
        score: float,
        dist: float,
        look_at: _Floats,
        ends: _Floats,
        scored_points: _Floats,
        distance: float,
        indirect: _Floats,
        scene: RayScene,
    ) -> tuple[int, int, float]:
        """Local descent of the (negated) score along the POI's edge in fixed steps."""
        s = self._settings
        a, b, t = int(poi.node_a[0]), int(poi.node_b[0]), float(poi.t[0])
        length = float(np.linalg.norm(self.graph.nodes_world[b] - self.graph.nodes_world[a]))
        weights = s.weight_shot_size + s.weight_direct_visibility + s.weight_indirect_visibility + s.weight_distance
        if a == b or length < 1e-9:
            return a, b, t
        step = s.descent_step_m / length
        for _ in range(s.descent_max_steps):
            ts = np.clip(np.array([t - step, t + step]), 0.0, 1.0)
            ts = ts[np.abs(ts - t) > 1e-12]
            if not len(ts):
                break
            pos = self.graph.nodes_world[a] + ts[:, None] * (self.graph.nodes_world[b] - self.graph.nodes_world[a])
            cand = Pois(np.full(len(ts), a), np.full(len(ts), b), ts, pos)
            size, ind = self._cheap_scores(cand, look_at, ends, distance, indirect)
            direct = direct_visibility(pos, scored_points, scene).min(axis=1)
            moved = dist + np.abs(ts - t) * length
            near = np.clip(1.0 - moved / s.max_graph_distance_m, 0.0, 1.0)
            total = (
                s.weight_shot_size * size
                + s.weight_direct_visibility * direct
                + s.weight_indirect_visibility * ind
                + s.weight_distance * near
            ) / weights
            k = int(np.argmax(total))
            if total[k] <= score:
                break
            score, dist, t = float(total[k]), float(moved[k]), float(ts[k])
            self._scores = _scored(
                k, shot_size=size, direct_visibility=direct, indirect_visibility=ind, graph_distance=near, total=total
            )
        return a, b, t

    def _cut(
        self,
        actor: _Floats,
        look_at: _Floats,
        ends: _Floats,
        scored_points: _Floats,
        forward: _Floats,
        distance: float,
        indirect: _Floats,
        scene: RayScene,
        reason: CutReason,
    ) -> bool:
        """Continuity search (Section 5.3); False when no POI keeps the rules (or none exists).
        The POIs are tried in tiers, the first that holds a cut wins:
        1. those that frame the actor solidly: within `framing_cut_margin` of the framing
           tolerance now (a place at the tolerance's edge is violated again a moment later), and
           framing it `visibility_lookahead_s` ahead;
        2. for a static camera that crops the actor, those where its framed extent fits now and
           ahead, at any distance (a shot too wide beats a cropped one, and a static camera the
           actor walks up to has no other way out; a moving one keeps its distance instead, and
           this tier cost it visibility on zdm2's tightest corridor: 0.96 -> 0.91 in medium);
        3. for a cut that cannot wait (occlusion, no target), all the others.
        Otherwise a cut for framing or shot duration waits for a later frame: a cut to another
        framing that fails is a jump for nothing and cuts again at the next chance. (Every POI
        that frames now, as a second tier for shot duration, cut more and saw less on the
        shared levels' routes.)"""
        s = self._settings
        first = reason == CutReason.FIRST_SHOT
        nodes_only = self._style.movement == Movement.STATIC
        pois = candidate_pois(self.graph, actor, look_at, distance, self._radius(distance), nodes_only)
        if first:
            return self._cut_to(pois, look_at, ends, scored_points, forward, distance, indirect, scene, first)
        shift = scored_points[1, 0] - scored_points[0, 0]  # where the actor walks in visibility_lookahead_s
        solid = self._frames(
            pois.position_world, look_at, ends, distance, s.framing_violation_log * s.framing_cut_margin
        ) & self._frames(pois.position_world, look_at + shift, ends + shift, distance)
        tiers = [solid]
        assert self._camera is not None  # every cut but the first leaves a camera
        if nodes_only and not self._fits(self._camera[None], ends)[0]:  # cropping: a shot too wide is better
            fits = self._fits(pois.position_world, ends) & self._fits(pois.position_world, ends + shift)
            tiers.append(fits & ~solid)
        if reason in _MUST_LEAVE:
            tiers.append(~solid)
        return any(
            self._cut_to(pois.take(tier), look_at, ends, scored_points, forward, distance, indirect, scene, first)
            for tier in tiers
        )

    def _cut_to(
        self,
        pois: Pois,
        look_at: _Floats,
        ends: _Floats,
        scored_points: _Floats,
        forward: _Floats,
        distance: float,
        indirect: _Floats,
        scene: RayScene,
        first: bool,
    ) -> bool:
        """The best of `pois` by the cut's scores, made the target; False when none keeps the
        continuity rules or, after the first shot, none sees the actor now, midway and ahead (a
        cut to a place that does not see the actor is a cut for nothing: it waits)."""
        s = self._settings
        if not len(pois):
            return False
        size, ind = self._cheap_scores(pois, look_at, ends, distance, indirect)
        weights = s.weight_shot_size + s.weight_direct_visibility + s.weight_indirect_visibility
        extra = np.zeros(len(pois))
        if not first:
            assert self._camera is not None  # every cut but the first leaves a camera
            angle = cut_angle_deg(self._camera, pois.position_world, look_at)
            direction = action_direction(self._actor_velocity, forward, s.min_actor_speed_m_s)
            before = screen_motion(self._camera[None], look_at, direction)[0]
            after = screen_motion(pois.position_world, look_at, direction)
            ok = (angle >= s.min_cut_angle_deg) & keeps_line_of_action(before, after)
            if not ok.any():
                return False
            pois, size, ind, angle, after = pois.take(ok), size[ok], ind[ok], angle[ok], after[ok]
            thirty = thirty_degree_score(angle, s.min_cut_angle_deg)
            line = line_of_action_score(before, after)
            extra = s.weight_thirty_degree * thirty + s.weight_line_of_action * line
            weights += s.weight_thirty_degree + s.weight_line_of_action
        partial = s.weight_shot_size * size + s.weight_indirect_visibility * ind + extra
        keep = np.argsort(-partial, kind="stable")[:_SCORED_POIS]
        pois, partial = pois.take(keep), partial[keep]
        # now and ahead score the place; a cut also needs the actor seen midway: one batch of rays
        moments = scored_points if first else np.concatenate([scored_points, scored_points.mean(axis=0)[None]])
        per_moment = direct_visibility(pois.position_world, moments, scene)
        direct = per_moment[:, : len(scored_points)].min(axis=1)
        total = (partial + s.weight_direct_visibility * direct) / weights
        if not first:
            seen = per_moment.min(axis=1) >= s.occluded_below_fraction
            if not seen.any():
                return False
            total = np.where(seen, total, -np.inf)
        best = int(np.argmax(total))
        self._target = (int(pois.node_a[best]), int(pois.node_b[best]), float(pois.t[best]))
        continuity = {} if first else {"thirty_degree": thirty[keep], "line_of_action": line[keep]}
        self._scores = _scored(
            best, shot_size=size[keep], direct_visibility=direct, indirect_visibility=ind[keep], **continuity, total=total
        )
        return True
