"""The program camera's lens: widened where a player would stand taller than the framing band.

A camera that walls pull in toward its subject (program_camera.py), a replay's close angle or a
DUEL's over-the-shoulder place can come within 2-3 m of a player, where a 1.4-1.8 m body fills
60-85% of a 50-degree frame (issue 41: the real duel's tall frames stood 1.8-3.4 m from the
camera, 95% of them the shot's own subjects). An operator in a tight corridor does not back
through the wall: they go wider. So after CAMERA has placed the pose, its vertical field of view
is the narrowest from the lens's up to `MatchSettings.widen_max_fov_deg` at which no player whose
sample points the pose sees (at least `TALL_SEEN` of them, ray cast: eval-match counts a player
shown at half of its 32, and two sets of points tell a body's share only to about 0.1) stands
taller than `MatchSettings.shown_height_max` of the frame's height, on a one-degree grid. Going
back to the lens's is a zoom at `MatchSettings.narrow_deg_s`, never faster, so a camera that
comes and goes near a wall does not pump; a cut starts at what it needs. A camera in a player's
eyes (HLTV's and the autotrack's first-person views) keeps the lens: a first-person view is the
game's own picture (eval-match leaves it out of its heights); a camera that comes into one from a
widened lens (a Toric camera passing through a player's head) goes back to it at the same pace.
The pose the program answers is checked again at the moment its picture shows, widened only
(program_camera.py `widened_for_answer`): a pose made for another moment, as the edit window's
held first pose of a shot, was sized for that one.
A player's height on screen is eval-match's (evaluation/match/measure.py): the extent of its
points on the screen's vertical axis, clipped to the frame, over the frame's height; its points
here are its outline (SubjectVisibility.outlines_local: the samples and its mesh's lowest and
highest vertices), since 16 samples fall short of the head and feet (sized by them, 7.7% of
nav_test's bot match's frames still had a player over 0.6; by the outline, 2.7%), and its rims
(visibility.py `_rims`): looked down on from near, a body's width stands on the screen's
vertical (on the real 2on2 at 29 and 31 Hz, a player 2.9 m below a DUEL's camera was 0.47 of
the frame by the outline, 0.63-0.645 by eval-match; by the rims too, the lens went wider).

A Toric camera's pose (our director's) whose framed subjects stand small zooms in
(`zoomed_fov_deg`): the narrowest width down to `MatchSettings.zoom_min_fov_deg` at which every
framed subject's outline stays inside the action-safe area (`zoom_safe`) and none stands taller
than `zoom_shown_height` (the style's FOLLOW size), reached at `zoom_deg_s` and left at once where
the framing needs it. A camera operator on a far subject zooms in rather than walk up to it: the
position is the Toric solve's, so what it sees (visibility, walls) is unchanged, and the frame
narrows about its centre, which pushes subjects composed off-centre outward, hence the safe area.
On open levels a pair 20-30 m apart, composed at the lens's 50 degrees, stood 0.06-0.09 of the
frame (issue 41: nav_test's median shown height 0.10 against a bar of 0.15); at the width that
fits them the same picture shows them and the players about them larger. The widening below
starts from the zoom's width: a player near the camera, enlarged by it, is still kept in the band.

A wide view of named players (an OVERVIEW of a fight no level place sees, shot_builder.py) zooms
on them the same way, as the operator of a high camera does; one that names nobody (an
establishing view) keeps the lens. On nav_test's bot match such views showed their players at a
median 0.065 of the frame's height (issue 41).

A Toric camera's pose (our director's, and its wide view of named players) also goes wide enough
to show a framed subject that the frame cuts off (`_cut_off`): a camera pulled in front of a wall
close over its subject looks down as steeply as a level camera can and has the subject below the
frame; wider, it shows it without a cut, at a width where it stands within the band (a subject
too close to fit stays cut off: a cast's OVERVIEW camera went to 90 degrees for a subject spawned
1.4 m beside it, 1.0 of the frame). The baselines' cameras keep what they frame.
"""

from __future__ import annotations

import math

import numpy as np

from camdirector.geometry.camera import NEAR_PLANE_M, CameraPose, Lens
from camdirector.geometry.transforms import quat_to_matrix
from camdirector.pipeline.match.first_person import CORPSE_EYE_FRACTION, EYE_HEIGHT_FRACTION
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.visibility import SubjectVisibility

