"""The match director contract: what the MATCH rig asks of a director, what it gives one when it
makes it, and the capabilities only some directors have, with their defaults.

A director decides, at each planning tick of the rig (rig.py, `plan_rate_hz`), whether the
program cuts and to which `Shot` (program_shot.py, whose camera is any `ShotCamera`). It is made
from a `DirectorContext` by its entry in the registry (director_registry.py) when a session starts
or its style names another director, and lives as long as it directs that session: its state is
its own attributes, pickled with the rig into the session's checkpoint, so its module must be
importable wherever the session may be restored (a plugin is imported in every worker process,
infra/plugins.py). It reads only what a decision is given and its context, and draws random
numbers only from the context's `rng` (the session's, seeded: the same seed and inputs make the
same program). What the rig does around it is the rig's, for every director: a human's takes
(takes.py), the candidates for the preview monitors (the situations of situations.py), the
camera's step every frame and its pull in front of a wall (rig.py, camera_ahead.py).

What only some directors do is a capability the rig asks, never which director it holds; a
director that subclasses `DirectorBase` has them all answered as "no":
- `plans_ahead`: its decision may be drawn at one tick for the moment of the next and computed
  off the frame path in the worker's idle moments (drawn_plan.py); it must then read nothing but
  its arguments and its context, and leave nothing in the decision that depends on when it ran.
  Ours does; the baselines decide in the frame (they are cheap).
- `replaces_occluded_places`: between its cuts the rig moves an occluded Toric camera of its
  shot to a better place on its side (replacement.py). Ours does; a take always does.
- `planned_cuts()`: the cuts its last decision planned (with a delay, for events it knows are
  coming), which the program shows as its next planned cut. Ours has them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.inputs import PlayerStats
from camdirector.pipeline.match.frame import PlannedCut
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import Shot
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shot_builder import ShotBuilder
from camdirector.pipeline.match.situations import Situations


@dataclass(frozen=True, eq=False)
class DirectorContext:
    """What a director is made from: the session's players and what the rig shares with it."""

    players: list[str]  # the players' ids, the session's targets in target order
    teams: np.ndarray  # (n,) int their teams
    lens: Lens
    settings: MatchSettings
    delay_s: float  # the broadcast delay, s: how far the buffer reaches ahead
    ray_scene: RayScene  # the session's level and static objects
    rng: np.random.Generator  # the session's, seeded
    level_nodes_world: np.ndarray  # (m, 3) the level graph's nodes, m; (0, 3) without a level
    player_stats: Mapping[str, PlayerStats]  # each player's latest scoreboard values up to the program moment
    builder: ShotBuilder  # Toric shots placed by ray casts and the grammar (shot_builder.py)
    situations: Situations  # the situations of a moment by interest (situations.py)


class MatchDirector(Protocol):
    """What the rig asks of a match director (module docstring)."""

    def decide(
        self, moment: Moment, buffer: MomentBuffer, current: Shot | None, current_pose: CameraPose | None, flags: list[str]
    ) -> Shot | None:
        """At a planning tick: the shot to cut to at the moment, or None to keep `current` (None:
        no shot of this director's on air: the first, or after a take was released). `buffer`
        holds the moments up to the delay's horizon; `current_pose` is the pose on air; a
        degraded choice appends its reason to `flags`."""
        ...

    @property
    def plans_ahead(self) -> bool:
        """Whether its decision may be computed off the frame path (module docstring)."""
        ...

    @property
    def replaces_occluded_places(self) -> bool:
        """Whether the rig re-places its shot's occluded Toric camera between cuts."""
        ...

    def planned_cuts(self) -> list[PlannedCut]:
        """The cuts its last decision planned, in time order."""
        ...


class DirectorBase:
    """The optional capabilities answered "no": a director subclasses it and overrides what it has."""

    plans_ahead = False
    replaces_occluded_places = False

    def planned_cuts(self) -> list[PlannedCut]:
        return []
