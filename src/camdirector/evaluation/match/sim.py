"""A match of bots on a precomputed level, for testing and evaluating the casting director (issue 12).

Two teams walk the navigation mesh of a level artifact (precompute/tracks/artifact.py, metres),
meet, fight and take objective points; the result is a MatchRecording (match_file.py) with every
player's transform per frame and the game events. Everything random is drawn from the one
generator passed in, in a fixed order, so a seed gives a bit-identical match.

The ground (`NavGround`): the largest connected region of the navmesh (triangles joined through
shared vertices and steps, navmesh.triangle_adjacency). A route is Dijkstra's shortest path over
triangle centroids (scipy.sparse.csgraph; one search per goal triangle serves every bot heading
there, and is cached; a link between triangles that share no vertex costs ten times its length,
as it may bridge a notch of the outline rather than a step), turned into a polyline on the mesh
(start, then for each pair of consecutive triangles the point they share, then the next
centroid, then the goal: each piece lies in one triangle; across a link, the midpoint of the
closest vertices), then string-pulled: a waypoint is skipped when ray casts straight down every
`path_check_step_m` along the shortcut find the navmesh within a step of the line. Feet are put
on the surface every frame by one batched ray cast down onto the navmesh. Measured (10 bots, 1
minute, seed 1): 0-0.15% of the alive frames stand off the mesh (over a link, or in a notch
between two checks), none by more than 10 cm.

A frame (`rate_hz`): bots move along their routes at `run_speed_m_s`, slowed while turning, and
turn at most `turn_rate_deg_s` towards where they go or whom they fight. Every `1 / ai_rate_hz`
seconds they think, in this order: line of sight between every pair of opponents within
`view_range_m` is ray cast against the level mesh (eye to chest, one batched query); a bot sees an
opponent in line of sight inside its field of view, and remembers where for `memory_s`; a bot
fights the opponent it fights already while that one stays in line of sight, else the nearest it
sees; fighters stand and fire at `fire_rate_hz` once their target is inside `aim_cone_deg`,
hitting with `hit_chance`; a bot hit turns on its attacker. The others chase the nearest opponent
they saw (or were hit by) recently, else head for an objective point their team does not hold, or
roam. A team takes an objective by holding its area alone for `capture_s`. Last, the dead whose
time is up respawn in their team's spawn area.

Events: a kill (actor the attacker, other the victim, at the victim's feet, time of the frame);
a damage at most every `damage_event_interval_s` per attacker and victim; an objective when a
team takes one. Players are "p00", "p01", ..., alternating teams 0 and 1. Not modelled: bots
walk through each other, do not strafe, take cover or jump, and shoot only at ticks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from camdirector.evaluation.match.match_file import MatchEvent, MatchPlayer, MatchRecording
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import UP_WORLD
from camdirector.precompute.tracks.artifact import LevelArtifact
from camdirector.precompute.tracks.navmesh import triangle_adjacency, weld_vertices

MAX_PLAYERS = 64  # the wire contract's limit on a match session's players


@dataclass(frozen=True)
class SimSettings:
    """The bots' rules; validated once, at construction. Lengths in metres, times in seconds.

    hit_chance and respawn_s: one on one a kill takes about 5 s, long enough to film; with
    3-5 s respawns and 0.3 hits, 10 bots on the shared levels made 25-40 kills a minute, with
    these 15-22. path_check_step_m: the navmesh outline has notches of a few centimetres; at
    0.3 m, 0.1-1.4% of the frames stood in one.
    """

    rate_hz: float = 60.0  # frames written per second (movement runs at this rate), Hz. [1, 240]
    ai_rate_hz: float = 10.0  # decisions, sight and shots per second; whole frames apart, Hz. [0.5, rate_hz]
    run_speed_m_s: float = 4.5  # walking speed of a shooter bot (Quake-like games run 5-8), m/s. (0, 20]
    turn_rate_deg_s: float = 360.0  # fastest turn of a bot's facing, deg/s. [10, 3600]
    turning_speed_fraction: float = 0.3  # speed kept facing >= 90 deg off the way (cos above), fraction. [0, 1]
    view_range_m: float = 25.0  # opponents further away are neither seen nor shot, m. (0, 1000]
    fov_deg: float = 120.0  # horizontal field of view in which a bot notices opponents, deg. (0, 360]
    aim_cone_deg: float = 15.0  # a fighter fires once its target is within this cone of its facing, deg. (0, 180]
    fire_rate_hz: float = 5.0  # shots per second of a fighter; at most ai_rate_hz, Hz. (0, ai_rate_hz]
    hit_chance: float = 0.2  # chance that a shot hits (class docstring), fraction. [0, 1]
    damage_per_hit: float = 20.0  # health taken by a hit, hp. (0, 1e4]
    max_health: float = 100.0  # health at spawn, hp. (0, 1e4]
    respawn_s: float = 8.0  # time dead before respawning (class docstring), s. [0, 600]
    spawn_radius_m: float = 8.0  # a team spawns within this path distance of its spawn point, m. (0, 1000]
    memory_s: float = 6.0  # a bot chases an opponent's last seen position for this long, s. [0, 600]
    objective_count: int = 3  # objective points on the level, count. [0, 16]
    objective_balance: float = 0.25  # objectives lie where |d(spawn0) - d(spawn1)| <= this x d(spawns), fraction. (0, 1]
    objective_radius_m: float = 3.0  # within this horizontally (and a player height) is on the point, m. (0, 100]
    capture_s: float = 3.0  # time a team must hold an objective alone to take it, s. (0, 600]
    objective_goal_chance: float = 0.7  # chance that a bot with nothing to chase takes an objective, fraction. [0, 1]
    damage_event_interval_s: float = 1.0  # damage events per attacker and victim are at least this far apart, s. [0, 600]
    eye_height_fraction: float = 0.9  # line of sight starts this far up the player, fraction of its height. (0, 1]
    chest_height_fraction: float = 0.6  # line of sight ends this far up the target, fraction of its height. (0, 1]
    reroute_m: float = 1.0  # a chase goal moving less than this is not re-routed, m. (0, 100]
    path_check_step_m: float = 0.05  # shortcuts are checked for ground this often (class docstring), m. (0, 10]
    max_shortcut_waypoints: int = 32  # string pulling tries shortcuts over at most this many waypoints, count. [2, 1000]

    def __post_init__(self):
        checks = [
            (1.0 <= self.rate_hz <= 240.0, "rate_hz must be in [1, 240]"),
            (0.5 <= self.ai_rate_hz <= self.rate_hz, "ai_rate_hz must be in [0.5, rate_hz]"),
            (0.0 < self.run_speed_m_s <= 20.0, "run_speed_m_s must be in (0, 20]"),
            (10.0 <= self.turn_rate_deg_s <= 3600.0, "turn_rate_deg_s must be in [10, 3600]"),
            (0.0 <= self.turning_speed_fraction <= 1.0, "turning_speed_fraction must be in [0, 1]"),
            (0.0 < self.view_range_m <= 1000.0, "view_range_m must be in (0, 1000]"),
            (0.0 < self.fov_deg <= 360.0, "fov_deg must be in (0, 360]"),
            (0.0 < self.aim_cone_deg <= 180.0, "aim_cone_deg must be in (0, 180]"),
            (0.0 < self.fire_rate_hz <= self.ai_rate_hz, "fire_rate_hz must be in (0, ai_rate_hz]"),
            (0.0 <= self.hit_chance <= 1.0, "hit_chance must be in [0, 1]"),
            (0.0 < self.damage_per_hit <= 1e4, "damage_per_hit must be in (0, 1e4]"),
            (0.0 < self.max_health <= 1e4, "max_health must be in (0, 1e4]"),
            (0.0 <= self.respawn_s <= 600.0, "respawn_s must be in [0, 600]"),
            (0.0 < self.spawn_radius_m <= 1000.0, "spawn_radius_m must be in (0, 1000]"),
            (0.0 <= self.memory_s <= 600.0, "memory_s must be in [0, 600]"),
            (0 <= self.objective_count <= 16, "objective_count must be in [0, 16]"),
            (0.0 < self.objective_balance <= 1.0, "objective_balance must be in (0, 1]"),
            (0.0 < self.objective_radius_m <= 100.0, "objective_radius_m must be in (0, 100]"),
            (0.0 < self.capture_s <= 600.0, "capture_s must be in (0, 600]"),
            (0.0 <= self.objective_goal_chance <= 1.0, "objective_goal_chance must be in [0, 1]"),
            (0.0 <= self.damage_event_interval_s <= 600.0, "damage_event_interval_s must be in [0, 600]"),
            (0.0 < self.eye_height_fraction <= 1.0, "eye_height_fraction must be in (0, 1]"),
            (0.0 < self.chest_height_fraction <= 1.0, "chest_height_fraction must be in (0, 1]"),
            (0.0 < self.reroute_m <= 100.0, "reroute_m must be in (0, 100]"),
            (0.0 < self.path_check_step_m <= 10.0, "path_check_step_m must be in (0, 10]"),
            (2 <= self.max_shortcut_waypoints <= 1000, "max_shortcut_waypoints must be in [2, 1000]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"SimSettings: {message}")


class NavGround:
    """The largest connected region of a level's navmesh: routes, heights, random points (module docstring).

    climb_m: the agent's step height (the artifact's agent_max_climb_m); link_m: how far apart
    stacked step vertices may be (half the navmesh cell, as navmesh.navmesh_components);
    path_check_step_m and max_shortcut_waypoints: SimSettings' string pulling.
    """

    _CACHED_SEARCHES = 128  # goal triangles whose shortest-path trees are kept
    _LINK_COST = 10.0  # a link between triangles that share no vertex costs this many times its length
    _BUCKET_M = 2.0  # cell of the top-view grid that finds the triangle under a point, m (navmesh cells are 0.6 m)

    def __init__(self, navmesh: TriMesh, climb_m: float, link_m: float, path_check_step_m: float, max_shortcut_waypoints: int):
        adjacency = triangle_adjacency(navmesh, climb_m, link_m)
        labels = connected_components(adjacency, directed=False)[1]
        keep = np.flatnonzero(labels == np.bincount(labels).argmax())
        self.vertices, faces = weld_vertices(navmesh.vertices, navmesh.faces.astype(np.int64)[keep])
        used, remapped = np.unique(faces.reshape(-1), return_inverse=True)
        self.vertices, self.faces = self.vertices[used], remapped.reshape(-1, 3)
        self.centroids = self.vertices[self.faces].mean(axis=1)  # (T, 3)
        coo = adjacency[keep][:, keep].tocoo()
        off = coo.row != coo.col
        rows, cols = coo.row[off], coo.col[off]
        # Links between triangles that share no vertex bridge steps, but also notches of the
        # outline (vertices within link_m across a gap): a route takes them only to save a detour.
        touching = triangle_adjacency(navmesh, climb_m, 0.0)[keep][:, keep]
        link_only = ~np.asarray(touching[rows, cols]).reshape(-1).astype(bool)
        # a tiny floor on the weight keeps coincident centroids connected (csgraph drops zero weights)
        weight = (np.linalg.norm(self.centroids[rows] - self.centroids[cols], axis=1) + 1e-6) * np.where(
            link_only, self._LINK_COST, 1.0
        )
        self._graph = sparse.csr_matrix((weight, (rows, cols)), shape=(len(self.faces),) * 2)
        self._tree = cKDTree(self.centroids)
        self._bucket(self._BUCKET_M)
        self._scene = RayScene([TriMesh(self.vertices, self.faces.astype(np.int32))])
        self._climb_m = climb_m
        self._step_m = path_check_step_m
        self._max_skip = max_shortcut_waypoints
        self._searches: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def triangle_count(self) -> int:
        return len(self.faces)

    def search(self, goal: int) -> tuple[np.ndarray, np.ndarray]:
        """(distance_m (T,), predecessor (T,) int32) of the shortest paths to triangle goal;
        predecessor[i] is the next triangle from i towards goal."""
        found = self._searches.get(goal)
        if found is None:
            if len(self._searches) >= self._CACHED_SEARCHES:
                del self._searches[next(iter(self._searches))]  # oldest first: deterministic
            found = dijkstra(self._graph, directed=False, indices=goal, return_predecessors=True)
            self._searches[goal] = found
        return found

    def _bucket(self, cell_m: float) -> None:
        """A top-view grid of cell_m squares listing the triangles whose xz bounds overlap each."""
        xz = self.vertices[self.faces][:, :, [0, 2]]  # (T, 3, 2)
        lo = np.floor(xz.min(axis=1) / cell_m).astype(np.int64)
        hi = np.floor(xz.max(axis=1) / cell_m).astype(np.int64)
        span = hi - lo + 1  # (T, 2) cells per axis
        count = span.prod(axis=1)
        triangle = np.repeat(np.arange(len(xz)), count)
        k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)  # index within each triangle's cells
        cell = lo[triangle] + np.stack([k // span[triangle, 1], k % span[triangle, 1]], axis=1)
        key = self._cell_key(cell)
        order = np.argsort(key, kind="stable")
        self._cell_m, self._keys, self._key_triangles = cell_m, key[order], triangle[order]

    @staticmethod
    def _cell_key(cell: np.ndarray) -> np.ndarray:
        return (cell[..., 0] << 32) + (cell[..., 1] & 0xFFFFFFFF)

    def surface(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(triangle (n,) int, height_m (n,) float64) of the ground under each of points (n, 3):
        of the triangles whose top view holds the point, the one whose surface is nearest in
        height; (-1, NaN) where none holds it."""
        points = np.atleast_2d(points_world)
        keys = self._cell_key(np.floor(points[:, [0, 2]] / self._cell_m).astype(np.int64))
        first = np.searchsorted(self._keys, keys, side="left")
        last = np.searchsorted(self._keys, keys, side="right")
        triangles, heights = np.full(len(points), -1), np.full(len(points), np.nan)
        for n, (i, j) in enumerate(zip(first.tolist(), last.tolist())):
            candidates = self._key_triangles[i:j]
            a, b, c = (self.vertices[self.faces[candidates, k]] for k in range(3))
            v0, v1, v2 = (b - a)[:, [0, 2]], (c - a)[:, [0, 2]], (points[n] - a)[:, [0, 2]]
            det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
            safe = np.where(np.abs(det) > 1e-12, det, 1.0)
            u = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / safe
            v = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / safe
            inside = (np.abs(det) > 1e-12) & (u >= -1e-6) & (v >= -1e-6) & (u + v <= 1.0 + 1e-6)
            if inside.any():
                height = a[:, 1] + u * (b - a)[:, 1] + v * (c - a)[:, 1]
                best = int(np.argmin(np.where(inside, np.abs(height - points[n, 1]), np.inf)))
                triangles[n], heights[n] = candidates[best], height[best]
        return triangles, heights

    def locate(self, points_world: np.ndarray) -> np.ndarray:
        """(n,) int triangle under each of points (n, 3) (surface()), else the nearest centroid's."""
        points = np.atleast_2d(points_world)
        triangles = self.surface(points)[0]
        off = triangles < 0
        if off.any():
            triangles[off] = self._tree.query(points[off])[1]
        return triangles

    def ground(self, points_world: np.ndarray) -> np.ndarray:
        """(n,) float64 height of the surface under points (n, 3) within a step above or below
        them, NaN where there is none."""
        span = 2.0 * self._climb_m
        t = self._scene.first_hit(points_world + self._climb_m * UP_WORLD, np.broadcast_to(-span * UP_WORLD, points_world.shape))
        return np.where(t <= 1.0, points_world[:, 1] + self._climb_m - t * span, np.nan)

    def random_points(self, rng: np.random.Generator, triangles: np.ndarray) -> np.ndarray:
        """(n, 3) uniform random points in the given triangles (n,)."""
        u, v = rng.random(len(triangles)), rng.random(len(triangles))
        flip = u + v > 1.0
        u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
        a, b, c = (self.vertices[self.faces[triangles, k]] for k in range(3))
        return a + u[:, None] * (b - a) + v[:, None] * (c - a)

    def route(self, start_world: np.ndarray, goal_world: np.ndarray, goal_triangle: int) -> np.ndarray:
        """(k, 3) polyline on the ground from start (3,) to goal (3,) in goal_triangle, string-pulled."""
        start = int(self.locate(start_world)[0])
        predecessor = self.search(goal_triangle)[1]
        chain = [start]
        while chain[-1] != goal_triangle and predecessor[chain[-1]] >= 0:
            chain.append(int(predecessor[chain[-1]]))
        if chain[-1] != goal_triangle:  # cannot happen within one connected region; stay put
            return np.asarray(start_world, dtype=np.float64)[None]
        path = np.asarray(chain)
        here, there = self.faces[path[:-1]], self.faces[path[1:]]  # (n, 3) welded vertex ids
        shared = (here[:, :, None] == there[:, None, :]).any(axis=2)  # (n, 3)
        count = shared.sum(axis=1)
        portal = (self.vertices[here] * shared[..., None]).sum(axis=1) / np.maximum(count, 1)[:, None]
        steps = np.flatnonzero(count == 0)  # joined by a step: halfway between the closest vertices
        if len(steps):
            d = np.linalg.norm(self.vertices[here[steps]][:, :, None] - self.vertices[there[steps]][:, None], axis=3)
            i, j = np.unravel_index(d.reshape(len(steps), 9).argmin(axis=1), (3, 3))
            portal[steps] = 0.5 * (self.vertices[here[steps, i]] + self.vertices[there[steps, j]])
        points = np.empty((2 * len(path) - 1, 3))  # start, portal, centroid, ..., portal, goal
        points[0], points[-1] = start_world, goal_world
        points[1::2] = portal
        points[2:-1:2] = self.centroids[path[1:-1]]
        return self._pull(points)

    def _pull(self, points: np.ndarray) -> np.ndarray:
        """Greedy string pulling of a polyline (k, 3) on the ground: from each kept waypoint, the
        furthest of the next max_shortcut waypoints reachable straight over ground."""
        kept, i, last = [0], 0, len(points) - 1
        while i < last:
            far = np.arange(min(last, i + self._max_skip), i + 1, -1)
            j = i + 1
            if len(far):
                ok = self._straight_over_ground(np.broadcast_to(points[i], far.shape + (3,)), points[far])
                if ok.any():
                    j = int(far[ok.argmax()])
            kept.append(j)
            i = j
        return points[kept]

    def _straight_over_ground(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(m,) bool: segments a (m, 3) -> b (m, 3) have ground within a step under every sample."""
        n = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / self._step_m).astype(int), 1) + 1
        segment = np.repeat(np.arange(len(a)), n)
        offsets = np.concatenate([[0], np.cumsum(n)[:-1]])
        f = (np.arange(n.sum()) - np.repeat(offsets, n)) / np.repeat(n - 1, n)
        samples = a[segment] + f[:, None] * (b[segment] - a[segment])
        return np.bincount(segment, weights=np.isnan(self.ground(samples)), minlength=len(a)) == 0


def _yaw_towards(direction: np.ndarray) -> np.ndarray:
    """(n,) yaw in radians about +Y that turns local +Z onto the horizontal part of direction (n, 3)."""
    return np.arctan2(direction[:, 0], direction[:, 2])


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


class _Match:
    """The state of a running match; `run` produces the recording (module docstring)."""

    def __init__(self, artifact: LevelArtifact, n_players: int, rng: np.random.Generator, settings: SimSettings):
        s = self.settings = settings
        self.rng = rng
        agent = artifact.settings
        self.height_m, self.radius_m = agent.agent_height_m, agent.agent_radius_m
        self.ground = NavGround(
            TriMesh(artifact.navmesh_vertices, artifact.navmesh_faces),
            agent.agent_max_climb_m,
            0.5 * agent.navmesh_cell_m,
            s.path_check_step_m,
            s.max_shortcut_waypoints,
        )
        self.level = RayScene([TriMesh(artifact.level_vertices, artifact.level_faces)])
        self.team = np.arange(n_players) % 2
        self.enemies = self.team[:, None] != self.team[None, :]
        self._place_spawns_and_objectives()
        p = n_players
        self.alive = np.ones(p, dtype=bool)
        self.health = np.full(p, s.max_health)
        self.died_s = np.full(p, -np.inf)
        self.pos = np.zeros((p, 3))
        self.yaw = np.zeros(p)
        self.target = np.full(p, -1)
        self.next_shot_s = np.zeros(p)
        self.seen_s = np.full((p, p), -np.inf)  # [i, j]: when bot i last saw (or was hit by) player j
        self.seen_pos = np.zeros((p, p, 3))  # [i, j]: where
        self.goal_kind = [""] * p  # "", "chase", "objective", "roam"
        self.goal_pos = np.zeros((p, 3))
        self.waypoints: list[np.ndarray] = [np.empty((0, 3))] * p  # the route after the current segment
        self.moving = np.zeros(p, dtype=bool)
        self.seg_a, self.seg_b = np.zeros((p, 3)), np.zeros((p, 3))
        self.seg_len, self.seg_at = np.ones(p), np.zeros(p)
        self.last_damage_event_s: dict[tuple[int, int], float] = {}
        self.owner = np.full(len(self.objectives), -1)
        self.capturing = np.full(len(self.objectives), -1)
        self.held_s = np.zeros(len(self.objectives))
        self.events: list[MatchEvent] = []
        self.ids = [f"p{i:02d}" for i in range(p)]
        for i in range(p):
            self._spawn(i)

    def _place_spawns_and_objectives(self) -> None:
        """Spawns at the two ends of the ground's longest shortest path (two sweeps from a random
        triangle); objectives where both are about as far, the first in the middle of the path
        between them, the next ones each as far from those before as possible."""
        s, ground = self.settings, self.ground
        first = int(self.rng.integers(ground.triangle_count))
        end_a = int(np.argmax(ground.search(first)[0]))
        dist_a = ground.search(end_a)[0]
        end_b = int(np.argmax(dist_a))
        dist_b = ground.search(end_b)[0]
        self.spawn_triangles = [np.flatnonzero(dist_a <= s.spawn_radius_m), np.flatnonzero(dist_b <= s.spawn_radius_m)]
        self.spawn_centre = ground.centroids[[end_a, end_b]]
        balanced = np.flatnonzero(np.abs(dist_a - dist_b) <= s.objective_balance * dist_a[end_b])
        chosen: list[int] = []
        nearest = np.full(ground.triangle_count, np.inf)
        for _ in range(min(s.objective_count, len(balanced))):
            pick = (
                int(balanced[np.argmin((dist_a + dist_b)[balanced])])
                if not chosen
                else int(balanced[np.argmax(nearest[balanced])])
            )
            chosen.append(pick)
            nearest = np.minimum(nearest, ground.search(pick)[0])
        self.objectives = ground.centroids[chosen].reshape(-1, 3)
        self.objective_triangles = [
            np.flatnonzero(np.linalg.norm(ground.centroids - o, axis=1) <= s.objective_radius_m) for o in self.objectives
        ]
        self.objective_names = [chr(ord("A") + k) for k in range(len(chosen))]

    # --- per frame -------------------------------------------------------------------------------

    def run(self, n_frames: int, progress=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Simulates n_frames; returns positions (F, P, 3), yaw (F, P) and alive (F, P)."""
        s = self.settings
        dt_s = 1.0 / s.rate_hz
        every = max(1, round(s.rate_hz / s.ai_rate_hz))
        p = len(self.team)
        positions, yaws, alive = np.empty((n_frames, p, 3)), np.empty((n_frames, p)), np.empty((n_frames, p), bool)
        for f in range(n_frames):
            self._move(dt_s)
            if f % every == 0:
                self._think(f / s.rate_hz, every * dt_s)  # the frame's time exactly as time_s holds it
            positions[f], yaws[f], alive[f] = self.pos, self.yaw, self.alive
            if progress is not None and f % 3600 == 0:
                progress(f / n_frames)
        return positions, yaws, alive

    def _move(self, dt_s: float) -> None:
        s = self.settings
        moving = self.moving & self.alive
        fighting = (self.target >= 0) & self.alive
        want = self.yaw.copy()
        if moving.any():
            want[moving] = _yaw_towards(self.seg_b[moving] - self.seg_a[moving])
        if fighting.any():
            want[fighting] = _yaw_towards(self.pos[self.target[fighting]] - self.pos[fighting])
        turn = np.radians(s.turn_rate_deg_s) * dt_s
        error = _wrap(want - self.yaw)
        self.yaw = _wrap(self.yaw + np.clip(error, -turn, turn))
        if not moving.any():
            return
        # slowed while facing away from the way (cos of the remaining error, floored)
        left = np.cos(np.minimum(np.abs(_wrap(want - self.yaw)), np.pi / 2))
        speed = s.run_speed_m_s * np.maximum(left, s.turning_speed_fraction)
        self.seg_at[moving] += speed[moving] * dt_s
        for i in np.flatnonzero(moving & (self.seg_at >= self.seg_len)):
            self._next_segment(int(i))
        moving = self.moving & self.alive
        if moving.any():
            f = (self.seg_at[moving] / self.seg_len[moving])[:, None]
            pos = self.seg_a[moving] + f * (self.seg_b[moving] - self.seg_a[moving])
            height = self.ground.ground(pos)
            pos[:, 1] = np.where(np.isnan(height), pos[:, 1], height)
            self.pos[moving] = pos

    def _next_segment(self, i: int) -> None:
        """Moves bot i on to the next segments of its route after passing the end of its segment."""
        while self.seg_at[i] >= self.seg_len[i]:
            if not len(self.waypoints[i]):
                self.pos[i] = self.seg_b[i]
                self.moving[i] = False
                return
            self.seg_at[i] -= self.seg_len[i]
            self.seg_a[i], self.seg_b[i] = self.seg_b[i], self.waypoints[i][0]
            self.waypoints[i] = self.waypoints[i][1:]
            self.seg_len[i] = max(float(np.linalg.norm(self.seg_b[i] - self.seg_a[i])), 1e-9)

    def _go(self, i: int, goal_world: np.ndarray, goal_triangle: int, kind: str) -> None:
        route = self.ground.route(self.pos[i], goal_world, goal_triangle)
        self.goal_kind[i], self.goal_pos[i] = kind, goal_world
        self.seg_a[i], self.seg_b[i], self.seg_at[i] = self.pos[i], self.pos[i], 0.0
        self.seg_len[i] = 1e-9
        self.waypoints[i] = route[1:]
        self.moving[i] = True

    def _stop(self, i: int) -> None:
        self.moving[i] = False
        self.waypoints[i] = np.empty((0, 3))
        self.goal_kind[i] = ""

    # --- per decision tick -----------------------------------------------------------------------

    def _think(self, t_s: float, tick_s: float) -> None:
        los, sees = self._sight()
        self.seen_s[sees] = t_s
        self.seen_pos[sees] = np.broadcast_to(self.pos, self.seen_pos.shape)[sees]
        distance = np.linalg.norm(self.pos[:, None] - self.pos[None], axis=2)
        for i in np.flatnonzero(self.alive):
            current = self.target[i]
            if current < 0 or not (self.alive[current] and los[i, current]):
                current = int(np.argmin(np.where(sees[i], distance[i], np.inf))) if sees[i].any() else -1
            self.target[i] = current
            if current >= 0 and self.moving[i]:
                self._stop(int(i))
        self._shoot(t_s, los)
        for i in np.flatnonzero(self.alive & (self.target < 0)):
            self._choose_goal(int(i), t_s)
        self._capture(t_s, tick_s)
        self._respawn(t_s)  # last: the respawned act from the next tick on, so nobody acts in a tick they were dead

    def _respawn(self, t_s: float) -> None:
        for i in np.flatnonzero(~self.alive & (t_s - self.died_s >= self.settings.respawn_s)):
            self._spawn(int(i))

    def _spawn(self, i: int) -> None:
        team = self.team[i]
        triangles = self.spawn_triangles[team]
        self.pos[i] = self.ground.random_points(self.rng, triangles[self.rng.integers(len(triangles), size=1)])[0]
        self.yaw[i] = _yaw_towards((self.spawn_centre[1 - team] - self.spawn_centre[team])[None])[0]
        self.alive[i], self.health[i], self.target[i] = True, self.settings.max_health, -1
        self._stop(i)

    def _sight(self) -> tuple[np.ndarray, np.ndarray]:
        """(P, P) bool line of sight within range, and the same inside each viewer's field of view."""
        s = self.settings
        p = len(self.team)
        eye = self.pos + s.eye_height_fraction * self.height_m * UP_WORLD
        chest = self.pos + s.chest_height_fraction * self.height_m * UP_WORLD
        i, j = np.nonzero(self.enemies & self.alive[:, None] & self.alive[None, :])
        near = np.linalg.norm(chest[j] - eye[i], axis=1) <= s.view_range_m
        i, j = i[near], j[near]
        clear = ~self.level.occluded(eye[i], chest[j]) if len(i) else np.zeros(0, dtype=bool)
        los = np.zeros((p, p), dtype=bool)
        los[i[clear], j[clear]] = True
        off = np.abs(_wrap(_yaw_towards(chest[j] - eye[i]) - self.yaw[i]))
        sees = np.zeros((p, p), dtype=bool)
        inside = clear & (off <= np.radians(s.fov_deg) / 2)
        sees[i[inside], j[inside]] = True
        return los, sees

    def _shoot(self, t_s: float, los: np.ndarray) -> None:
        """Fighters fire in a random order; one killed earlier in the tick does not fire."""
        s = self.settings
        for i in self.rng.permutation(len(self.team)):
            j = self.target[i]
            if not self.alive[i] or j < 0 or not self.alive[j] or not los[i, j] or t_s < self.next_shot_s[i]:
                continue
            off = abs(_wrap(_yaw_towards((self.pos[j] - self.pos[i])[None])[0] - self.yaw[i]))
            if off > np.radians(s.aim_cone_deg) / 2:
                continue
            self.next_shot_s[i] = t_s + 1.0 / s.fire_rate_hz
            if self.rng.random() < s.hit_chance:
                self._hit(int(i), int(j), t_s)

    def _hit(self, i: int, j: int, t_s: float) -> None:
        s = self.settings
        self.health[j] -= s.damage_per_hit
        self.seen_s[j, i], self.seen_pos[j, i] = t_s, self.pos[i]
        if self.health[j] <= 0.0:
            self.alive[j], self.died_s[j], self.target[j] = False, t_s, -1
            self._stop(j)
            self.target[self.target == j] = -1
            self.events.append(
                MatchEvent("kill", self.ids[i], self.ids[j], 0, t_s, f"{self.ids[i]} killed {self.ids[j]}", self.pos[j].copy())
            )
            return
        if self.target[j] < 0:  # turns on its attacker
            self.target[j] = i
            self._stop(j)
        if t_s - self.last_damage_event_s.get((i, j), -np.inf) >= s.damage_event_interval_s:
            self.last_damage_event_s[(i, j)] = t_s
            self.events.append(
                MatchEvent("damage", self.ids[i], self.ids[j], 0, t_s, f"{self.health[j]:.0f} hp left", self.pos[j].copy())
            )

    def _choose_goal(self, i: int, t_s: float) -> None:
        s, team = self.settings, self.team[i]
        recent = self.enemies[i] & self.alive & (t_s - self.seen_s[i] <= s.memory_s)
        if recent.any():
            gap = np.where(recent, np.linalg.norm(self.seen_pos[i] - self.pos[i], axis=1), np.inf)
            goal = self.seen_pos[i, int(np.argmin(gap))]
            if self.goal_kind[i] != "chase" or np.linalg.norm(goal - self.goal_pos[i]) > s.reroute_m:
                self._go(i, goal.copy(), int(self.ground.locate(goal)[0]), "chase")
            return
        if self.goal_kind[i] in ("objective", "roam") and self.moving[i]:
            return
        if self.goal_kind[i] == "objective" and not self.moving[i]:
            k = int(np.argmin(np.linalg.norm(self.objectives - self.pos[i], axis=1)))
            if self.owner[k] != team:  # hold the point until taken
                return
        if len(self.objectives) and self.rng.random() < s.objective_goal_chance:
            open_ = np.flatnonzero(self.owner != team)
            k = int(self.rng.choice(open_ if len(open_) else np.arange(len(self.objectives))))
            triangles = self.objective_triangles[k]
            kind = "objective"
        else:
            triangles = np.arange(self.ground.triangle_count)
            kind = "roam"
        triangle = int(triangles[self.rng.integers(len(triangles))])
        self._go(i, self.ground.random_points(self.rng, np.array([triangle]))[0], triangle, kind)

    def _capture(self, t_s: float, tick_s: float) -> None:
        s = self.settings
        for k, point in enumerate(self.objectives):
            off = self.pos - point
            on = self.alive & (np.hypot(off[:, 0], off[:, 2]) <= s.objective_radius_m) & (np.abs(off[:, 1]) <= self.height_m)
            teams = np.unique(self.team[on])
            if len(teams) != 1 or teams[0] == self.owner[k]:
                self.capturing[k], self.held_s[k] = -1, 0.0
                continue
            team = int(teams[0])
            self.held_s[k] = self.held_s[k] + tick_s if self.capturing[k] == team else tick_s
            self.capturing[k] = team
            if self.held_s[k] >= s.capture_s:
                self.owner[k], self.capturing[k], self.held_s[k] = team, -1, 0.0
                actor = self.ids[int(np.flatnonzero(on)[0])]
                self.events.append(
                    MatchEvent(
                        "objective", actor, "", 0, t_s, f"team {team} took objective {self.objective_names[k]}", point.copy()
                    )
                )