FRAMED_IN = 0.75  # a framed subject cut off by the frame is widened for until this share of its points is in it and
# seen (or as much as the widest lens shows): over eval-match's SHOWN_FRACTION, whose 32 points are not the rig's 16
SHOWN_SEEN = 0.5  # a player with this share of its points seen from the pose is shown (eval-match's SHOWN_FRACTION)
# a player seen at this share of its points is kept in the band: half of SHOWN_SEEN, as 16 points and eval-match's 32 each
# tell a body's share only to about 0.1 (a cast's p01 seen at 0.40 by 2,000 points, under 0.5 by these 16, was shown at
# 0.53 by eval-match's 32: 1.0 of the frame's height)
TALL_SEEN = 0.25
FOV_STEP_DEG = 1.0  # the widths tried, from the lens's up, deg
EYES_RADIUS_M = 0.5  # a camera this near a player's eye point looks through its eyes (eval-match's EYE_TOLERANCE_M), m
EYES_MARGIN_M = 0.05  # but only this much nearer is taken for one here: eval-match measures the eye from the feet the
# program file records (to the mm) and a camera at its boundary stands in the body, m (0 to EYES_RADIUS_M)


def widened_fov_deg(
    pose: CameraPose,
    moment: Moment,
    visibility: SubjectVisibility,
    lens: Lens,
    settings: MatchSettings,
    last_fov_deg: float | None,
    dt_s: float,
    subjects: tuple[int, ...] = (),
) -> float:
    """The pose's vertical field of view, deg (module docstring): at least the lens's, or the
    zoom's for the players the shot frames (`subjects`; `zoomed_fov_deg`), at most
    settings.widen_max_fov_deg; `last_fov_deg` the last frame's when this one moves on from it
    (None on a cut), narrowed from by at most narrow_deg_s * dt_s (zoom_deg_s below the lens's).
    Each subject is shown too where a width up to the widest shows it (`_cut_off`)."""
    lens_deg, max_deg = lens.vertical_fov_deg, max(settings.widen_max_fov_deg, lens.vertical_fov_deg)
    zooms = bool(subjects) and settings.zoom_min_fov_deg < lens_deg
    if max_deg <= lens_deg and not zooms:
        return lens_deg
    points = silhouette_points(moment, visibility)
    if looked_through(pose, moment, points).any():
        # the lens, reached at its pace from a widened one (a Toric camera passing through a player's head: a FOLLOW's
        # lens went 71 -> 50 -> 62 degrees over three frames in a cast of the 2on2)
        return _paced_deg(lens_deg, lens_deg, max_deg, last_fov_deg, dt_s, settings)
    slope_y, slope_x = screen_slopes(points, pose.position_world[None], quat_to_matrix(pose.rotation_xyzw)[None])[:, 0]
    outline = slice(0, visibility.outline_count)  # the zoom frames the outline (outline_points); the band holds the rims too
    framed = list(subjects)
    base_deg = zoomed_fov_deg(slope_y[framed, outline], slope_x[framed, outline], lens, settings) if zooms else lens_deg
    floor_deg = _paced_deg(base_deg, lens_deg, max_deg, last_fov_deg, dt_s, settings)
    if max_deg <= lens_deg:  # settings that never widen
        return float(floor_deg)
    # most frames show nobody too tall at the floor's width: the grid of widths only for those who are
    at_floor = screen_heights(slope_y, slope_x, np.tan(np.radians([floor_deg]) / 2.0), lens.aspect)[:, 0]  # (P,)
    tall = np.flatnonzero(at_floor > settings.shown_height_max)
    if len(tall):
        tall = tall[visibility.visible_share(pose.position_world, moment, tuple(int(i) for i in tall))[0] >= TALL_SEEN]
    cut_off = _cut_off(pose, moment, visibility, subjects, slope_y, slope_x, floor_deg, max_deg, lens.aspect)
    if not len(tall) and not cut_off:
        return float(floor_deg)
    widths_deg = np.append(np.arange(floor_deg, max_deg, FOV_STEP_DEG), max_deg)  # (T,), the first the floor
    tan_half = np.tan(np.radians(widths_deg) / 2.0)
    heights = screen_heights(slope_y[tall], slope_x[tall], tan_half, lens.aspect)  # (tall, T)
    fits = (heights <= settings.shown_height_max).all(axis=0)  # (T,)
    for subject, seen in cut_off:  # shown at a width: in its frame and seen
        k = len(seen)
        shown = (_in_frame(slope_y[subject, :k], slope_x[subject, :k], tan_half, lens.aspect) & seen[:, None]).mean(axis=0)
        enough = shown >= min(FRAMED_IN, shown[-1])  # (T,) as much of it as the widest shows, up to FRAMED_IN
        # within the band itself where the width shows it (`tall` holds only those tall at the floor's width, where the
        # frame cut it off: an OVERVIEW's fixed camera widened to 90 degrees for a subject spawned 1.4 m beside it)
        own_heights = screen_heights(slope_y[subject][None], slope_x[subject][None], tan_half, lens.aspect)[0]  # (T,)
        enough &= own_heights <= settings.shown_height_max
        if (fits & enough).any():  # the band first: a subject too close to fit stays cut off
            fits &= enough
    return float(widths_deg[int(np.argmax(fits))] if fits.any() else max_deg)


