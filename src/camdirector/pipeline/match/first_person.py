"""Through a player's eyes: the first-person view, the autotrack's camera and a shot our director
may take (issue 41, item 3: a rhythm casters use).

A QuakeWorld spectator who tracks a player sees that player's own view, the eye DEFAULT_VIEWHEIGHT
(22 units) above its origin, 16 below it for a corpse (ezQuake cl_cam.c Cam_Track with
cl_chasecam 1, cl_view.c V_CalcRefdef). `FirstPersonCamera` is that view through the level camera
of look_along.py (the horizon kept level, as every MATCH camera: the wire carries the body's yaw,
not the view's pitch), at the eye height of the body's own height (Quake's 46 of 56 units, 1.44 m
for its 1.75-m player). It needs nothing of the level: a player's eye is where the game let it be,
so it is never pulled in, held before a wall or moved inside (program_camera.py); a teleport or a
respawn moves it through walls, and the rig cuts there as for any camera. Only where a demo puts
the eye inside solid (the frames it interpolates across a teleport) does the picture stay where
it was until the eye is back in the level.

Why our director takes it: a Toric camera (shots.py) follows its player from outside, and in the
real matches' corridors every wall between its last place and its next was a cut within the shot:
on the real 4on4's first 3 minutes the director's own 55 shots (median 3.1 s, none under 2 s)
were cut into 147 by 89 such cuts, median 0.8 s. A player's own view never meets a wall, and it
is how QuakeWorld and Counter-Strike broadcasts show most of a match (the casters' spectator
tracks a player; HLTV's director and GOTV's observers sit in a player's eyes between fights).
From the killer's eyes, the victim is in the frame and unhidden at the moment of the kill in
0.78-0.93 of the real matches' kills (level view, 16:9 at 73.7 degrees vertical).

`through_eyes` decides it for a shot at its cut, with the buffered future: a planned shot (a
DUEL, GROUP or FOLLOW for its events) is taken through its kept player's eyes (the Toric camera's
anchor: a DUEL's killer) when from there each of its other subjects is shown: near enough to read
(`eyes_shown_height_min` of the frame's height: a kill seen from 20 m away in first person is a
speck; on the eight development matches, without it, the median shown height fell under 0.15 on
five of them, the duel's from 0.28 to 0.13), its aim point (the chest) inside the frame and
`eyes_seen` of its points in the frame and unhidden, at every event's moment and the frame
eval-match judges the kill at (the first at or after it: `_event_moments`). It is also taken when
its Toric camera would meet a wall (its place, carried by the players over the shot's moments,
passes through level geometry: a cut within the shot) and the eyes show the others at some moment
of the `eyes_lead_s` before each event: the fight is seen, if not always its very moment. Not
where the eyes do not see the others at an event at all (`eyes_seen` of their points in the frame
and unhidden, however far) while the Toric camera's own place does (framed_seen, the worst-seen
framed subject, at each event's moment and the frame eval-match judges it at): there the kill is
the Toric camera's, walls and all. On the real 2on2's first 3 minutes the lead took the eyes for 9 planned
shots, and 5 of their kills were missed (the killer turned away, or the victim behind a corner at
a rocket's splash): kill coverage 0.464 -> 0.679 there, 0.562 -> 0.589 on the 4on4, 0.929 -> 1.0
on the duel, for more cuts within those shots (shots under 2 s 7 -> 10, 5 -> 11, 9 -> 10). A
discretionary FOLLOW of one player (no event to show) always is; a discretionary shot of several
(a fight) when the eyes show the others at every moment it is placed for (the cut and up to 3 s
ahead: planned.py OPTION_COVER_S): on the real duel's first 3 minutes its Toric fights were
behind 6 of its 30 shots under 2 s. A discretionary FOLLOW whose eyes show no other player
readable (`follow_eyes_height_min` of the frame's height, median over the moments it is placed
for, players shown at half of them or more) is the Toric camera's instead, and so is a planned
shot of one player alone (an objective it takes, a suicide: there is no other subject to show,
and through its eyes the viewer sees the objective but not who takes it), where that camera,
carried by its player to the buffer's horizon, meets no wall and sees its player with
`min_visible` at every `stand_step_s`; unless (a discretionary FOLLOW) its player kills or dies
within the buffered future (its planned shot will likely be through the same eyes, and the
picture goes on uncut). A view through a player's eyes does not show that player, and on an open level the others are far off in
it: on sim_zdm2 the median shown height went 0.1495 -> 0.2185, on sim_undulating 0.106 -> 0.120,
with the real matches' programs unchanged (their corridors meet a wall within the horizon).
The picture then names the kept player alone away from a DUEL's events, as its Toric camera would
(its `PairWindow`, shots.py), and the pair around them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.quake_frame import M_PER_UNIT, ORIGIN_ABOVE_FEET_UNITS, PLAYER_HEIGHT_M
from camdirector.geometry.transforms import quat_rotate, quat_to_matrix
from camdirector.pipeline.match.look_along import look_along
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import PairWindow, ToricCamera, seen_in_frame
from camdirector.pipeline.match.stand import scores_from, shot_moments
from camdirector.pipeline.match.visibility import SubjectVisibility

VIEWHEIGHT_UNITS = 22.0  # DEFAULT_VIEWHEIGHT: the eye above a living player's origin
CORPSE_VIEWHEIGHT_UNITS = -16.0  # cl_view.c: a corpse's eye below its origin
EYE_ABOVE_FEET_M = (ORIGIN_ABOVE_FEET_UNITS + VIEWHEIGHT_UNITS) * M_PER_UNIT
CORPSE_EYE_ABOVE_FEET_M = (ORIGIN_ABOVE_FEET_UNITS + CORPSE_VIEWHEIGHT_UNITS) * M_PER_UNIT
EYE_HEIGHT_FRACTION = EYE_ABOVE_FEET_M / PLAYER_HEIGHT_M  # of a body's height: Quake's 46 / 56
CORPSE_EYE_FRACTION = CORPSE_EYE_ABOVE_FEET_M / PLAYER_HEIGHT_M


class FirstPersonCamera:
    """A player's own view (module docstring): the eye eye_above_feet_m over its feet (a corpse's
    corpse_eye_above_feet_m), looking along its facing through `lens`; `pair`: the planned DUEL
    window that names the pair around its events and the kept player alone elsewhere (None: its
    shot names its subjects throughout); `faces_killer`: a corpse's eye looks at its killer.

    The corpse's view: QuakeWorld's spectator keeps looking where the body faced (rolled 80
    degrees, cl_view.c), so the picture after a followed player's death is usually a floor or a
    wall: on the real 2on2 at 31 Hz, 14 frames of nobody after a rocket, its killer 4-10 m off
    the corpse's line of sight and seen whole from its eye. Games since look at the killer (Quake
    II's LookAtKiller turns the dead player's view yaw to the attacker; Source's death cam turns
    to it over half of DEATH_ANIMATION_TIME), and so does our director's camera through the eyes
    (`eyes_camera`): from the corpse's eye, level, at the killer's aim point while the killer
    lives (Moment.killers), at once as the game's own view changes at death. The autotrack's
    camera is the game's picture and keeps the body's facing."""

    # class defaults: an autotrack camera pickled into a checkpoint before these existed has none
    pair: PairWindow | None = None
    eye_above_feet_m: float = EYE_ABOVE_FEET_M
    corpse_eye_above_feet_m: float = CORPSE_EYE_ABOVE_FEET_M
    faces_killer: bool = False

    def __init__(
        self,
        player: int,
        lens: Lens,
        eye_above_feet_m: float = EYE_ABOVE_FEET_M,
        corpse_eye_above_feet_m: float = CORPSE_EYE_ABOVE_FEET_M,
        pair: PairWindow | None = None,
        faces_killer: bool = False,
    ):
        self.player, self.lens, self.pair = player, lens, pair
        self.eye_above_feet_m, self.corpse_eye_above_feet_m = eye_above_feet_m, corpse_eye_above_feet_m
        self.faces_killer = faces_killer

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        """Nothing to smooth: the view is the player's own."""

    def pose(self, moment: Moment) -> CameraPose:
        transform = moment.transforms[self.player]
        height = self.eye_above_feet_m if moment.alive[self.player] else self.corpse_eye_above_feet_m
        eye = transform.position_world + np.array([0.0, height, 0.0])
        forward = quat_rotate(transform.rotation_xyzw, np.array([0.0, 0.0, 1.0]))
        killer = self._killer(moment)
        if killer is not None:
            forward = moment.aims_world[killer] - eye
        if math.hypot(forward[0], forward[2]) < 1e-6:  # straight up or down: a level camera needs a heading
            forward = moment.forward_world[self.player]
        return look_along(eye, forward, self.lens.vertical_fov_deg)

    def _killer(self, moment: Moment) -> int | None:
        """The living killer a dead player's eye looks at (class docstring), None where it looks
        along the body: alive, no killer known, or the killer dead too."""
        if not self.faces_killer or moment.alive[self.player] or moment.killers is None:
            return None
        killer = int(moment.killers[self.player])
        return killer if killer >= 0 and moment.alive[killer] else None

    def framed(self, time_s: float) -> tuple[int, ...] | None:
        """The player the picture names alone at time_s, s, away from its pair's events; None: all its subjects."""
        if self.pair is None or self.pair.weight(time_s) >= 0.5:
            return None
        return (self.player,)


