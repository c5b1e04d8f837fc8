"""The camera of each shot kind, and where on its manifold a shot's camera is placed.

DUEL, FOLLOW and GROUP use the Toric framing (toric-space-primer.md; the occlusion-anticipation
paper, section 3): the camera stays on the torus of the two framed points every frame, at a place
(theta as a ratio along the arc, phi about the A-B axis) chosen at the cut:
- DUEL frames the two players, the screen-left one given by the line of action (grammar.py);
- FOLLOW frames one player and a gaze-room point `gaze_room_m` ahead of its smoothed facing,
  horizon level (the level's camera tracks are not used: the Toric rig serves every level);
- GROUP frames the two players of the group farthest apart, at screen points 1.5 times wider than
  the style's, so the others, between them, are in frame too.
A planned DUEL (a kill the delay lets the director see coming) frames its pair only around its
events (`PairWindow`): before, the victim is mostly still behind walls, and after, dead; there
the same camera frames the killer alone as a FOLLOW does, the second framed point swung from the
victim to the killer's gaze-room point (`swung_point`), and the shot names the killer alone.

OVERVIEW is a static camera high above the players' bounding box looking at its centre, or at
a node of the level's graph, whichever sees the worst-seen player best by the same measure as
the places below; it is level too (geometry.camera.level_look_rotation). It also stands in for a
DUEL or GROUP whose best place sees its subjects under `min_visible` when it sees them better
(shot_builder.py, ShotBuilder.build).

Every camera keeps the horizon level, as broadcast casting does. DUEL and GROUP do not compose A
and B exactly (geometry.toric.look_rotation rolls the camera whenever the composition demands
it: over a shoulder from above the pair's axis, by up to 85 degrees; with it, at a 10 s delay on
nav_test, dungeon and zdm2, the program was rolled by more than 20 degrees for 34%, 55% and 61% of
its time) but turn that composition about the bisector of the rays to A and B until the horizon
is level (geometry.toric.level_pair_rotation): A and B lie about the midpoint of their screen
points, exactly on them wherever the exact composition has no roll, one above the other over a
shoulder from above. The place search judges this level picture (`ToricCamera.rotations`), so a
place whose level picture cannot hold both players fails the frame test: a pair 20-24 m apart
along a corridor, seen only from above it, is shot wide instead (the OVERVIEW stand-in above).
Measured with eval-match at a 10 s delay (5-minute 10-player matches, seed 0), rolled -> level
with the stand-in: kill coverage nav_test 0.857 -> 0.893, dungeon 0.909 -> 0.875, zdm2 0.872 ->
0.881; shot lengths, shots under 2 s and jump cuts unchanged; program roll 0.

The place is chosen by ray casting the subjects' sample points from a grid of places, at the cut
and at the moments the shot must cover (with a delay these are buffered future moments: the
occlusion is anticipated by looking at it, section 5's look-ahead done with the real future),
scoring each place by its worst-seen subject (a point counts when it is unoccluded and inside
the frame), each moment with its weight (a planned event's own moment weighs most). A place is
also a framing width: the style's screen points spread `width` times apart (clamped to the
frame), which shrinks the torus, since a wider composition angle puts the camera closer to the
players (primer, "the torus"); in corridors and rooms a close camera is the one under the
walls, so the grid tries the style's composition first and two wider ones. While the shot runs,
a place that falls under `min_visible` is replaced by the best one on the same side, and the
camera glides there (and to its width) with the style's response time, so the composition never
jumps inside a shot.

Every frame the program camera keeps its framed subjects' readable distance (shot_builder.py
`readable_clearance`: nearer, no lens width the rig goes to shows them under the framing band):
a camera pulled in front of a wall stops there (`pulled_in`), and a place that the moving torus
brings nearer steps back along the line from the anchor through it (`stepped_back`), as an
operator steps back rather than filling the frame with a player. Measured with eval-match (the
eight development matches, 10 s delay, 30 Hz): frames with a player over 0.6 of the frame's
height on the real 4on4 3.74% -> 2.04%, 2on2 3.43% -> 1.36%, duel 1.99% -> 1.04%, nav_test
2.67% -> 1.04%; kill coverage kept or better on each.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens, level_look_matrices, level_look_rotation, project_from_cameras
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.toric import (
    DegenerateTorus,
    Torus,
    composition_angle,
    level_pair_matrices,
    level_pair_rotation,
    make_torus,
    theta_max,
    torus_position,
)
from camdirector.geometry.transforms import UP_WORLD, quat_to_matrix
from camdirector.infra.slices import pause
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.pipeline.style import Style

THETA_MARGIN = 0.04  # keep the camera off A and B, ratio of the arc
# The place grid along the arc (the ends are over a shoulder) and about the axis (0 above, 90 level
# beside), and the framing widths (module docstring), the style's own first so that it wins ties.
# Dense at the ends of the arc (over a shoulder, where a close camera sees past the walls) and
# from nearly above to a little below the axis: a duel's line of action leaves one side of it,
# and on dungeon and zdm2 the best place of that side at a kill sees both players for 0.89-0.98
# of the kills with this grid, 0.68-0.82 with 10 ratios and 5 phis from 30 to 95 degrees (with
# the rolled composition; level, the places nearly above still show a pair one above the other,
# and more phis or a fourth width did not recover dungeon's four kills: module docstring).
PLACE_RATIOS = np.array([0.01, 0.03, 0.06, 0.1, 0.15, 0.3, 0.5, 0.7, 0.85, 0.9, 0.94, 0.97, 0.99])
PLACE_PHI_RAD = np.radians([5.0, 10.0, 20.0, 30.0, 45.0, 65.0, 80.0, 95.0, 110.0, 125.0])
PLACE_WIDTHS = (1.0, 1.8, 2.6)
# A new shot's camera rides its place for at least the style's min_shot_s: its path over that
# time, sampled every PATH_STEP_S, crossing a wall costs a place PATH_WALL_COST of its seen share
# (a camera that meets a wall under 2 s after its cut makes a shot under 2 s: issue 41, item 3)
PATH_STEP_S = 0.25
PATH_WALL_COST = 0.25
MAX_SCREEN = 0.9  # a widened screen point stays this far inside the frame
MIN_CAMERA_HEIGHT_M = 0.5  # a place lower than this above the lowest subject's feet is under the ground: never chosen
HEADING_TIME_CONSTANT_S = 0.6  # FOLLOW: smoothing of the facing, as framing.py
GROUP_SCREEN_SCALE = 1.5  # GROUP: screen points this much wider than the style's
OVERVIEW_HEIGHTS_M = (4.0, 8.0)  # overview heights tried below overview_height_m
OVERVIEW_AZIMUTHS = 8
STEP_BACK_MAX_M = 3.0  # a camera too near its subjects steps back along its line this far at most, m
READABLE_STEP_M = 0.1  # the grid along a camera's line on which the readable distance is found, m
READABLE_REFINE = 8  # each refinement subdivides the bracket found this many times
READABLE_REFINEMENTS = 2  # twice: 0.1 m / 64, 1.6 mm


@dataclass(frozen=True)
class PairWindow:
    """When a planned DUEL frames its pair: from `before_s` before each event it shows to `after_s`
    after it, fully, easing in and out over `ramp_s`; elsewhere it frames `keep_index` (the killer)
    alone, with gaze room where it looks. A reframe within the shot, not a cut: on the real 4on4
    the pair of a planned kill was seen 0.40-0.45 of its time more than a second before the kill
    (the victim still behind walls) and 0.32-0.53 after it (the victim dead or respawned across
    the map), against 0.77 in the half second before it."""

    keep_index: int
    times_s: tuple[float, ...]
    before_s: float
    after_s: float
    ramp_s: float
    place: Place | None = None  # the pair's place, when the camera's own place is the kept player's (None: one for both)

    def weight(self, time_s: float) -> float:
        """How much of the pair is framed at time_s, s: 1 the pair, 0 the kept player alone, [0, 1]."""
        weight = 0.0
        for event_s in self.times_s:
            outside_s = max(event_s - self.before_s - time_s, time_s - event_s - self.after_s)
            if outside_s <= 0.0:
                return 1.0
            weight = max(weight, 1.0 - outside_s / self.ramp_s)
        return weight


def swung_point(origin: np.ndarray, from_offset: np.ndarray, to_offset: np.ndarray, weight: float) -> np.ndarray:
    """origin plus an offset (3,) that turns from from_offset to to_offset as weight goes 0 -> 1:
    the yaw the shorter way round, the pitch linearly and the length geometrically, so that the
    framed point never passes through origin (a straight blend of a point ahead and a player behind
    would, and the torus through it would shrink to nothing)."""
    lengths = [max(float(np.linalg.norm(o)), 1e-6) for o in (from_offset, to_offset)]
    yaws = [math.atan2(o[0], o[2]) for o in (from_offset, to_offset)]
    pitches = [math.asin(max(-1.0, min(1.0, o[1] / n))) for o, n in zip((from_offset, to_offset), lengths)]
    yaw = yaws[0] + weight * math.remainder(yaws[1] - yaws[0], math.tau)
    pitch = pitches[0] + weight * (pitches[1] - pitches[0])
    length = lengths[0] ** (1.0 - weight) * lengths[1] ** weight
    point: np.ndarray = origin + length * np.array(
        [math.cos(pitch) * math.sin(yaw), math.sin(pitch), math.cos(pitch) * math.cos(yaw)]
    )
    return point


@dataclass(frozen=True)
class Place:
    theta_ratio: float  # along the arc, 0 at A .. 1 at B, [0, 1]
    phi_rad: float  # about the A-B axis, rad
    width: float = 1.0  # the screen points this many times the style's apart (module docstring), [1, 10]

    def eased(self, goal: Place, keep: float) -> Place:
        """The place `keep` of the way back from goal to this one ([0, 1]: 0 is the goal), phi the shorter way round."""
        return Place(
            goal.theta_ratio + keep * (self.theta_ratio - goal.theta_ratio),
            goal.phi_rad - keep * math.remainder(goal.phi_rad - self.phi_rad, math.tau),
            goal.width + keep * (self.width - goal.width),
        )


@functools.lru_cache(maxsize=256)
def _composition(
    style_a: tuple[float, ...], style_b: tuple[float, ...], lens: Lens, width: float
) -> tuple[tuple[float, ...], tuple[float, ...], float]:
    """ToricCamera.composition, made once per style, lens and width (a place search asks thousands of times)."""
    screen_a = tuple(max(-MAX_SCREEN, min(MAX_SCREEN, c * width)) for c in style_a)
    screen_b = tuple(max(-MAX_SCREEN, min(MAX_SCREEN, c * width)) for c in style_b)
    return screen_a, screen_b, composition_angle(screen_a, screen_b, lens)


class ToricCamera:
    """DUEL, FOLLOW or GROUP: the camera on the torus of points A and B (module docstring).
    a_index, b_index: players; b_index None frames A with gaze room. With `stand_world` (3,) m
    set, the camera stands there and turns to frame them as it would from its torus (stand.py)."""

    stand_world: np.ndarray | None = None  # a class default: a camera pickled before stands existed has none

    def __init__(self, kind: ShotKind, a_index: int, b_index: int | None, style: Style, lens: Lens, place: Place):
        self.kind, self.a_index, self.b_index = kind, a_index, b_index
        scale = GROUP_SCREEN_SCALE if kind == ShotKind.GROUP else 1.0
        self.style_a = tuple(c * scale for c in style.screen_a)
        self.style_b = tuple(c * scale for c in style.screen_b)
        self.lens, self.gaze_room_m = lens, style.gaze_room_m
        self.place = self.goal = place
        self.heading: np.ndarray | None = None  # the anchor's smoothed facing (FOLLOW, and a pair framing one)
        self.reach_m: float | None = None  # pulled in front of a wall: how far from A it may stand now (None: free)
        self.seen_again_s: float | None = None  # when program_camera.py last re-placed it to show its subjects, s
        self.pair: PairWindow | None = None  # a planned DUEL: when it frames the pair (None: always)

    @property
    def anchor_index(self) -> int:
        """The player the camera stays on whatever it frames: the pair window's kept one, else A."""
        return self.a_index if self.pair is None else self.pair.keep_index

    def framed(self, time_s: float) -> tuple[int, ...] | None:
        """The players the picture frames at time_s, s, when the pair window frames one alone; None: all of them."""
        if self.pair is None or self.pair.weight(time_s) >= 0.5:
            return None
        return (self.pair.keep_index,)

    def composition(self, width: float) -> tuple[tuple[float, ...], tuple[float, ...], float]:
        """The screen points of A and B (2,) each at a framing width, and their composition angle, rad."""
        return _composition(self.style_a, self.style_b, self.lens, width)

    @property
    def side(self) -> float:
        return math.copysign(1.0, self.place.phi_rad)

    def points(self, moment: Moment) -> tuple[np.ndarray, np.ndarray]:
        """The framed points A and B, (3,) each, at the moment."""
        a = moment.aims_world[self.a_index]
        if self.b_index is None:
            return a, a + self.gaze_room_m * self._heading(moment)
        b = moment.aims_world[self.b_index]
        if self.pair is None:
            return a, b
        weight = self.pair.weight(moment.time_s)
        if weight >= 1.0:
            return a, b
        kept, dropped = (a, b) if self.pair.keep_index == self.a_index else (b, a)
        point = swung_point(kept, self.gaze_room_m * self._heading(moment), dropped - kept, weight)
        return (a, point) if self.pair.keep_index == self.a_index else (point, b)

    def _heading(self, moment: Moment) -> np.ndarray:
        return moment.forward_world[self.anchor_index] if self.heading is None else self.heading

    def torus(self, moment: Moment, width: float) -> Torus | None:
        try:
            return make_torus(*self.points(moment), self.composition(width)[2], UP_WORLD)
        except DegenerateTorus:
            return None

    def positions(self, moment: Moment, places: Sequence[Place]) -> np.ndarray | None:
        """(len(places), 3) camera centres at the moment, None when the framing is degenerate."""
        widths = np.array([p.width for p in places])
        out = np.empty((len(places), 3))
        for width in dict.fromkeys(widths.tolist()):  # one torus per framing width
            torus = self.torus(moment, width)
            if torus is None:
                return None
            rows = np.flatnonzero(widths == width)
            arc = theta_max(torus.alpha)
            theta = arc * THETA_MARGIN + arc * (1.0 - 2.0 * THETA_MARGIN) * np.array(
                [places[r].theta_ratio for r in rows.tolist()]
            )
            out[rows] = torus_position(torus, theta, np.array([places[r].phi_rad for r in rows.tolist()]))
        return out

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        """Glides the place toward the goal and smooths the FOLLOW heading (time constants, s)."""
        keep = math.exp(-dt_s / response_time_s) if dt_s > 0.0 else 1.0
        self.place = self.place.eased(self.goal, keep)
        forward = moment.forward_world[self.anchor_index]
        if self.heading is None:
            self.heading = forward
        elif dt_s > 0.0:
            blend = self.heading + (1.0 - math.exp(-dt_s / HEADING_TIME_CONSTANT_S)) * (forward - self.heading)
            norm = np.linalg.norm(blend)
            self.heading = blend / norm if norm > 1e-6 else forward

    def rotations(self, moment: Moment, positions_world: np.ndarray, places: Sequence[Place]) -> np.ndarray:
        """(m, 3, 3) camera-to-world rotations of pose_from at m positions (m, 3) of their places'
        widths, at once for a pair (geometry.toric.level_pair_matrices), so that the place search
        judges the level picture that is shown (FOLLOW: geometry.camera.level_look_matrices); NaN where degenerate."""
        a, b = self.points(moment)
        widths = np.array([p.width for p in places])
        out = np.empty((len(places), 3, 3))
        for width in dict.fromkeys(widths.tolist()):
            rows = np.flatnonzero(widths == width)
            screen_a, screen_b, _ = self.composition(width)
            out[rows] = (
                level_look_matrices(positions_world[rows], a, screen_a, self.lens)
                if self.b_index is None
                else level_pair_matrices(positions_world[rows], a, b, screen_a, screen_b, self.lens)
            )
        return out

    def pose(self, moment: Moment) -> CameraPose | None:
        place = self.place_at(moment.time_s)
        if self.stand_world is not None:
            return self.pose_from(moment, self.stand_world, place.width)
        positions = self.positions(moment, [place])
        return None if positions is None else self.pose_from(moment, self.above_ground(moment, positions[0]), place.width)

    def above_ground(self, moment: Moment, position_world: np.ndarray) -> np.ndarray:
        """The camera centre (3,) raised straight up to MIN_CAMERA_HEIGHT_M above the lowest feet of
        the players it frames at the moment where its place rides lower. The search never chooses a
        place under the ground (`seen_in_frame`), but a place rides with its players: a pair's
        axis that tilts after the cut (one player jumping or on a stair) carries a phi past 90
        degrees under the floor, where the pull in front of a wall then stopped the camera at
        the floor itself (the cast 2on2's replay of its first kill: 0.13 m over the floor, 2 m
        from the killer, who stood 0.82 of the frame's height at 82 degrees)."""
        framed = self.framed(moment.time_s)
        if framed is None:
            framed = (self.a_index,) if self.b_index is None else (self.a_index, self.b_index)
        ground_m = float(moment.feet_world[list(framed), 1].min()) + MIN_CAMERA_HEIGHT_M
        if position_world[1] >= ground_m:
            return position_world
        return np.array([position_world[0], ground_m, position_world[2]])

    def place_at(self, time_s: float) -> Place:
        """The place the picture is taken from at time_s, s: the camera's own, or, where its pair
        window has a place of its own, that one around the pair's events, eased between the two
        as the framing is."""
        if self.pair is None or self.pair.place is None:
            return self.place
        weight = self.pair.weight(time_s)
        if weight <= 0.0:
            return self.place
        return self.place.eased(self.pair.place, 1.0 - weight)

    @property
    def split(self) -> bool:
        """Whether the camera's own place is its kept player's and the pair window holds the pair's."""
        return self.pair is not None and self.pair.place is not None

    def pose_from(self, moment: Moment, position_world: np.ndarray, width: float) -> CameraPose:
        """The camera at a point (3,) of the torus of a framing width, horizon level (module
        docstring): DUEL and GROUP frame A and B about their screen points (geometry.toric.
        level_pair_rotation), FOLLOW frames A exactly (geometry.camera.level_look_rotation)."""
        a, b = self.points(moment)
        screen_a, screen_b, _ = self.composition(width)
        if self.b_index is None:
            rotation = level_look_rotation(position_world, a, screen_a, self.lens)
        else:
            rotation = level_pair_rotation(position_world, a, b, screen_a, screen_b, self.lens)
        return CameraPose(position_world, rotation, self.lens.vertical_fov_deg)

    def pulled_in(
        self,
        moment: Moment,
        pose: CameraPose,
        hidden: bool,
        ray_scene: RayScene,
        dt_s: float,
        margin_m: float,
        regrow_m_s: float,
        clearance: Callable[[np.ndarray], np.ndarray],
    ) -> tuple[CameraPose, bool]:
        """The pose kept in front of the walls between it and the anchor's aim point (A, or the
        player a pair window keeps), and
        whether it was pulled in: a degrade for the moments the place search did not foresee (a
        player running past a corner at 10 m/s carries its torus through a wall between two plan
        ticks). hidden: whether the place's view of A is mostly blocked (the caller's ray casts to
        A's body): only then does the camera come in, along the line from A to the place, to
        margin_m short of the first wall, as HLTV's chase camera does; it goes back out at
        regrow_m_s (it never jumps out, so a wall flickering in and out of the line does not make
        the picture jump). The rotation is pose_from's at the new point, so the framing of A and B
        is kept as well as it can be. It never comes nearer than where the framed subjects stay
        readable (`clearance`: (m, 3) centres -> (m,) m, negative too near; shot_builder.py
        readable_clearance): a wall nearer A than that leaves the camera behind it (the caller
        keeps the place then, and the rig re-places it), since from nearer no lens shows A under
        the framing band (issue 41: the real 4on4's pulled-in cameras 1.5-2.3 m from their subject
        showed it over 0.6 of the frame's height at 90 degrees)."""
        if not hidden and self.reach_m is None:
            return pose, False
        a = moment.aims_world[self.anchor_index]
        offset = pose.position_world - a
        full_m = float(np.linalg.norm(offset))
        if full_m < 1e-6:
            return pose, False
        direction = offset / full_m
        if self.pair is not None and self.pair.weight(moment.time_s) > 0.0:
            # onto the pair's place, chosen to see both at the kill: out as fast as the reframe moves (at
            # 2 m/s a camera pulled in while the killer was alone was still at its shoulder at the kill)
            regrow_m_s = max(regrow_m_s, full_m / self.pair.ramp_s)
        allowed_m = full_m if self.reach_m is None else self.reach_m + dt_s * regrow_m_s
        if hidden:
            allowed_m = min(allowed_m, float(ray_scene.first_hit(a, direction[None, :])[0]) - margin_m)
        if clearance(pose.position_world[None])[0] < 0.0:  # too near at its place already: stepped_back's
            allowed_m = full_m
        else:  # no nearer than the last readable point coming in
            near = readable_change_m(a, direction, full_m, 0.0, clearance)
            allowed_m = max(allowed_m, 0.0 if near is None else near[0])
        if allowed_m >= full_m:
            self.reach_m = None
            return pose, False
        self.reach_m = max(allowed_m, 0.0)
        return self.pose_from(moment, a + max(self.reach_m, 0.05) * direction, self.place_at(moment.time_s).width), True

    def stepped_back(
        self,
        moment: Moment,
        pose: CameraPose,
        ray_scene: RayScene,
        margin_m: float,
        clearance: Callable[[np.ndarray], np.ndarray],
    ) -> CameraPose:
        """The pose moved out, along the line from the anchor's aim point through it, to where the
        framed subjects stay readable (`clearance`, as pulled_in's) when its place has come too near
        them, as an operator steps back: a DUEL's place over a shoulder stands at A's back, and a
        torus shrinks as its pair closes in (issue 41: on the real 4on4, 118 of 201 frames with a
        player over 0.6 of the frame's height were DUELs' own subjects, about 1 m from the camera
        across). At most STEP_BACK_MAX_M, and never past margin_m short of the first wall behind
        it (an anchor the walls hide from it: not at all); the rotation is pose_from's there."""
        spare_m = float(clearance(pose.position_world[None])[0])
        if spare_m >= 0.0:
            return pose
        a = moment.aims_world[self.anchor_index]
        offset = pose.position_world - a
        full_m = float(np.linalg.norm(offset))
        if full_m < 1e-6:
            return pose
        direction = offset / full_m
        wall_m = float(ray_scene.first_hit(a, direction[None, :])[0]) - margin_m
        farthest_m = min(full_m + STEP_BACK_MAX_M, wall_m)
        if farthest_m <= full_m:
            return pose
        out = readable_change_m(a, direction, full_m, farthest_m, clearance)
        if out is None:  # not readable within reach: as far back as it may go, if that is nearer readable
            if float(clearance((a + farthest_m * direction)[None])[0]) <= spare_m:
                return pose
        out_m = farthest_m if out is None else out[1]
        return self.pose_from(moment, a + out_m * direction, self.place_at(moment.time_s).width)