def _paced_deg(
    base_deg: float, lens_deg: float, max_deg: float, last_fov_deg: float | None, dt_s: float, settings: MatchSettings
) -> float:
    """The narrowest width a frame may have on its way to base_deg (the lens's or its zoom's), deg,
    at most max_deg: base_deg on a cut (last_fov_deg None), else narrowed from the last frame's at a
    pace, back from a widening at narrow_deg_s, on into a zoom at zoom_deg_s."""
    if last_fov_deg is None:
        return float(min(base_deg, max_deg))
    rate_deg_s = settings.zoom_deg_s if base_deg < lens_deg and last_fov_deg <= lens_deg else settings.narrow_deg_s
    return float(min(max(base_deg, last_fov_deg - rate_deg_s * dt_s), max_deg))


def zoomed_fov_deg(slope_y: np.ndarray, slope_x: np.ndarray, lens: Lens, settings: MatchSettings) -> float:
    """The narrowest vertical field of view, deg, from the lens's down to settings.zoom_min_fov_deg,
    at which every framed subject's outline lies inside zoom_safe of the frame about its centre and
    none stands taller than zoom_shown_height of the frame's height (module docstring): slope_y,
    slope_x (s, S) the screen slopes of the s subjects' outline points (`screen_slopes`, NaN behind
    the near plane). The lens's where a point is behind the camera or outside that area already."""
    lens_deg = lens.vertical_fov_deg
    if np.isnan(slope_y).any():
        return lens_deg
    # tan of the half-width each bound needs: the outlines inside the safe area, the tallest no taller than the size
    fits = max(float(np.abs(slope_y).max()), float(np.abs(slope_x).max()) / lens.aspect) / settings.zoom_safe
    sized = float((slope_y.max(axis=1) - slope_y.min(axis=1)).max()) / (2.0 * settings.zoom_shown_height)
    tan_half = max(fits, sized, math.tan(math.radians(settings.zoom_min_fov_deg) / 2.0))
    return min(lens_deg, math.degrees(2.0 * math.atan(tan_half)))


def _cut_off(
    pose: CameraPose,
    moment: Moment,
    visibility: SubjectVisibility,
    subjects: tuple[int, ...],
    slope_y: np.ndarray,
    slope_x: np.ndarray,
    floor_deg: float,
    max_deg: float,
    aspect: float,
) -> list[tuple[int, np.ndarray]]:
    """The framed subjects that the frame cuts off at the floor's width, under FRAMED_IN of their
    sample points in it and seen, and that the widest lens shows more of (at least SHOWN_SEEN): each with its sample points
    seen (k,) bool (ray cast only for those the frame cuts off). A camera pulled in front of a
    wall close over its subject, looking down as steeply as a level camera can, has it below the
    frame (issue 41: on the real 4on4, 102 of 311 frames of nobody outside overviews had the shot's
    subject seen but mostly out of frame, 1.8-3.0 m from the camera); a wider lens shows it
    without a cut."""
    out: list[tuple[int, np.ndarray]] = []
    for subject in subjects:
        k = visibility.k
        y, x = slope_y[subject, :k], slope_x[subject, :k]
        tans = np.tan(np.radians([floor_deg, max_deg]) / 2.0)
        in_frame = _in_frame(y, x, tans, aspect).mean(axis=0)  # (2,) at the floor's width and the widest
        if in_frame[0] >= FRAMED_IN or in_frame[1] <= in_frame[0]:
            continue
        seen = visibility.seen_points(pose.position_world, moment, (subject,))[0, 0]  # (k,)
        shown = (seen[:, None] & _in_frame(y, x, tans, aspect)).mean(axis=0)  # (2,)
        if shown[1] >= SHOWN_SEEN and shown[0] < min(FRAMED_IN, shown[1]):
            out.append((subject, seen))
    return out