def eyes_camera(
    player: int, body_height_m: float, lens: Lens, settings: MatchSettings, pair: PairWindow | None = None
) -> FirstPersonCamera:
    """Our director's first-person camera of a player whose body is body_height_m tall: Quake's eye
    heights scaled to it, the lens's aspect at `eyes_fov_deg`, a corpse's eye on its killer."""
    return FirstPersonCamera(
        player,
        Lens(settings.eyes_fov_deg, lens.aspect),
        EYE_HEIGHT_FRACTION * body_height_m,
        CORPSE_EYE_FRACTION * body_height_m,
        pair,
        faces_killer=True,
    )


def seen_through(
    visibility: SubjectVisibility, moment: Moment, subjects: tuple[int, ...], pose: CameraPose, lens: Lens
) -> np.ndarray:
    """(len(subjects),) the share of each subject's sample points in the frame of `pose` and
    unhidden by the level (eval-match's shown fraction; no floor rule: an eye looks down on a
    player below as the game shows it)."""
    rotation = quat_to_matrix(pose.rotation_xyzw[None])
    share: np.ndarray = seen_in_frame(visibility, moment, subjects, pose.position_world[None], rotation, lens, from_below=True)[0]
    return share


def through_eyes(
    toric: ToricCamera,
    subjects: tuple[int, ...],
    buffer: MomentBuffer | None,
    cut: Moment,
    events_s: tuple[float, ...],
    visibility: SubjectVisibility,
    body_heights_m: np.ndarray,
    settings: MatchSettings,
    cover: Sequence[Moment] = (),
    kills_ahead: bool = False,
) -> FirstPersonCamera | None:
    """The shot's camera through its kept player's eyes (module docstring), or None (`toric` is
    the camera the shot would otherwise have from the cut: its anchor, pair window and torus;
    `cover`, the moments a discretionary shot is placed for; `kills_ahead`, whether the kept
    player kills or dies in the buffered future)."""
    eyes = toric.anchor_index
    camera = eyes_camera(eyes, float(body_heights_m[eyes]), toric.lens, settings, toric.pair)
    others = tuple(i for i in subjects if i != eyes)
    if not others:
        if kills_ahead or buffer is None or not cover:
            return camera
        if _shows_readable(camera, cover, visibility, body_heights_m, settings):
            return camera
        ahead = [buffer.at(t) for t in np.arange(cover[0].time_s, buffer.horizon_s + 1e-9, settings.stand_step_s)]
        if _path_meets_a_wall(toric, ahead, visibility):
            return camera
        seen = [scores_from(toric, subjects, [m], [1.0], None, visibility)[0] for m in ahead]
        return None if min(seen) >= settings.min_visible else camera
    if not events_s:  # a discretionary shot: the others shown at every moment it is placed for
        return camera if all(shows_at(camera, others, m, visibility, body_heights_m, settings) for m in cover) else None
    if buffer is None:
        return None
    at_events = _event_moments(buffer, events_s)
    if all(shows_at(camera, others, m, visibility, body_heights_m, settings) for m in at_events):
        return camera
    if not _meets_a_wall(toric, buffer, cut, events_s, visibility, settings):
        return None
    if _only_toric_sees(camera, toric, subjects, others, at_events, visibility, settings):
        return None
    lead = np.arange(0.0, settings.eyes_lead_s + 1e-9, settings.stand_step_s / 2.0)
    for event_s in events_s:
        moments = [buffer.at(min(event_s - dt, buffer.horizon_s)) for dt in lead]
        if not any(shows_at(camera, others, moment, visibility, body_heights_m, settings) for moment in moments):
            return None
    return camera