def readable_change_m(
    origin_world: np.ndarray, direction: np.ndarray, from_m: float, to_m: float, clearance: Callable[[np.ndarray], np.ndarray]
) -> tuple[float, float] | None:
    """Along the ray from origin_world (3,) m in the unit direction (3,), going from from_m to to_m,
    m (either way), the first change of whether `clearance` ((m, 3) centres -> (m,) m) is >= 0
    from what it is at from_m: the last distance like from_m's and the first unlike it, m, found
    on a READABLE_STEP_M grid refined READABLE_REFINEMENTS times (a few millimetres apart, so that
    a camera kept there does not jitter); None where it does not change."""

    def clear(ts: np.ndarray) -> np.ndarray:
        return np.asarray(clearance(origin_world + ts[:, None] * direction) >= 0.0)

    start = bool(clear(np.array([from_m]))[0])
    steps = max(1, math.ceil(abs(to_m - from_m) / READABLE_STEP_M))
    kept_m, step_m, count = from_m, (to_m - from_m) / steps, steps
    changed_m = to_m
    for _ in range(1 + READABLE_REFINEMENTS):  # the grid, then the bracket it found subdivided
        ts = kept_m + step_m * np.arange(1, count + 1)
        changed = np.flatnonzero(clear(ts) != start)
        if not len(changed):  # the grid's pass only: a refinement's last point is the bracket's changed end
            return None
        k = int(changed[0])
        kept_m, changed_m = (float(ts[k - 1]) if k else kept_m), float(ts[k])
        step_m, count = step_m / READABLE_REFINE, READABLE_REFINE
    return kept_m, changed_m


