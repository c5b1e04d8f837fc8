"""The program camera stepped back from a player that no lens shows within the framing band.

lens_width.py goes as wide as `MatchSettings.widen_max_fov_deg` to keep every shown player under
`shown_height_max` of the frame's height; a player nearer the camera than its readable distance
(shot_builder.py `readable_clearance`: about 1.75 m for a 1.75 m body at 90 degrees) fills more
than that even there. The degrades that move a pose toward the player it keeps (program_camera.py:
moved inside the level, held before a wall, pulled in front of one), a replay's close angle and
an OVERVIEW's fixed camera that a player runs past left such frames on 1-2% of the third-person
frames of the real matches' first 3 minutes (issue 41, whose bar is none over 0.6: 23 of 1,117
on the 4on4, 46 on the duel, 25 on the 2on2, every one at 90 degrees with the player 0.8-2.0 m
from the camera). An operator steps back. So where a player the pose sees (`TALL_SEEN` of its
points) stands taller than the band at the widest lens, the pose moves to the nearest of
`BACK_STEPS_M` along the camera's own backward line (a dolly: the framing holds) or away from the
nearest such player, straight or turned by `TURNS_DEG`, panning as it goes to keep the framed
subjects' bearing (a step aside that kept its rotation would leave the player as near in depth,
so as tall), where:
- no player it sees stands taller than the band at the widest lens,
- the places test accepts the point and the move crosses no wall (in_level.py),
- each of the shot's framed subjects stays framed and seen (shots.py `framed_seen`, at the
  widest lens) as much as before or `candidate_seen`, whichever is less.
No such point (a camera in a corner the player runs into): the pose turns off the player where it
stands, keeping the other framed subjects where a turn can: a pan, the least of AWAY_TURNS_DEG
either way, or after the pans a tilt, the least of AWAY_TILTS_DEG up or down (a player straight
below the camera stays in a 90-degree frame turned any way about the vertical); none off it: the
pose stays. On the real matches' first 3 minutes, after the steps,
2-6 frames a match still had a player over 0.6 (issue 41's bar: none), each 1-3 frames long, as a
player ran past a camera at a wall or in a corridor; the pan is the operator letting the player
go by the lens. The shot's camera keeps its own state (its place, its damping), so the step is
taken again each frame the player stays near and ends when it leaves; the lens narrows back at
lens_width.py's pace.

Costs: nothing where no player's feet are within NEAR_M. Otherwise the places at one distance are
judged together, one batch of casts per test (the places test, the wall test, the too-tall
players' shares, the framed subjects' shares), nearest distance first, and the first place at
that distance that passes them all is taken: the place one by one would take, in four calls per
distance instead of up to four per place (the real 4on4's first 3 minutes in eval-match: the
same answer in each of 2,500 calls; the calls over 5 ms one by one, 6.5 ms on average, 3.0 ms).
"""

from __future__ import annotations

import math

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.transforms import matrix_to_quat, quat_to_matrix
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.lens_width import TALL_SEEN, looked_through, screen_heights, screen_slopes, silhouette_points
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import framed_seen
from camdirector.pipeline.match.visibility import SubjectVisibility

BACK_STEPS_M = np.arange(1, 9) * 0.25  # the distances tried, nearest first: up to 2 m, a readable distance's worth, m
NEAR_M = 5.0  # only a player whose feet are this near is asked about (a 2 m body at 90 deg fills half the frame at 2 m), m
TURNS_DEG = (0.0, 30.0, -30.0, 60.0, -60.0, 90.0, -90.0)  # the directions tried away from the player, after the backward line
AWAY_TURNS_DEG = np.arange(1, 19) * 10.0  # where no step helps, the pans tried either way, nearest first: up to 180 deg, deg
AWAY_TILTS_DEG = np.arange(1, 10) * 10.0  # where no pan helps, the tilts tried up and down, nearest first: up to 90 deg, deg
AWAY_SEEN = TALL_SEEN  # a player panned from is framed and seen at under this share of its points: half of eval-match's
# SHOWN_FRACTION, as the rig's 16 points are not eval-match's 32


