"""The shot builder: a shot's camera for a kind and subjects, placed by ray casts and the grammar.

Every director of ours that places a Toric camera builds its shots here (our director, planned.py;
the rig's takes and candidates, rig.py and takes.py); a plugin director may too (its context's
`builder`, director_contract.py). The shot's camera comes from shots.py with the grammar of
grammar.py: the line of action of a pair is kept, and a cut that shares subjects with the previous
shot must turn 30 degrees. A DUEL or GROUP (not a human's take) whose best place sees its subjects
under `min_visible` over the moments it must cover is shot as a level OVERVIEW of exactly those
subjects when one of its cameras (above them, or a node of the level's graph), allowed by the
30-degree rule, sees them better; its reason says so ("wide: no level duel place sees both"). The
level Toric pictures cannot show a pair far apart along a corridor, seen only from above it over a
shoulder, one above the other (shots.py).

Framing band: no FOLLOW, GROUP or OVERVIEW place, nor a replacement's place (replacement.py), is
chosen from which a subject would stand taller on screen than `shown_height_max` of the frame's
height at the cut (`within_band`, by distance: a body H m
tall d m away fills H / (2 d tan(fov / 2)) of a level frame), and a FOLLOW's gaze room is
stretched so that at the style's place its player fills `follow_shown_height`. Broadcast shot sizes name the
band: a long (full) shot shows the whole body head to toe, an extreme long shot the body small
in its surroundings; a medium shot cuts the body at the waist, too close for a player who runs
and jumps in and out of it. So a shot here is a long to extreme long shot, never a medium one.
A DUEL's places are held to less: the place of a kill's pair is the one that sees both past the
walls, often over a shoulder (on the real 4on4 and 2on2, held to the band too, kill coverage fell
0.671 -> 0.603 and 0.643 -> 0.536; with DUELs free the 4on4 kept 0.671), so a DUEL's place is
only one at its subjects' readable distance (`readable_clearance`: from nearer, no lens the rig
goes to shows them under the band's top) or one the program camera can step back from to it
before a wall (shots.py stepped_back). Refusing those too cost the open nav_test's bot match
kill coverage 0.721 -> 0.623: there, every over-the-shoulder place can step back.

Through a player's eyes (first_person.py): a shot our director plans for its events, or a
discretionary FOLLOW of one player, not a human's take nor a replay, is taken through its kept
player's eyes when from there it shows its other subjects at each event (`through_eyes`); its
reason ends "through P's eyes" and its choice names P (`eyes_id`). Else a planned shot may stand
at a level node (stand.py), else it rides its torus.

Candidates (`candidate_camera`): a situation is offered beside the program only when its camera,
at the style's place, shows at least `candidate_min_shown` of its subjects at that moment.

A killer framed alone at the cut (a planned DUEL's pair window, shots.py `PairWindow`) is on air
from the cut: its place is ranked by its camera's path over the shot's first `min_shot_s` too
(shots.py `wall_free`), a place whose camera would cross a wall on the way ranked PATH_WALL_COST
lower. On the real duel's first 3 minutes, 3 of its 7 shots under 2 s were one such killer's
camera meeting walls in corridors every 1.2-1.8 s (issue 41, item 3): 3 shots under 2 s after.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.pipeline.inputs import EventKind
from camdirector.pipeline.match.first_person import FirstPersonCamera, through_eyes
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.grammar import Grammar
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import Shot
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import (
    PATH_STEP_S,
    READABLE_STEP_M,
    STEP_BACK_MAX_M,
    PairWindow,
    Place,
    StaticCamera,
    ToricCamera,
    best_place,
    framed_seen,
    overview_pose,
    place_grid,
)
from camdirector.pipeline.match.stand import best_stand
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.pipeline.style import Style

ALONE_GAP_S = 0.6  # a killer alone this long before its pair's window is also placed for halfway, s
ALONE_AFTER_S = 0.5  # and for this long after the window closes, s


def within_band(
    visibility: SubjectVisibility,
    lens: Lens,
    settings: MatchSettings,
    subjects: tuple[int, ...],
    moment: Moment,
    allowed: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Callable[[np.ndarray], np.ndarray]:
    """(m, 3) camera centres at the moment -> (m,) bool: those `allowed` allows (None: all) from
    which no subject stands taller on screen than shown_height_max (module docstring); a body's
    height is its sample points' extent. The builder's places and the replacement's (replacement.py)."""
    aims = moment.aims_world[list(subjects)]  # (s, 3)
    heights_m = np.array([np.ptp(visibility.samples_local[i][:, 1]) for i in subjects])
    nearest_m = heights_m / (2.0 * settings.shown_height_max * lens.tan_half_fov_y)

    def within(positions: np.ndarray) -> np.ndarray:
        far: np.ndarray = (np.linalg.norm(positions[:, None, :] - aims[None], axis=2) >= nearest_m).all(axis=1)
        return far if allowed is None else far & allowed(positions)

    return within


