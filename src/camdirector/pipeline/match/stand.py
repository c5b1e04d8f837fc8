"""Where a planned shot's camera stands: a fixed place that turns with its players, chosen with
the buffered future (issue 41, item 3: a rhythm casters use).

A Toric camera (shots.py) rides the torus of its framed players: in the real matches' corridors it
meets walls all the time (on the real 4on4's first 3 minutes it was pulled in front of a wall in
39% of the program's frames and held before one in 5%), and each wall it would pass through, or
that left it showing nobody, was a cut within the shot (94 of that program's 147 cuts, half of
them under 0.6 s after the cut before): a kill montage of 0.8-s shots. A broadcast covers a
corridor fight from a camera that stands where it sees the fight through and turns with it. With
the delay the director knows the whole of a planned shot's future, so it can choose that place at
the cut: of the level's camera nodes (the precompute's places, inside the level by construction)
within `stand_reach_m` of the player the shot keeps in view, the one whose picture, framed as the
Toric camera frames it (the same screen points, the pair window's reframe included:
ToricCamera.pose_from from the stand), best sees the framed players (framed_seen, the worst-seen
one) over the shot's moments every `stand_step_s` from the cut to its last event's pair window,
each event's own moment and the next frame's weighing `stand_event_weight`. It is taken when it
sees them with `min_visible` and at least as well as the Toric camera's own place over the same moments (the torus
unobstructed: that camera's pulls and holds are not scored, so it is not favoured), within the
framing band at every one of them (no framed player taller on screen than `shown_height_max`, the
kept one not shorter than `stand_shown_height_min`) and the cut's grammar. A camera that stands
never moves, so it never meets a wall and never cuts within its shot (rig.py).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import ToricCamera, framed_seen
from camdirector.pipeline.match.visibility import SubjectVisibility

NEXT_FRAME_S = 0.1  # an event's next frame, scored with it (planned.py POST_EVENT_S), s


def shot_moments(
    camera: ToricCamera, buffer: MomentBuffer, start_s: float, events_s: tuple[float, ...], settings: MatchSettings
) -> tuple[list[Moment], list[float]]:
    """The moments a stand is judged over, from start_s to the camera's last event's pair window
    (within the buffered future), every stand_step_s, and each event's moment and the next
    frame's; with their weights."""
    s = settings
    end_s = max(events_s) + (s.pair_after_s if camera.pair is not None else 0.0)
    end_s = min(end_s, buffer.horizon_s)
    times = list(np.arange(start_s, end_s + 1e-9, s.stand_step_s))
    weights = [1.0] * len(times)
    for event_s in events_s:
        for t in (event_s, event_s + NEXT_FRAME_S):
            if t <= buffer.horizon_s:
                times.append(t)
                weights.append(s.stand_event_weight)
    return [buffer.at(t) for t in times], weights


def scores_from(
    camera: ToricCamera,
    subjects: tuple[int, ...],
    moments: list[Moment],
    weights: list[float],
    stands_world: np.ndarray | None,
    visibility: SubjectVisibility,
) -> np.ndarray:
    """(n,) the weighted mean over the moments of the worst-seen framed subject's share, from n
    fixed stands (n, 3) m, or (1,) from the camera's own place on its torus (stands_world None);
    0 at a moment where the framing is degenerate."""
    total = np.zeros(1 if stands_world is None else len(stands_world))
    for moment, weight in zip(moments, weights):
        place = camera.place_at(moment.time_s)
        positions = camera.positions(moment, [place]) if stands_world is None else stands_world
        if positions is None:
            continue
        rotations = camera.rotations(moment, positions, [place] * len(positions))
        framed = camera.framed(moment.time_s) or subjects
        total += weight * framed_seen(visibility, moment, framed, positions, rotations, camera.lens).min(axis=1)
    out: np.ndarray = total / max(sum(weights), 1e-9)
    return out


def in_band(
    camera: ToricCamera,
    subjects: tuple[int, ...],
    moments: list[Moment],
    stands_world: np.ndarray,
    body_heights_m: np.ndarray,
    settings: MatchSettings,
) -> np.ndarray:
    """(n,) bool: the stands (n, 3) m from which, at every moment, no framed subject stands
    taller on screen than shown_height_max and the kept one (the anchor) no shorter than
    stand_shown_height_min (a level frame of the lens: H / (2 d tan(fov / 2)))."""
    tan_half = camera.lens.tan_half_fov_y
    ok = np.ones(len(stands_world), dtype=bool)
    for moment in moments:
        framed = list(camera.framed(moment.time_s) or subjects)
        d = np.linalg.norm(stands_world[:, None, :] - moment.aims_world[framed][None], axis=2)  # (n, f)
        nearest_m = body_heights_m[framed] / (2.0 * settings.shown_height_max * tan_half)
        ok &= (d >= nearest_m).all(axis=1)
        anchor_m = np.linalg.norm(stands_world - moment.aims_world[camera.anchor_index], axis=1)
        ok &= anchor_m <= body_heights_m[camera.anchor_index] / (2.0 * settings.stand_shown_height_min * tan_half)
    return ok


def best_stand(
    camera: ToricCamera,
    subjects: tuple[int, ...],
    buffer: MomentBuffer,
    cut: Moment,
    events_s: tuple[float, ...],
    nodes_world: np.ndarray,
    visibility: SubjectVisibility,
    body_heights_m: np.ndarray,
    settings: MatchSettings,
    allowed: Callable[[np.ndarray], np.ndarray] | None,
) -> np.ndarray | None:
    """(3,) m: where the planned shot's camera stands (module docstring), or None when no node
    in reach sees its players at least as well as its Toric place over the shot, and with
    min_visible."""
    s = settings
    if not len(nodes_world):
        return None
    near = np.linalg.norm(nodes_world - cut.aims_world[camera.anchor_index], axis=1) <= s.stand_reach_m
    stands = nodes_world[near]
    moments, weights = shot_moments(camera, buffer, cut.time_s, events_s, settings)
    ok = in_band(camera, subjects, moments, stands, body_heights_m, settings)
    if allowed is not None:
        ok &= allowed(stands)
    stands = stands[ok]
    if not len(stands):
        return None
    scores = scores_from(camera, subjects, moments, weights, stands, visibility)
    best = int(np.argmax(scores))
    own = float(scores_from(camera, subjects, moments, weights, None, visibility)[0])
    return stands[best] if scores[best] >= max(own + s.stand_margin, s.min_visible) else None