class StaticCamera:
    """OVERVIEW (and the HLTV baseline's fixed cameras): a pose that does not move during the shot."""

    kind = ShotKind.OVERVIEW

    def __init__(self, pose: CameraPose):
        self.fixed_pose = pose

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        """Nothing moves."""

    def pose(self, moment: Moment) -> CameraPose:
        return self.fixed_pose


@functools.cache
def place_grid(side: float | None) -> tuple[Place, ...]:
    """The places tried: every width, ratio and phi, on one side (sign of phi) or both when side is None.
    Made once per side (a plan asks for it at every search; made anew, it was a tenth of a plan's cost)."""
    signs = (1.0, -1.0) if side is None else (side,)
    return tuple(
        Place(float(r), s * float(p), w) for w in PLACE_WIDTHS for s in signs for r in PLACE_RATIOS for p in PLACE_PHI_RAD
    )


def framed_seen(
    visibility: SubjectVisibility,
    moment: Moment,
    subjects: tuple[int, ...],
    positions_world: np.ndarray,
    rotations: np.ndarray,
    lens: Lens,
) -> np.ndarray:
    """(m, len(subjects)) the share of each subject's sample points that each of m cameras,
    positions (m, 3) and camera-to-world rotation matrices (m, 3, 3), sees at the moment:
    unoccluded and inside the frame, and not from under the subjects' ground. A camera whose
    rotation is NaN (a degenerate framing) sees nothing. A pause point of a plan computed in
    slices (infra/slices.py): one batch of ray casts, 0.2-20 ms, whose work is its m * len(subjects)
    * k camera-point pairs. Only the points inside a frame are ray-cast."""
    pause(len(positions_world) * len(subjects) * visibility.k)
    return seen_in_frame(visibility, moment, subjects, positions_world, rotations, lens, from_below=False)