def readable_clearance(
    visibility: SubjectVisibility, lens: Lens, settings: MatchSettings, subjects: tuple[int, ...], moment: Moment
) -> Callable[[np.ndarray], np.ndarray]:
    """(m, 3) camera centres at the moment -> (m,) m: how much farther each stands from the nearest
    of the subjects' bodies than that body's readable distance (negative: too near for any lens
    the rig goes to). A body is an upright cylinder about its feet, from its outline's lowest to
    highest point (SubjectVisibility.outlines_local), as wide as the outline's farthest point from
    its axis (bodies turn by yaw alone); the distance is to its nearest point.

    The readable distance: a body H m tall whose nearest point is rho m from the camera subtends
    at most 2 atan(H / 2 rho) (square to the line of sight and centred on it); centred in a frame
    of vertical field of view F it fills tan(alpha / 2) / tan(F / 2) <= H / (2 rho tan(F / 2)) of
    the frame's height. So at rho >= H / (2 shown_height_max tan(F_max / 2)), F_max the widest lens
    (widen_max_fov_deg, lens_width.py), no lens width can show it over the band's top (0.5: 1.75 m
    for a 1.75 m player at 90 deg), and it stays under issue 41's 0.6 with its centre up to about
    21 deg off the frame's middle (off centre, perspective stretches it: tan(c + alpha / 2) -
    tan(c - alpha / 2)). Nearer, the widest lens cannot save the picture (issue 41: on the real
    4on4, 190 of 201 frames with a player over 0.6 had the shot's own subject 1.5-2.3 m from the
    camera, about 1 m from its upright axis, the lens at 90 deg)."""
    widest = math.tan(math.radians(max(settings.widen_max_fov_deg, lens.vertical_fov_deg)) / 2.0)
    feet_world = moment.feet_world[list(subjects)]  # (s, 3) m
    outlines = [moment.transforms[i].apply(visibility.outlines_local[i]) - f for i, f in zip(subjects, feet_world)]
    bottom_y = feet_world[:, 1] + np.array([o[:, 1].min() for o in outlines])  # (s,) m
    top_y = feet_world[:, 1] + np.array([o[:, 1].max() for o in outlines])
    radius_m = np.array([np.hypot(o[:, 0], o[:, 2]).max() for o in outlines])  # (s,) its girth about its axis
    nearest_m = (top_y - bottom_y) / (2.0 * settings.shown_height_max * widest)  # (s,)

    def clearance(positions_world: np.ndarray) -> np.ndarray:
        offset = positions_world[:, None, [0, 2]] - feet_world[None, :, [0, 2]]  # (m, s, 2)
        across = np.maximum(0.0, np.linalg.norm(offset, axis=2) - radius_m[None])  # (m, s) to its girth
        height = positions_world[:, None, 1]
        along = np.maximum(0.0, np.maximum(bottom_y[None] - height, height - top_y[None]))  # (m, s) above or below it
        spare: np.ndarray = (np.hypot(across, along) - nearest_m[None]).min(axis=1, initial=np.inf)
        return spare

    return clearance