def yaw_to_quat(yaw: np.ndarray) -> np.ndarray:
    """(..., 4) xyzw rotations about +Y by yaw (...) radians: local +Z onto (sin yaw, 0, cos yaw)."""
    q = np.zeros(yaw.shape + (4,))
    q[..., 1], q[..., 3] = np.sin(yaw / 2.0), np.cos(yaw / 2.0)
    return q


def simulate_match(
    artifact: LevelArtifact,
    level_name: str,
    n_players: int,
    duration_s: float,
    rng: np.random.Generator,
    seed: int,
    settings: SimSettings | None = None,
    progress=None,
) -> MatchRecording:
    """A match of n_players bots (2 to 64) for duration_s seconds on a level (module docstring).

    rng: the only source of randomness; seed: recorded in the file (the seed rng was made from).
    progress: optional callable taking the fraction done. Raises ValueError on bad arguments.
    """
    settings = settings or SimSettings()
    if not 2 <= n_players <= MAX_PLAYERS:
        raise ValueError(f"players must be 2 to {MAX_PLAYERS}, got {n_players}")
    n_frames = int(round(duration_s * settings.rate_hz))
    if n_frames < 1:
        raise ValueError(f"duration_s must give at least one frame at {settings.rate_hz} Hz, got {duration_s}")
    match = _Match(artifact, n_players, rng, settings)
    positions, yaws, alive = match.run(n_frames, progress)
    players = [
        MatchPlayer(id=pid, team=int(t), height_m=match.height_m, radius_m=match.radius_m)
        for pid, t in zip(match.ids, match.team)
    ]
    return MatchRecording(
        level=level_name,
        seed=seed,
        rate_hz=settings.rate_hz,
        players=players,
        time_s=np.arange(n_frames) / settings.rate_hz,
        positions_world=positions,
        rotations_xyzw=yaw_to_quat(yaws),
        alive=alive,
        events=match.events,
    )