def _only_toric_sees(
    camera: FirstPersonCamera,
    toric: ToricCamera,
    subjects: tuple[int, ...],
    others: tuple[int, ...],
    moments: list[Moment],
    visibility: SubjectVisibility,
    settings: MatchSettings,
) -> bool:
    """Whether, at some of the moments (each event's and the one eval-match judges it at), the
    eyes see the others under eyes_seen (in the frame and unhidden, whatever their distance) while
    at every one of them the Toric camera's own place sees its framed subjects with eyes_seen
    (module docstring)."""
    if all(seen_through(visibility, m, others, camera.pose(m), camera.lens).min() >= settings.eyes_seen for m in moments):
        return False
    return all(scores_from(toric, subjects, [m], [1.0], None, visibility)[0] >= settings.eyes_seen for m in moments)


def _event_moments(buffer: MomentBuffer, events_s: tuple[float, ...]) -> list[Moment]:
    """Each event's moment (the buffered one at or before it) and the one eval-match judges it at
    (the first at or after it: a kill's victim shown there counts it covered), up to the buffer's
    horizon. Judged a fixed 0.1 s after it instead (three frames at 30 Hz), p03's eyes on the real
    2on2 had lost p00 there though they showed his death, and the shot went to a Toric camera that
    cut through walls four times in 2 s (docs/casting.md, "The killer's eyes judged at the frame
    eval-match judges the kill at"). One moment where the event falls on a buffered one."""
    moments: list[Moment] = []
    for t in (min(t, buffer.horizon_s) for t in events_s):
        before, judged = buffer.at(t), buffer.at_or_after(t)
        moments.extend((before,) if judged is before else (before, judged))
    return moments