class ShotBuilder:
    """Makes a shot's camera for a kind and subjects, placed by ray casts and the grammar."""

    def __init__(
        self,
        players: list[str],
        style: Style,
        lens: Lens,
        settings: MatchSettings,
        visibility: SubjectVisibility,
        grammar: Grammar,
        extra_overview_cameras: np.ndarray,
    ):
        self.players, self.style, self.lens = players, style, lens
        self.settings, self.visibility, self.grammar = settings, visibility, grammar
        self.extra_overview_cameras = extra_overview_cameras
        # (n,) m: each player's body height (its mesh's extent: the sample points fall short of the head and
        # feet, 1.39 m of a real 1.75-m player), for the framing band and the eye of a first-person shot
        self.body_heights_m = np.array([np.ptp(points[:, 1]) for points in visibility.outlines_local])

    @property
    def upright(self) -> float:
        """The sign of phi where the style's composition is upright (geometry/toric.py: seen from
        phi = +pi/2, A is on the left)."""
        return 1.0 if self.style.screen_a[0] <= self.style.screen_b[0] else -1.0

    def default_place(self) -> Place:
        return Place(self.style.preferred_theta_ratio, self.upright * math.radians(self.style.preferred_phi_deg))

    def cameras(
        self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment, default: bool
    ) -> list[tuple[ToricCamera, Sequence[Place]]]:
        """The Toric cameras a shot may use, each with the places to try (default: the style's only)."""
        if kind == ShotKind.FOLLOW:
            camera = ToricCamera(kind, subjects[0], None, self.style, self.lens, self.default_place())
            camera.gaze_room_m = self._follow_gaze_room_m(camera, subjects[0], moment)
            return [(camera, [self.default_place()] if default else place_grid(None))]
        if kind == ShotKind.DUEL:
            i, j = subjects
            left = self.grammar.duel_left(self.players[i], self.players[j])
            orders = [(i, j), (j, i)] if left is None else [(i, j) if self.players[i] == left else (j, i)]
        else:  # GROUP: the two players farthest apart frame the rest
            aims = moment.aims_world[list(subjects)]
            d = np.linalg.norm(aims[:, None] - aims[None], axis=2)
            a, b = np.unravel_index(int(np.argmax(d)), d.shape)
            orders = [(subjects[a], subjects[b]), (subjects[b], subjects[a])]
        grid = [self.default_place()] if default else place_grid(self.upright)
        return [
            (ToricCamera(kind, a, b, self.style, self.lens, self.default_place()), grid)
            for a, b in (orders[:1] if default else orders)
        ]

    def _follow_gaze_room_m(self, camera: ToricCamera, subject: int, moment: Moment) -> float:
        """The gaze room, m, that puts a FOLLOW's camera at the style's place where its subject fills
        follow_shown_height of the frame's height (module docstring), never less than the style's:
        the torus, and the camera's distance with it, grows in proportion to the gaze room."""
        positions = camera.positions(moment, [self.default_place()])
        if positions is None:
            return camera.gaze_room_m
        distance_m = float(np.linalg.norm(positions[0] - moment.aims_world[subject]))
        wanted_m = float(self.body_heights_m[subject]) / (2.0 * self.settings.follow_shown_height * self.lens.tan_half_fov_y)
        return camera.gaze_room_m * max(1.0, wanted_m / max(distance_m, 1e-6))

    def candidate_camera(self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment) -> ToricCamera | None:
        """The camera a candidate situation is offered with (the style's place), None when at the
        moment it shows under candidate_min_shown of its subjects, each shown with candidate_seen of
        its points seen (module docstring): a preview of walls is no choice. One batch of
        len(subjects) * samples_per_player ray casts per situation, at the planner's rate."""
        camera = self.cameras(kind, subjects, moment, default=True)[0][0]
        places = [camera.place]
        positions = camera.positions(moment, places)
        if positions is None:
            return None
        seen = framed_seen(self.visibility, moment, subjects, positions, camera.rotations(moment, positions, places), self.lens)
        s = self.settings
        return camera if float((seen[0] >= s.candidate_seen).mean()) >= s.candidate_min_shown else None

    def _within_band(
        self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment, allowed: Callable[[np.ndarray], np.ndarray] | None
    ) -> Callable[[np.ndarray], np.ndarray]:
        """The band of a kind's places (module docstring): a DUEL's, its readable distance alone."""
        if kind != ShotKind.DUEL:
            return within_band(self.visibility, self.lens, self.settings, subjects, moment, allowed)
        clearance = readable_clearance(self.visibility, self.lens, self.settings, subjects, moment)
        aims = moment.aims_world[list(subjects)]  # (s, 3)

        def readable(positions_world: np.ndarray) -> np.ndarray:
            ok = np.asarray(clearance(positions_world) >= 0.0)
            near = np.flatnonzero(~ok)
            if len(near):  # those whose step back (program_camera.py) reaches the readable distance before a wall
                ok[near] = self._steppable(positions_world[near], aims, clearance)
            return ok if allowed is None else ok & allowed(positions_world)

        return readable

    def _steppable(
        self, positions_world: np.ndarray, aims_world: np.ndarray, clearance: Callable[[np.ndarray], np.ndarray]
    ) -> np.ndarray:
        """(m,) bool: which of m camera centres (m, 3) too near their subjects reach a readable one
        (`clearance` >= 0) stepping back along the line from the nearest subject's aim point (aims
        (s, 3)) within STEP_BACK_MAX_M and pull_margin_m short of the first wall (shots.py
        stepped_back, which steps back from the shot's anchor: mostly the one it stands too near)."""
        nearest = np.linalg.norm(positions_world[:, None] - aims_world[None], axis=2).argmin(axis=1)
        origins = aims_world[nearest]  # (m, 3)
        offsets = positions_world - origins
        full_m = np.maximum(np.linalg.norm(offsets, axis=1), 1e-6)
        directions = offsets / full_m[:, None]
        back_m = READABLE_STEP_M * np.arange(1, round(STEP_BACK_MAX_M / READABLE_STEP_M) + 1)  # (t,)
        tried = positions_world[:, None] + back_m[None, :, None] * directions[:, None]  # (m, t, 3)
        clear = clearance(tried.reshape(-1, 3)).reshape(len(positions_world), len(back_m)) >= 0.0
        needed_m = full_m + back_m[clear.argmax(axis=1)]  # (m,) the first readable point's distance
        free_m = self.visibility.ray_scene.first_hit(origins, directions) - self.settings.pull_margin_m
        return np.asarray(clear.any(axis=1) & (needed_m <= free_m))

    def _best(
        self,
        kind: ShotKind,
        subjects: tuple[int, ...],
        moment: Moment,
        cover: list[Moment],
        weights: list[float] | None,
        allowed: Callable[[np.ndarray], np.ndarray] | None,
        pair: PairWindow | None = None,
    ) -> tuple[ToricCamera, Place, float]:
        """The camera (of those cameras() offers at the moment, with the pair window of a planned
        DUEL) and place that best see the subjects over cover, and its score (-1: the grammar
        refuses every place)."""
        best: tuple[ToricCamera, Place, float] | None = None
        for camera, places in self.cameras(kind, subjects, moment, default=False):
            camera.pair = pair
            place, score = best_place(camera, places, cover, subjects, self.visibility, allowed, moment, weights)
            if best is None or score > best[2]:
                best = (camera, place, score)
        assert best is not None  # every kind offers a camera
        return best

    def place_score(
        self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment, cover: list[Moment], weights: list[float]
    ) -> float:
        """How well the best place of a shot from the moment on sees the subjects over cover, [0, 1]."""
        if kind == ShotKind.OVERVIEW:
            return self._overview(subjects, cover, weights)[1]
        return self._best(kind, subjects, moment, cover, weights, None)[2]

    def _overview(
        self,
        subjects: tuple[int, ...],
        cover: list[Moment],
        weights: list[float],
        allowed: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> tuple[CameraPose, float]:
        return overview_pose(
            cover,
            weights,
            subjects,
            self.lens,
            self.visibility,
            self.settings.overview_height_m,
            self.extra_overview_cameras,
            allowed,
        )

    def build(
        self,
        choice: ShotChoice,
        subjects: tuple[int, ...],
        moment: Moment,
        cover: list[Moment],
        previous: Shot | None,
        previous_pose: CameraPose | None,
        start_s: float,
        weights: list[float] | None = None,
        events_s: tuple[float, ...] = (),
        buffer: MomentBuffer | None = None,
    ) -> tuple[Shot | None, float]:
        """A shot showing `subjects` from `moment` on, placed for the moments in `cover` (with
        `weights`, default equal), respecting the 30-degree rule against the previous picture at
        `moment`; and its place's score. None (and -1) when no place respects the rule. A DUEL or
        GROUP whose best place scores under min_visible is a wide OVERVIEW of its subjects when
        one sees them better (module docstring).

        A DUEL planned for events at events_s, s, frames its pair around them only, its first
        subject (the killer) alone elsewhere (shots.py `PairWindow`). When the cut itself shows the
        killer alone, the pair's place is chosen for the events as before, without the 30-degree
        rule (the pair is not on screen at the cut), and the killer's own place from all of the
        grid for the moments it is alone (`_alone_cover`, read from `buffer`), with the rule."""
        if choice.kind == ShotKind.OVERVIEW:
            # everybody when nobody is named and nobody alive (all dead between rounds): a view of the map, not an error
            shown = subjects or tuple(int(i) for i in np.flatnonzero(moment.alive)) or tuple(range(len(moment.alive)))
            pose, seen = self._overview(shown, cover, [1.0] * len(cover) if weights is None else weights)
            return Shot(choice, subjects, StaticCamera(pose), start_s), seen
        previous_framed = set() if previous is None else set(previous.framed(moment.time_s))
        previous_world = None if previous_pose is None else previous_pose.position_world

        def allowed_after(framed: tuple[int, ...]) -> Callable[[np.ndarray], np.ndarray]:
            """The 30-degree rule for a cut from the previous picture to one framing `framed`,
            within the framing band (a DUEL: its readable distance; module docstring)."""
            shared = list(previous_framed & set(framed))
            rule = functools.partial(self.grammar.allows_cut, previous_world, moment.aims_world[shared])
            return self._within_band(choice.kind, framed, moment, rule)

        s = self.settings
        pair = (
            PairWindow(subjects[0], events_s, s.pair_before_s, s.pair_after_s, s.reframe_s)
            if events_s and choice.kind == ShotKind.DUEL
            else None
        )
        alone = pair is not None and buffer is not None and pair.weight(moment.time_s) <= 0.0
        allowed = allowed_after(subjects)
        band = self._within_band(choice.kind, subjects, moment, None)
        camera, place, score = self._best(choice.kind, subjects, moment, cover, weights, band if alone else allowed, pair)
        if score < s.min_visible and not choice.held:  # a wide view of them may see them better
            pose, seen = self._overview(subjects, cover, [1.0] * len(cover) if weights is None else weights, allowed)
            # a killer shown alone until its kill sees more than a static view seeing the pair under min_visible
            if seen > max(score, 0.0) and (seen >= s.min_visible or not alone):
                what = "both" if choice.kind == ShotKind.DUEL else "them all"
                wide = replace(
                    choice,
                    kind=ShotKind.OVERVIEW,
                    reason=f"{choice.reason}; wide: no level {choice.kind.name.lower()} place sees {what}",
                )
                return Shot(wide, subjects, StaticCamera(pose), start_s), seen
        if alone and score >= 0.0:
            assert pair is not None and buffer is not None  # `alone` needs both
            keep = (pair.keep_index,)
            camera.pair = replace(pair, place=place)
            place, alone_score = best_place(
                camera,
                place_grid(None),
                self._alone_cover(pair, moment, buffer),
                keep,
                self.visibility,
                allowed_after(keep),
                moment,
                path=self._path(moment, buffer),  # on air from the cut: a wall on its way would cut it short
            )
            score = score if alone_score >= 0.0 else -1.0
        if score < 0.0:
            return None, -1.0
        camera.place = camera.goal = place
        planned = buffer if events_s else None  # a planned shot: its events and the buffer that holds them
        if s.first_person and not choice.held and choice.replay is None:
            kills_ahead = not events_s and self._kills_ahead(camera.anchor_index, moment, buffer)  # read by a FOLLOW alone
            eyes = through_eyes(
                camera, subjects, buffer, moment, events_s, self.visibility, self.body_heights_m, s, cover, kills_ahead
            )
            if eyes is not None and self._eyes_allowed(eyes, previous, previous_framed, previous_world, moment, subjects):
                # first_person.py: no wall to meet, no cut within the shot
                who = self.players[eyes.player]
                choice = replace(choice, reason=f"{choice.reason}; through {who}'s eyes", eyes_id=who)
                return Shot(choice, subjects, eyes, start_s), score
        if planned is not None:  # where it stands, when a level node sees it through
            framed_at_cut = camera.framed(moment.time_s) or subjects
            camera.stand_world = best_stand(
                camera,
                subjects,
                planned,
                moment,
                events_s,
                self.extra_overview_cameras,
                self.visibility,
                self.body_heights_m,
                s,
                allowed_after(framed_at_cut),
            )
            if camera.stand_world is not None:
                choice = replace(choice, reason=f"{choice.reason}; standing where it sees them through")
        if choice.kind == ShotKind.DUEL:
            assert camera.b_index is not None  # a DUEL's camera frames two
            self.grammar.remember_duel(self.players[camera.a_index], self.players[camera.b_index])
        return Shot(choice, subjects, camera, start_s), score

    def _kills_ahead(self, player: int, moment: Moment, buffer: MomentBuffer | None) -> bool:
        """Whether the player kills or dies in the buffered future after the moment."""
        if buffer is None:
            return False
        who = self.players[player]
        return any(
            e.kind == EventKind.KILL and who in (e.actor_id, e.other_actor_id)
            for e in buffer.events_between(moment.time_s, buffer.horizon_s)
        )

    def _eyes_allowed(
        self,
        eyes: FirstPersonCamera,
        previous: Shot | None,
        previous_framed: set[int],
        previous_world: np.ndarray | None,
        moment: Moment,
        subjects: tuple[int, ...],
    ) -> bool:
        """Whether a cut to the eyes keeps the 30-degree rule against the previous picture (not a
        cut at all through the eyes the previous shot looked through: rig.py goes on with it)."""
        if previous is not None and isinstance(previous.camera, FirstPersonCamera) and previous.camera.player == eyes.player:
            return True
        shared = list(previous_framed & set(eyes.framed(moment.time_s) or subjects))
        eye_world = eyes.pose(moment).position_world
        return bool(self.grammar.allows_cut(previous_world, moment.aims_world[shared], eye_world)[0])

    def _path(self, moment: Moment, buffer: MomentBuffer) -> list[Moment]:
        """The moments of a new shot's first min_shot_s, every PATH_STEP_S, as far as the buffer
        reaches (best_place's `path`)."""
        times = moment.time_s + PATH_STEP_S * np.arange(math.floor(self.style.min_shot_s / PATH_STEP_S) + 1)
        return [buffer.at(float(t)) for t in times if t <= buffer.horizon_s]

    @staticmethod
    def _alone_cover(pair: PairWindow, moment: Moment, buffer: MomentBuffer) -> list[Moment]:
        """The moments a planned DUEL's killer is framed alone, its own place is chosen for: the
        cut, halfway to the pair's window when that is over ALONE_GAP_S away, and ALONE_AFTER_S
        after the window closes when the buffer reaches it."""
        now = moment.time_s
        opens = pair.times_s[0] - pair.before_s - pair.ramp_s
        closed = pair.times_s[-1] + pair.after_s + pair.ramp_s + ALONE_AFTER_S
        times = (
            [now]
            + ([0.5 * (now + opens)] if opens - now > ALONE_GAP_S else [])
            + ([closed] if closed <= buffer.horizon_s else [])
        )
        return [buffer.at(t) for t in times]
