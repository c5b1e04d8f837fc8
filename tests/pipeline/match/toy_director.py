"""A toy match director, defined and registered by the tests alone: what a studio's own director
is to the server (a plugin module that registers itself on import: `camdirector serve --plugin
tests.pipeline.match.toy_director`). It always follows the first player, from its own camera: 3 m
behind and 1.5 m above the player's aim point, looking at it. Nothing of the service names it.
"""

from __future__ import annotations

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.pipeline.match.director_contract import DirectorBase, DirectorContext
from camdirector.pipeline.match.director_registry import DirectorEntry, register
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.look_along import look_along
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import Shot

OFFSET_M = np.array([0.0, 1.5, -3.0])  # from the followed player's aim point, world axes, m


class BehindCamera:
    """A `ShotCamera` of its own: a fixed offset from one player's aim point, looking at it."""

    def __init__(self, player: int, fov_deg: float):
        self.player, self.fov_deg = player, fov_deg

    def advance(self, moment: Moment, dt_s: float, response_time_s: float) -> None:
        pass  # it has no state that moves: its pose is the moment's

    def pose(self, moment: Moment) -> CameraPose:
        aim = moment.aims_world[self.player]
        return look_along(aim + OFFSET_M, -OFFSET_M, self.fov_deg)


class ToyDirector(DirectorBase):
    """Follows the first player, cut once (no capability: `DirectorBase` answers them)."""

    def __init__(self, context: DirectorContext):
        self.first, self.fov_deg = context.players[0], context.lens.vertical_fov_deg

    def decide(
        self, moment: Moment, buffer: MomentBuffer, current: Shot | None, current_pose: CameraPose | None, flags: list[str]
    ) -> Shot | None:
        if current is not None:
            return None
        return Shot(
            ShotChoice((self.first,), ShotKind.FOLLOW, f"toy: always {self.first}"),
            (0,),
            BehindCamera(0, self.fov_deg),
            moment.time_s,
        )


register(DirectorEntry("toy", "a test's toy: always the first player, from behind", ToyDirector))