def shows_at(
    camera: FirstPersonCamera,
    others: tuple[int, ...],
    moment: Moment,
    visibility: SubjectVisibility,
    body_heights_m: np.ndarray,
    settings: MatchSettings,
) -> bool:
    """Whether the eye shows every one of the others at the moment: near enough to read
    (eyes_shown_height_min of the frame's height, by distance: a body H m tall d m away fills
    H / (2 d tan(fov / 2)) of a level frame), its chest inside the frame and eyes_seen of its
    points seen."""
    pose = camera.pose(moment)
    distance_m = np.linalg.norm(moment.aims_world[list(others)] - pose.position_world, axis=1)
    with np.errstate(divide="ignore"):  # no floor: every distance reads
        readable_m = body_heights_m[list(others)] / (2.0 * settings.eyes_shown_height_min * camera.lens.tan_half_fov_y)
    if np.any(distance_m > readable_m):
        return False
    chests = project_to_screen(pose, camera.lens, moment.aims_world[list(others)])
    with np.errstate(invalid="ignore"):
        if not np.all(np.abs(chests) <= 1.0):  # NaN: behind the eye
            return False
    return bool(seen_through(visibility, moment, others, pose, camera.lens).min() >= settings.eyes_seen)


def _meets_a_wall(
    toric: ToricCamera,
    buffer: MomentBuffer,
    cut: Moment,
    events_s: tuple[float, ...],
    visibility: SubjectVisibility,
    settings: MatchSettings,
) -> bool:
    """Whether the Toric camera's place, carried by its players from the cut over the shot's
    moments (stand.py `shot_moments`: every stand_step_s to its last event's pair window), passes
    through level geometry between two of them: a cut within the shot."""
    moments, _ = shot_moments(toric, buffer, cut.time_s, events_s, settings)
    return _path_meets_a_wall(toric, moments, visibility)


def _path_meets_a_wall(toric: ToricCamera, moments: Sequence[Moment], visibility: SubjectVisibility) -> bool:
    """Whether the Toric camera's place, carried by its players over the moments (in time order
    once sorted), passes through level geometry between two of them."""
    ordered = sorted({m.time_s: m for m in moments}.values(), key=lambda m: m.time_s)
    path = []
    for moment in ordered:
        centres = toric.positions(moment, [toric.place_at(moment.time_s)])
        if centres is not None:
            path.append(toric.above_ground(moment, centres[0]))  # where the pose stands (shots.py)
    return len(path) > 1 and bool(visibility.ray_scene.occluded(np.array(path[:-1]), np.array(path[1:])).any())


def _shows_readable(
    camera: FirstPersonCamera,
    moments: Sequence[Moment],
    visibility: SubjectVisibility,
    body_heights_m: np.ndarray,
    settings: MatchSettings,
) -> bool:
    """Whether the eyes show the players in their frame readable: the median, over the moments
    where they show any (eyes_seen of its points in the frame and unhidden), of their shown
    heights (eval-match's: the body over the frame's height at its chest's distance) is at least
    follow_eyes_height_min, with players shown at half of the moments or more."""
    everyone = tuple(i for i in range(len(body_heights_m)) if i != camera.player)
    medians = []
    for moment in moments:
        pose = camera.pose(moment)
        seen = seen_through(visibility, moment, everyone, pose, camera.lens)
        shown = [i for i, share in zip(everyone, seen) if share >= settings.eyes_seen]
        if shown:
            distance_m = np.maximum(np.linalg.norm(moment.aims_world[shown] - pose.position_world, axis=1), 0.1)
            medians.append(float(np.median(body_heights_m[shown] / (2.0 * distance_m * camera.lens.tan_half_fov_y))))
    return 2 * len(medians) >= len(moments) and float(np.median(medians)) >= settings.follow_eyes_height_min