def stepped_back(
    pose: CameraPose,
    moment: Moment,
    visibility: SubjectVisibility,
    lens: Lens,
    settings: MatchSettings,
    in_level: InLevel,
    subjects: tuple[int, ...],
) -> tuple[CameraPose, bool] | None:
    """The pose stepped back (module docstring) with the widest lens, for lens_width.py to narrow,
    and whether it was panned off the player where it stands rather than stepped (`_turned_away`,
    where no step helps); None where no player it sees is too near for the widest lens, or
    neither helps. subjects: the shot's framed players, kept in the picture."""
    if np.linalg.norm(moment.feet_world - pose.position_world, axis=1).min(initial=np.inf) > NEAR_M:
        return None  # most frames: nobody near enough to ask
    widest_deg = max(settings.widen_max_fov_deg, lens.vertical_fov_deg)
    tan_widest = np.array([math.tan(math.radians(widest_deg) / 2.0)])
    points = silhouette_points(moment, visibility)  # (P, S, 3)
    if looked_through(pose, moment, points).any():  # a first-person view keeps its player's size
        return None
    rotation = quat_to_matrix(pose.rotation_xyzw)  # (3, 3) camera-to-world, -Z ahead

    def too_tall(positions_world: np.ndarray, rotations: np.ndarray) -> np.ndarray:
        """(m, P) bool: the players over the band at the widest lens from each of (m, 3) centres
        turned by (m, 3, 3) rotations."""
        slopes = screen_slopes(points, positions_world, rotations)
        m, p, s = slopes.shape[1:]
        heights = screen_heights(slopes[0].reshape(m * p, s), slopes[1].reshape(m * p, s), tan_widest, lens.aspect)
        return np.asarray(heights.reshape(m, p) > settings.shown_height_max)

    def seen_tall(positions_world: np.ndarray, tall: np.ndarray) -> np.ndarray:
        """(m,) bool: whether from each of (m, 3) centres a player too tall there, (m, P) bool,
        is seen at TALL_SEEN of its points; one batch of casts for all of them."""
        players = tuple(int(i) for i in np.flatnonzero(tall.any(axis=0)))
        if not players:
            return np.zeros(len(positions_world), dtype=bool)
        seen = visibility.visible_share(positions_world, moment, players) >= TALL_SEEN  # (m, len(players))
        return np.asarray((seen & tall[:, list(players)]).any(axis=1))

    here = too_tall(pose.position_world[None], rotation[None])[0]
    if not seen_tall(pose.position_world[None], here[None])[0]:
        return None
    nearest = min(np.flatnonzero(here), key=lambda i: float(np.linalg.norm(moment.feet_world[i] - pose.position_world)))
    directions = _directions(pose.position_world - moment.feet_world[nearest], rotation[:, 2])  # (D, 3)
    tried = (pose.position_world + BACK_STEPS_M[:, None, None] * directions[None]).reshape(-1, 3)  # nearest first
    # a step aside pans to keep the framed subjects where they were across the frame
    target = moment.aims_world[list(subjects)].mean(axis=0) if subjects else None
    rotations = _panned(rotation, pose.position_world, tried, target)  # (m, 3, 3)
    tall = too_tall(tried, rotations)  # (m, P)
    widest = Lens(vertical_fov_deg=widest_deg, aspect=lens.aspect)
    # each framed subject's share to keep: as much as before or candidate_seen, whichever is less
    keep = None
    if subjects:
        before = framed_seen(visibility, moment, subjects, pose.position_world[None], rotation[None], widest)[0]
        keep = np.minimum(before, settings.candidate_seen)
    # the places at one distance tested together, nearest distance first: a batch of casts per
    # test, not one per place (up to 64 places one by one took 13-30 ms of a frame near players)
    for rows in np.arange(len(tried)).reshape(len(BACK_STEPS_M), -1):
        ok = in_level.inside_many(tried[rows])
        ok[ok] = ~in_level.crossed_many(pose.position_world, tried[rows[ok]])
        ok[ok] = ~seen_tall(tried[rows[ok]], tall[rows[ok]])
        if keep is not None and ok.any():
            ok[ok] = (framed_seen(visibility, moment, subjects, tried[rows[ok]], rotations[rows[ok]], widest) >= keep).all(axis=1)
        if ok.any():
            first = rows[int(np.argmax(ok))]
            return CameraPose(tried[first], matrix_to_quat(rotations[first]), widest_deg), False
    tall_here = tuple(int(i) for i in np.flatnonzero(here))
    panned = _turned_away(pose, moment, visibility, rotation, widest, tall_here, subjects, keep)
    return None if panned is None else (panned, True)


