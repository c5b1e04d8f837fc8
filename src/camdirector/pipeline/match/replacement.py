"""Re-placement: between cuts, a Toric camera whose place sees its subjects under `min_visible`
glides to a better place on its side. The rig asks it at each tick without a cut for a director
that `replaces_occluded_places` (director_contract.py; ours, planned.py) and for a human's take.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.planned import PlannedDirector
from camdirector.pipeline.match.program_shot import Shot, ShotCamera
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shot_builder import within_band
from camdirector.pipeline.match.shots import Place, ToricCamera, best_place, place_grid
from camdirector.pipeline.match.visibility import SubjectVisibility

REPLACE_LOOKAHEAD_S = 1.0  # an occluded place is replaced by the best one over now and this far ahead, s


def replaced_places(
    moment: Moment,
    buffer: MomentBuffer,
    shot: Shot,
    camera: ShotCamera,
    visibility: SubjectVisibility,
    settings: MatchSettings,
    flags: list[str],
) -> tuple[Place | None, Place | None]:
    """A Toric camera whose goal place sees its subjects under min_visible glides to the best
    place on its side: the new goal, None to keep it. With planned events still ahead in the
    buffer the place is judged at their moments (planned.py's event cover: being hidden now
    matters less than at the kill); otherwise now and REPLACE_LOOKAHEAD_S ahead. A camera whose
    pair window holds the pair's place (shots.py `ToricCamera.split`): its own place, the
    killer's, is judged for the killer alone, from all the grid, at those of now and
    REPLACE_LOOKAHEAD_S ahead where it frames the killer alone; the pair's place at the upcoming
    events while the picture is not yet on it, and replaced at once (it is not on screen): the
    second place returned, None to keep it. Another camera is kept."""
    if not isinstance(camera, ToricCamera):
        return None, None
    now = moment.time_s
    upcoming = [t for t in shot.cover_times_s if now <= t <= buffer.horizon_s]
    ahead = now + REPLACE_LOOKAHEAD_S
    soon = [moment] + ([buffer.at(ahead)] if ahead <= buffer.horizon_s else [])
    if not camera.split:
        side = None if camera.b_index is None else camera.side
        cover, weights = PlannedDirector.event_cover(buffer, now, upcoming) if upcoming else (soon, None)
        return _better_place(
            camera, camera.goal, place_grid(side), cover, weights, shot.subjects, visibility, settings, flags
        ), None
    pair, pair_place = camera.pair, None
    assert pair is not None and pair.place is not None  # a split camera's pair window holds the pair's place
    if upcoming and pair.weight(now) <= 0.0:
        cover, weights = PlannedDirector.event_cover(buffer, now, upcoming)
        side = math.copysign(1.0, pair.place.phi_rad)
        pair_place = _better_place(
            camera, pair.place, place_grid(side), cover, weights, shot.subjects, visibility, settings, flags
        )
    alone = [m for m in soon if pair.weight(m.time_s) <= 0.0]
    goal = (
        _better_place(camera, camera.goal, place_grid(None), alone, None, (pair.keep_index,), visibility, settings, flags)
        if alone
        else None
    )
    return goal, pair_place


def _better_place(
    camera: ToricCamera,
    place: Place,
    grid: Sequence[Place],
    cover: list[Moment],
    weights: list[float] | None,
    subjects: tuple[int, ...],
    visibility: SubjectVisibility,
    settings: MatchSettings,
    flags: list[str],
) -> Place | None:
    """The best place of grid for the subjects over cover when `place` sees them under
    min_visible and it sees them better (flagged replaced_for_visibility); else None."""
    _, seen = best_place(camera, [place], cover, subjects, visibility, weights=weights)
    if seen >= settings.min_visible:
        return None
    band = within_band(visibility, camera.lens, settings, subjects, cover[0])  # issue 41: never closer than the band
    better, score = best_place(camera, grid, cover, subjects, visibility, band, cover[0], weights)
    if score <= seen:
        return None
    flags.append("replaced_for_visibility")
    return better