def poses_seen(
    visibility: SubjectVisibility, moment: Moment, subjects: tuple[int, ...], poses: Sequence[CameraPose], lens: Lens
) -> np.ndarray:
    """(len(poses), len(subjects)): each subject's share framed and seen from each pose (framed_seen) through the lens."""
    positions_world = np.array([p.position_world for p in poses])
    rotations = quat_to_matrix(np.array([p.rotation_xyzw for p in poses]))
    return framed_seen(visibility, moment, subjects, positions_world, rotations, lens)


def seen_in_frame(
    visibility: SubjectVisibility,
    moment: Moment,
    subjects: tuple[int, ...],
    positions_world: np.ndarray,
    rotations: np.ndarray,
    lens: Lens,
    from_below: bool,
) -> np.ndarray:
    """framed_seen's shares without its pause; from_below: a camera under the subjects' ground
    sees them too (a player's eye looking down on players below, first_person.py)."""
    screen = project_from_cameras(positions_world, rotations, lens, visibility.points_world(moment, subjects))
    with np.errstate(invalid="ignore"):
        asked = np.asarray((np.abs(screen) <= 1.0).all(axis=2))  # (m, s * k); NaN (behind, degenerate) is False
    if not from_below:
        ground_m = moment.feet_world[list(subjects), 1].min() + MIN_CAMERA_HEIGHT_M
        asked[positions_world[:, 1] < ground_m] = False  # phi past 90 degrees looks from below: not through a floor
    share: np.ndarray = visibility.seen_points(positions_world, moment, subjects, asked).mean(axis=2)
    return share


