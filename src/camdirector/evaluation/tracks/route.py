"""Actor routes on a level: Recast's test cases where they apply, else A* paths on the navmesh, and
routes through a level's tightest corridor and its most open area.

`RecastDemo/Bin/TestCases/nav_mesh_test.txt` lists path-find queries for nav_test.obj as lines
`pf sx sy sz ex ey ez includeFlags excludeFlags` (metres, the level's frame). A route is the A*
path over navmesh triangles (centroid to centroid across shared vertices or steps, costs in
metres) from the triangle nearest the start to the one nearest the end, walked at a constant
speed and sampled at a frame rate.

The tightest and the most open place (`corridor_and_open_routes`) are picked among points every
`_SKELETON_STEP_M` along the level's skeleton (the navmesh's centre lines, to within their
simplification: a corridor runs along them, and a room's centre is on them) where an actor can
stand (`walkable`: on the navmesh, with head room). A place's measure is half the narrowest width
between walls through it (`passage_half_width_m`): `_CLEARANCE_RAYS` horizontal rays through the
level, each capped at `OPEN_RANGE_M` (a ray that meets nothing: open ground), the least sum of two
opposite ones, at the actor's knees, waist and eyes, the widest of the three. Walls are what hem a
camera in; the navmesh's own outline would also count the edges of ledges, where a camera has all
the room it wants, and the cuts between skeleton layers on ramps. The tightest place has the
smallest half width, the most open the largest (ties, common at the cap, broken by the mean of
the capped ray lengths); each is the first place in that order through which a route runs
(`NavmeshPaths.through_path`): a path of about `ROUTE_LENGTH_M` from one end A to the other B
through the place p, with A the navmesh triangle farthest from p by path within half the length
and B the one within that reach farthest from A in a straight line, kept only when p lies on a
shortest path from A to B (to `_THROUGH_RATIO`) and the path is at least `_MIN_ROUTE_SHARE` of
the length: a dead end or a niche is passed over. Nothing is random: the same level gives the same
routes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import UP_WORLD
from camdirector.pipeline.tracks.graph_search import adjacency_lists, astar_many
from camdirector.precompute.tracks.navmesh import navmesh_components, triangle_adjacency
from camdirector.precompute.tracks.track_settings import TrackSettings

ROUTE_LENGTH_M = 20.0  # a tightest or open route's length one way, m (the scenario)
OPEN_RANGE_M = 25.0  # clearance rays are capped here: past the visibility table's 15 m, more room changes nothing, m
WALK_SPEED_M_S = 1.4  # the actor's walking speed on every evaluation route, m/s
FRAME_RATE_HZ = 30.0  # frames per second of every evaluation route
_SKELETON_STEP_M = 0.5  # candidate places lie this far apart along the skeleton, m
_CLEARANCE_RAYS = 32  # horizontal rays per candidate place and height
_WIDTH_HEIGHT_FRACTIONS = (0.25, 0.5, 0.9)  # widths are measured at the actor's knees, waist and eyes, fractions of its height
_ON_NAVMESH_M = 0.25  # a candidate place is on the navmesh when this close to it vertically, m
_HEAD_LIFT_M = 0.05  # the head-room ray starts this far above the place, clear of its own floor, m
_THROUGH_RATIO = 0.9  # p is on a through path when the A-B distance is at least this share of A-p-B
_MIN_ROUTE_SHARE = 0.75  # a route shorter than this share of the length asked for is passed over


@dataclass(frozen=True)
class ActorRoute:
    """time_s (F,), position_world (F, 3) the actor's feet, forward_world (F, 3) unit facing."""

    time_s: np.ndarray
    position_world: np.ndarray
    forward_world: np.ndarray