def _turned_away(
    pose: CameraPose,
    moment: Moment,
    visibility: SubjectVisibility,
    rotation: np.ndarray,
    widest: Lens,
    tall: tuple[int, ...],
    subjects: tuple[int, ...],
    keep: np.ndarray | None,
) -> CameraPose | None:
    """The pose where it stands, turned so that no player too tall at the widest lens (tall) is
    framed and seen at AWAY_SEEN of its points: of the pans about the vertical (the least of
    AWAY_TURNS_DEG either way) and then the tilts about its own right axis (the least of
    AWAY_TILTS_DEG up or down, the camera kept upright), the first where each framed subject but
    those keeps its share (keep, (len(subjects),): as stepping back), else the first off the tall
    ones alone; None where none is off them. The tilts are for a player below: a 30 Hz program's
    DUEL camera 2 m above a player fallen into a pit looked down on him at 90 degrees (0.75 of the
    frame by the rig's outline, 0.675 by eval-match's), and no pan took him out of the frame.
    Where no step back helps, an operator a player brushes past lets it go by the lens rather
    than hold it pressed against it: issue 41's bar is no frame with a player over 0.6 of its
    height, and its frames of nobody (a lone subject panned from) have a budget of 2%."""
    turns = np.radians(np.stack([AWAY_TURNS_DEG, -AWAY_TURNS_DEG], axis=1).ravel())  # nearest first
    tilts = np.radians(np.stack([AWAY_TILTS_DEG, -AWAY_TILTS_DEG], axis=1).ravel())
    tilted = _about(rotation[:, 0], tilts) @ rotation
    upright = tilted[:, 1, 1] > 0.0  # the camera's up still above its horizon: no tilt past the vertical
    rotations = np.concatenate([_yaw(turns) @ rotation, tilted[upright]])  # (m, 3, 3), the pans first
    positions = np.broadcast_to(pose.position_world, (len(rotations), 3))
    away = framed_seen(visibility, moment, tall, positions, rotations, widest).max(axis=1) < AWAY_SEEN
    if not away.any():
        return None
    kept = [k for k, s in enumerate(subjects) if s not in tall]
    if kept and keep is not None:
        seen = framed_seen(visibility, moment, tuple(subjects[k] for k in kept), positions, rotations, widest)
        keeping = away & (seen >= keep[kept]).all(axis=1)
        away = keeping if keeping.any() else away  # else the others are let go too: the bar is on the player at the lens
    return CameraPose(pose.position_world, matrix_to_quat(rotations[int(np.argmax(away))]), widest.vertical_fov_deg)


def _panned(rotation: np.ndarray, from_world: np.ndarray, to_world: np.ndarray, target_world: np.ndarray | None) -> np.ndarray:
    """(m, 3, 3) the camera-to-world rotation (3, 3) turned about the vertical, for a camera moved
    from from_world (3,) to each of to_world (m, 3), so that the level bearing of target_world
    (3,) from it is as it was; unturned without a target."""
    if target_world is None:
        return np.broadcast_to(rotation, (len(to_world), 3, 3)).copy()
    before, after = target_world - from_world, target_world - to_world  # (3,), (m, 3)
    return np.asarray(_yaw(np.arctan2(after[:, 0], after[:, 2]) - math.atan2(before[0], before[2])) @ rotation)


def _directions(away_world: np.ndarray, backward_world: np.ndarray) -> np.ndarray:
    """(D, 3) level unit vectors: the camera's backward line, then away from the player (away_world
    (3,), from its feet to the camera) turned by each of TURNS_DEG about the vertical; a line with
    no level part (straight down) is left out."""
    out = []
    for vector, turns in ((backward_world, (0.0,)), (away_world, TURNS_DEG)):
        level = np.array([vector[0], 0.0, vector[2]])
        norm = float(np.linalg.norm(level))
        if norm >= 1e-6:
            out.append(_yaw(np.radians(turns)) @ (level / norm))
    return np.concatenate([np.zeros((0, 3)), *out])


def _about(axis_world: np.ndarray, turn_rad: np.ndarray) -> np.ndarray:
    """(m, 3, 3) rotations about the unit axis_world (3,) by each of (m,) angles, rad (Rodrigues);
    about the camera's right axis, a positive angle tilts its view up."""
    x, y, z = axis_world
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])  # the cross product with the axis
    s, c = np.sin(turn_rad)[:, None, None], np.cos(turn_rad)[:, None, None]
    return np.asarray(np.eye(3) + s * k + (1.0 - c) * (k @ k))


def _yaw(turn_rad: np.ndarray) -> np.ndarray:
    """(m, 3, 3) rotations about the world's vertical (+Y) by each of (m,) angles, rad: (x, z)
    goes to (x cos + z sin, z cos - x sin)."""
    c, s = np.cos(turn_rad), np.sin(turn_rad)
    yaw = np.zeros((len(turn_rad), 3, 3))
    yaw[:, 0, 0], yaw[:, 0, 2], yaw[:, 1, 1], yaw[:, 2, 0], yaw[:, 2, 2] = c, s, 1.0, -s, c
    return yaw