def best_place(
    camera: ToricCamera,
    places: Sequence[Place],
    moments: list[Moment],
    subjects: tuple[int, ...],
    visibility: SubjectVisibility,
    allowed: Callable[[np.ndarray], np.ndarray] | None = None,
    cut_moment: Moment | None = None,
    weights: list[float] | None = None,
    path: list[Moment] | None = None,
) -> tuple[Place, float]:
    """The place of `places` whose worst-seen subject is best seen (framed_seen), a mean over
    `moments` with `weights` (default equal), and that score in [0, 1]; at a moment where the
    camera's pair window frames its kept player alone, that player is the subject. allowed: (m, 3) positions
    at cut_moment -> (m,) bool (the cut's grammar); places it refuses score -1. path: the moments
    (in time order) of the shot's first min_shot_s, over which a place whose camera would cross a
    wall ranks PATH_WALL_COST lower (`wall_free`; its score stays what it sees). Ties go to the
    earlier place."""
    weights = [1.0] * len(moments) if weights is None else weights
    score = np.zeros(len(places))
    for moment, weight in zip(moments, weights):
        positions = camera.positions(moment, places)
        if positions is None:
            continue
        rotations = camera.rotations(moment, positions, places)
        framed = camera.framed(moment.time_s) or subjects  # a pair window's kept player alone, outside its events
        score += weight * framed_seen(visibility, moment, framed, positions, rotations, camera.lens).min(axis=1)
    score /= max(sum(weights), 1e-9)
    if allowed is not None:
        assert cut_moment is not None  # the grammar judges the cut's moment
        first = camera.positions(cut_moment, places)
        if first is not None:
            score = np.where(allowed(first), score, -1.0)
    ranked = score
    if path:  # the path chooses among the places; the score stays what the place sees
        ranked = np.where((score < 0.0) | wall_free(camera, places, path, visibility), score, score - PATH_WALL_COST)
    best = int(np.argmax(ranked))
    return places[best], float(score[best])