def outline_points(moment: Moment, visibility: SubjectVisibility) -> np.ndarray:
    """(P, k + 2, 3) m every player's outline (SubjectVisibility.outlines_local) at the moment."""
    return silhouette_points(moment, visibility)[:, : visibility.outline_count]


def silhouette_points(moment: Moment, visibility: SubjectVisibility) -> np.ndarray:
    """(P, S, 3) m every player's outline and rims (SubjectVisibility.silhouettes_local: its
    outline_points first) at the moment."""
    return np.stack([moment.transforms[i].apply(visibility.silhouettes_local[i]) for i in range(len(moment.transforms))])


def screen_slopes(points_world: np.ndarray, positions_world: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """(2, m, P, S): the screen slopes (tan of the elevation, y, and of the bearing, x) of points
    (P, S, 3) m seen from m cameras, centres (m, 3) m and camera-to-world rotations (m, 3, 3);
    NaN for a point behind the near plane."""
    camera = np.einsum("mpsi,mij->mpsj", points_world[None] - positions_world[:, None, None], rotations)  # -Z ahead
    depth = -camera[..., 2]
    ahead = depth >= NEAR_PLANE_M
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([np.where(ahead, camera[..., 1] / depth, np.nan), np.where(ahead, camera[..., 0] / depth, np.nan)])


def _in_frame(slope_y: np.ndarray, slope_x: np.ndarray, tan_half: np.ndarray, aspect: float) -> np.ndarray:
    """(S, T) bool: which of S points (their screen slopes (S,), NaN behind the near plane) lie in
    the frame at each width (tan_half (T,) of the half vertical field of view)."""
    t = tan_half[None, :]
    with np.errstate(invalid="ignore"):
        return np.asarray((np.abs(slope_y[:, None]) <= t) & (np.abs(slope_x[:, None]) <= t * aspect))  # NaN: False


def looked_through(pose: CameraPose, moment: Moment, points_world: np.ndarray) -> np.ndarray:
    """(P,) bool: the players through whose eyes the camera looks (within EYES_RADIUS_M less
    EYES_MARGIN_M of a living or a dead one's eye point, first_person.py, at its body's height): a
    first-person view. A camera elsewhere in a body is not one: eval-match measures its picture as
    any other (on the real wipeout a replay's camera inside a third player's body kept a 50-degree
    lens while its subject, 3 m off, filled 0.63 of the frame). Nor is one at the radius's edge:
    a cast's DUEL camera moved inside the level to 0.5 m from p02's eye kept its lens here and was
    0.5001 m off by the program file's feet, where eval-match measured p02 at 1.0 of the frame.
    A first-person camera stands at the eye itself."""
    feet = moment.feet_world  # (P, 3)
    top_m = points_world[..., 1].max(axis=1) - feet[:, 1]  # (P,) the body's height above its feet
    near = np.zeros(len(feet), dtype=bool)
    for fraction in (EYE_HEIGHT_FRACTION, CORPSE_EYE_FRACTION):
        eyes = feet + np.outer(fraction * top_m, [0.0, 1.0, 0.0])
        near |= np.linalg.norm(eyes - pose.position_world, axis=1) < EYES_RADIUS_M - EYES_MARGIN_M
    return near


def screen_heights(slope_y: np.ndarray, slope_x: np.ndarray, tan_half: np.ndarray, aspect: float) -> np.ndarray:
    """(P, T) each player's on-screen height, share of the frame's height, at each width
    (tan_half (T,) of the half vertical field of view): the extent of its points in the frame
    (those behind the near plane are NaN), clipped to the frame; 0 with no point in the frame."""
    t = tan_half[None, None, :]  # (1, 1, T)
    y, x = slope_y[..., None], slope_x[..., None]  # (P, S, 1)
    with np.errstate(invalid="ignore"):
        inside = (np.abs(y) <= t) & (np.abs(x) <= t * aspect)  # NaN compares False
    any_inside = inside.any(axis=1)  # (P, T)
    clipped = np.clip(np.where(np.isnan(y), 0.0, y), -t, t)  # (P, S, T)
    valid = ~np.isnan(y)
    top = np.where(valid, clipped, -np.inf).max(axis=1)
    bottom = np.where(valid, clipped, np.inf).min(axis=1)
    heights = np.where(any_inside, (top - bottom) / (2.0 * tan_half[None, :]), 0.0)
    return np.asarray(heights)