def read_recast_queries(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """(start (3,), end (3,)) of every `pf` line of a Recast test-case file."""
    queries = []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if len(parts) >= 7 and parts[0] == "pf":
            values = np.array([float(x) for x in parts[1:7]])
            queries.append((values[:3], values[3:]))
    return queries


class NavmeshPaths:
    """A* over the triangles of a navigation mesh (metres, world frame)."""

    def __init__(self, navmesh: TriMesh, settings: TrackSettings):
        self.navmesh = navmesh
        self.centroids = navmesh.vertices[navmesh.faces].mean(axis=1)
        adjacency = triangle_adjacency(navmesh, settings.agent_max_climb_m, 0.5 * settings.navmesh_cell_m).tocoo()
        off = adjacency.row != adjacency.col
        rows, cols = adjacency.row[off], adjacency.col[off]
        order = np.argsort(rows, kind="stable")
        rows, cols = rows[order], cols[order]
        lengths = np.linalg.norm(self.centroids[rows] - self.centroids[cols], axis=1)
        self._adjacency = adjacency_lists(np.searchsorted(rows, np.arange(len(self.centroids) + 1)), cols, lengths)
        # the same graph for Dijkstra; a zero length would read as no edge, so it gets a tiny one
        self._lengths = sparse.csr_matrix((np.maximum(lengths, 1e-9), (rows, cols)), shape=(len(self.centroids),) * 2)
        self._positions = self.centroids.tolist()
        self.component = navmesh_components(navmesh, settings)
        self._tree = cKDTree(self.centroids)

    def path(self, start_world: np.ndarray, end_world: np.ndarray) -> np.ndarray | None:
        """(p, 3) polyline from start to end through triangle centroids, or None when unconnected."""
        s = int(self._tree.query(start_world)[1])
        e = int(self._tree.query(end_world)[1])
        parent: dict[int, int] = {}
        found = astar_many(self._adjacency, self._positions, {s: 0.0}, {e}, np.inf, parent)
        if e not in found:
            return None
        chain = [e]
        while chain[-1] != s:
            chain.append(parent[chain[-1]])
        points = self.centroids[chain[::-1]]
        return np.vstack([points[:1] if s == e else points, points[-1:]])

    def random_path(self, rng: np.random.Generator, min_length_m: float, tries: int = 50) -> np.ndarray | None:
        """A path between random triangles of the largest region, at least min_length_m long when
        one of `tries` draws finds it (else the longest found)."""
        largest = np.flatnonzero(self.component == np.bincount(self.component).argmax())
        best, best_len = None, -1.0
        for _ in range(tries):
            a, b = rng.choice(largest, size=2)
            path = self.path(self.centroids[a], self.centroids[b])
            if path is None:
                continue
            length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
            if length > best_len:
                best, best_len = path, length
            if length >= min_length_m:
                break
        return best

    def through_path(self, point_world: np.ndarray, length_m: float) -> np.ndarray | None:
        """(p, 3) polyline of about length_m through point_world (3,), a point on the navmesh, from
        one end A to the other B (module docstring; distances from the triangle nearest the
        point), or None when no such path runs through it."""
        p = int(self._tree.query(point_world)[1])
        from_p, parent = dijkstra(self._lengths, indices=p, limit=0.5 * length_m, return_predecessors=True)
        reach = np.flatnonzero(np.isfinite(from_p))
        a = int(reach[np.argmax(from_p[reach])])
        b = int(reach[np.argmax(np.linalg.norm(self.centroids[reach] - self.centroids[a], axis=1))])
        along = from_p[a] + from_p[b]
        if along < _MIN_ROUTE_SHARE * length_m:
            return None
        a_to_b = dijkstra(self._lengths, indices=a, limit=along)[b]
        if a_to_b < _THROUGH_RATIO * along:
            return None

        def chain(end: int) -> list[int]:
            """Triangles from p to end on the shortest-path tree."""
            nodes = [end]
            while nodes[-1] != p:
                nodes.append(int(parent[nodes[-1]]))
            return nodes[::-1]

        to_p = chain(a)[::-1]
        polyline = self.centroids[to_p + chain(b)[1:]]
        polyline[len(to_p) - 1] = point_world  # through the place itself, not its triangle's centroid
        return polyline


def passage_half_width_m(points_world: np.ndarray, scene: RayScene, height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Per point (n, 3) m on the floor: half the narrowest width between walls through it, and the
    mean distance to walls around, m (n,) each (module docstring): `_CLEARANCE_RAYS` horizontal
    rays (an even number: each has its opposite) capped at `OPEN_RANGE_M`, at each of
    `_WIDTH_HEIGHT_FRACTIONS` of height_m above the point; the widest of those heights counts. A
    width through the point, not its distance to the nearest wall, so that a point off a
    corridor's centre line measures the corridor all the same; the widest height, so that a wall
    hems the place in and a rail, a table or a beam, in the way at one height only, does not."""
    angles = np.arange(_CLEARANCE_RAYS) * (2.0 * np.pi / _CLEARANCE_RAYS)
    directions = OPEN_RANGE_M * np.stack([np.cos(angles), np.zeros_like(angles), np.sin(angles)], axis=1)
    points = np.atleast_2d(points_world)
    half, mean = np.zeros(len(points)), np.zeros(len(points))
    for fraction in _WIDTH_HEIGHT_FRACTIONS:
        origins = np.repeat(points + fraction * height_m * UP_WORLD, _CLEARANCE_RAYS, axis=0)
        hit = scene.first_hit(origins, np.tile(directions, (len(points), 1))).reshape(-1, _CLEARANCE_RAYS)
        distance = OPEN_RANGE_M * np.minimum(hit, 1.0)
        opposite = distance[:, : _CLEARANCE_RAYS // 2] + distance[:, _CLEARANCE_RAYS // 2 :]
        half = np.maximum(half, 0.5 * opposite.min(axis=1))
        mean = np.maximum(mean, distance.mean(axis=1))
    return half, mean


def walkable(points_world: np.ndarray, navmesh_scene: RayScene, scene: RayScene, height_m: float) -> np.ndarray:
    """(n,) bool: whether each point (n, 3) m lies on the navmesh (within `_ON_NAVMESH_M` above or
    below it) with height_m of head room over it in the level; navmesh_scene, scene: RayScenes of
    the navmesh and of the level. The skeleton runs over posts the navmesh goes round (its outline's
    small holes are filled) and under beams: no actor stands there."""
    points = np.atleast_2d(points_world)
    down = np.tile(-2.0 * _ON_NAVMESH_M * UP_WORLD, (len(points), 1))
    on = np.isfinite(navmesh_scene.first_hit(points + _ON_NAVMESH_M * UP_WORLD, down))
    lifted = points + _HEAD_LIFT_M * UP_WORLD
    return on & ~scene.occluded(lifted, points + height_m * UP_WORLD)


def skeleton_points(segments_world: np.ndarray, step_m: float) -> np.ndarray:
    """(n, 3) points every step_m or less along each skeleton segment (k, 2, 3), its ends included."""
    points = []
    for start, end in segments_world:
        count = max(1, int(np.ceil(np.linalg.norm(end - start) / step_m)))
        points.append(start + np.linspace(0.0, 1.0, count + 1)[:, None] * (end - start))
    return np.unique(np.concatenate(points), axis=0) if points else np.empty((0, 3))


@dataclass(frozen=True)
class PlaceRoute:
    """A route through a place: place_world (3,) m the place on the skeleton, half_width_m half the
    narrowest width between walls through it, polyline_world (p, 3) m the path from one end through
    it to the other (walked there and back by `there_and_back`)."""

    place_world: np.ndarray
    half_width_m: float
    polyline_world: np.ndarray


def corridor_and_open_routes(
    paths: NavmeshPaths,
    skeleton_segments_world: np.ndarray,
    scene: RayScene,
    actor_height_m: float,
    length_m: float = ROUTE_LENGTH_M,
) -> dict[str, PlaceRoute]:
    """'tightest' and 'open': routes through the level's tightest corridor and its most open
    place (module docstring); a name is missing when no place of its kind has a route through it.
    skeleton_segments_world (k, 2, 3) m; scene: a RayScene of the level."""
    points = skeleton_points(skeleton_segments_world, _SKELETON_STEP_M)
    if len(points):
        points = points[walkable(points, RayScene([paths.navmesh]), scene, actor_height_m)]
    if not len(points):
        return {}
    half_width, mean = passage_half_width_m(points, scene, actor_height_m)
    orders = {"tightest": np.lexsort((mean, half_width)), "open": np.lexsort((-mean, -half_width))}
    routes = {}
    for name, order in orders.items():
        for k in order.tolist():
            polyline = paths.through_path(points[k], length_m)
            if polyline is not None:
                routes[name] = PlaceRoute(points[k], float(half_width[k]), polyline)
                break
    return routes


def there_and_back(polyline_world: np.ndarray) -> ActorRoute:
    """The actor walking a polyline (p, 3) m and back, at `WALK_SPEED_M_S`, `FRAME_RATE_HZ`."""
    return walk(np.vstack([polyline_world, polyline_world[-2::-1]]), WALK_SPEED_M_S, FRAME_RATE_HZ)


def walk(polyline_world: np.ndarray, speed_m_s: float, frame_rate_hz: float) -> ActorRoute:
    """The actor walking a polyline (p, 3) at a constant speed, one sample per frame."""
    seg = np.diff(polyline_world, axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 1e-9
    points = np.vstack([polyline_world[:1], polyline_world[1:][keep]])
    cumulative = np.concatenate([[0.0], np.cumsum(length[keep])])
    total = cumulative[-1]
    times = np.arange(0.0, total / speed_m_s + 1e-9, 1.0 / frame_rate_hz)
    travelled = np.minimum(times * speed_m_s, total)
    position = np.stack([np.interp(travelled, cumulative, points[:, k]) for k in range(3)], axis=1)
    heading = np.diff(
        position,
        axis=0,
        append=position[-1:] + (position[-1:] - position[-2:-1] if len(position) > 1 else np.array([[0.0, 0.0, 1.0]])),
    )
    heading[:, 1] = 0.0
    norm = np.linalg.norm(heading, axis=1, keepdims=True)
    heading = np.where(norm > 1e-9, heading / np.maximum(norm, 1e-12), np.array([0.0, 0.0, 1.0]))
    return ActorRoute(times, position, heading)