def wall_free(camera: ToricCamera, places: Sequence[Place], path: list[Moment], visibility: SubjectVisibility) -> np.ndarray:
    """(len(places),) bool: which places' camera centres at the path's moments (in time order) are
    joined by segments that meet no level geometry (one cast each, from the earlier centre). A
    moment whose framing is degenerate is skipped."""
    free = np.ones(len(places), dtype=bool)
    last = None
    for moment in path:
        positions = camera.positions(moment, places)
        if positions is None:
            continue
        if last is not None:
            move = positions - last
            rows = np.flatnonzero(free & move.any(axis=1))
            pause(len(rows))
            # ray parameter in units of the move: under 1, the wall is before the next centre
            free[rows[visibility.ray_scene.first_hit(last[rows], move[rows]) < 1.0]] = False
        last = positions
    return free


def overview_pose(
    moments: list[Moment],
    weights: list[float],
    subjects: tuple[int, ...],
    lens: Lens,
    visibility: SubjectVisibility,
    top_height_m: float,
    extra_cameras_world: np.ndarray,
    allowed: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[CameraPose, float]:
    """A high view of the subjects' bounding box over `moments`, looking at its centre, and its
    worst-seen subject's share (framed_seen, a mean over the moments with `weights`). Tries
    OVERVIEW_AZIMUTHS directions at each height up to top_height_m, and the (k, 3) extra camera
    places (the level's graph nodes, when there is a level) within twice the box's viewing
    distance; the best worst-seen subject wins, then the best mean. allowed: (m, 3) camera
    centres -> (m,) bool (the cut's grammar); cameras it refuses score -1. The pose keeps the
    horizon level (roll 0: geometry.camera.level_look_rotation), as every camera of the rig."""
    aims = np.concatenate([m.aims_world[list(subjects)] for m in moments])
    centre = aims.mean(axis=0)
    radius_m = float(np.max(np.linalg.norm((aims - centre)[:, [0, 2]], axis=1))) + 2.0
    distance_m = radius_m / lens.tan_half_fov_y
    above = []
    for height in (*OVERVIEW_HEIGHTS_M, top_height_m):
        for k in range(OVERVIEW_AZIMUTHS):
            azimuth = math.tau * k / OVERVIEW_AZIMUTHS
            horizontal = max(distance_m * math.cos(math.atan2(height, distance_m)), 1.0)
            above.append(centre + np.array([horizontal * math.sin(azimuth), height, horizontal * math.cos(azimuth)]))
    cameras = np.array(above)
    if len(extra_cameras_world):
        near = np.linalg.norm(extra_cameras_world - centre, axis=1) <= 2.0 * max(distance_m, top_height_m)
        cameras = np.concatenate([cameras, extra_cameras_world[near]])
    rotations = level_look_matrices(cameras, centre, (0.0, 0.0), lens)
    seen = np.zeros((len(cameras), len(subjects)))
    for m, w in zip(moments, weights):
        seen = seen + w * framed_seen(visibility, m, subjects, cameras, rotations, lens)
    seen /= max(sum(weights), 1e-9)  # (cameras, subjects)
    worst = seen.min(axis=1)
    if allowed is not None:
        worst = np.where(allowed(cameras), worst, -1.0)
    best = int(np.lexsort((-seen.mean(axis=1), -worst))[0])
    pose = CameraPose(cameras[best], level_look_rotation(cameras[best], centre, (0.0, 0.0), lens), lens.vertical_fov_deg)
    return pose, float(worst[best])
