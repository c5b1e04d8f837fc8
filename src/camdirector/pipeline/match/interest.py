"""Interest: how much each player and each pair of opponents is worth showing at a moment.

A fight is two living opponents within `engage_range_m` of each other who can see each other (the
segment between their aim points crosses no level geometry: through a wall or a floor is no fight,
however near; on real maps of several storeys most near pairs are on another floor), at least one
facing the other (within acos(facing_cos) of its forward). Its score in [0, 1] is the proximity (1 at contact,
0 at the range) times the mean of the two facings (each 0 when looking away by more than the
facing cone, 1 when looking straight at the other). This is the HLTV director's player ranking
idea (opponents near and facing, hltvdirector.cpp AnalyzePlayers) restricted to opponents and
made symmetric so a pair, not only a player, has a value. Recent DAMAGE and KILL events add their
priority (of 15) to their pair, fading over `recent_event_s`: a fight that draws blood is a fight.
"""

from __future__ import annotations

import numpy as np

from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.inputs import GameEvent
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.match.settings import MatchSettings

MAX_PRIORITY = 15


def event_priority(event: GameEvent, settings: MatchSettings) -> int:
    """The event's priority in [1, 15]: the client's, or its kind's default when 0."""
    return event.priority if event.priority > 0 else settings.priorities[event.kind]


def fight_matrix(moment: Moment, teams: np.ndarray, settings: MatchSettings, ray_scene: RayScene | None = None) -> np.ndarray:
    """(n, n) symmetric fight scores in [0, 1] of a moment (module docstring); teams (n,) int.
    Without a ray scene every pair is in sight (a session without a level)."""
    delta = moment.feet_world[None, :, :] - moment.feet_world[:, None, :]  # (n, n, 3): i -> j
    delta[..., 1] = 0.0
    distance = np.linalg.norm(delta, axis=2)
    np.fill_diagonal(distance, np.inf)
    toward = delta / np.maximum(distance, 1e-6)[..., None]
    cos_facing = np.einsum("ik,ijk->ij", moment.forward_world, toward)  # (n, n): i's forward . unit(i -> j)
    facing = np.clip((cos_facing - settings.facing_cos) / max(1.0 - settings.facing_cos, 1e-6), 0.0, 1.0)
    proximity = np.clip(1.0 - distance / settings.engage_range_m, 0.0, 1.0)
    opponents = (teams[:, None] != teams[None, :]) & moment.alive[:, None] & moment.alive[None, :] & (proximity > 0.0)
    if ray_scene is not None:
        opponents &= in_sight(moment, opponents, ray_scene)
    return np.where(opponents, proximity * 0.5 * (facing + facing.T), 0.0)


def in_sight(moment: Moment, pairs: np.ndarray, ray_scene: RayScene) -> np.ndarray:
    """(n, n) symmetric bool: whether the aim points of each pair marked in pairs (n, n) bool see
    each other (one ray per unordered pair); False for the unmarked."""
    ii, jj = np.nonzero(np.triu(pairs, 1))
    seen = np.zeros(pairs.shape, dtype=bool)
    if len(ii):
        clear = ~ray_scene.occluded(moment.aims_world[ii], moment.aims_world[jj])
        seen[ii[clear], jj[clear]] = True
    return seen | seen.T


def recent_event_boost(
    events: list[GameEvent], index: dict[str, int], now_s: float, n: int, settings: MatchSettings
) -> np.ndarray:
    """(n, n) symmetric boost of the pairs named by events in (now - recent_event_s, now]: each adds
    priority / 15, fading linearly to 0 over recent_event_s."""
    boost = np.zeros((n, n))
    for event in events:
        i, j = index.get(event.actor_id), index.get(event.other_actor_id)
        age_s = now_s - event.time_s
        if i is None or j is None or i == j or not 0.0 <= age_s < settings.recent_event_s:
            continue
        value = event_priority(event, settings) / MAX_PRIORITY * (1.0 - age_s / settings.recent_event_s)
        boost[i, j] += value
        boost[j, i] += value
    return boost
