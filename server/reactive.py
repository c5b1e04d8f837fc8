"""MOTION stage of the REACTIVE baseline: what game engines ship (Cinemachine's Deoccluder with
the "pull camera forward" strategy), on top of the FRAMING_ONLY rig.

The rig proposes its pose; if the segment from the framed point A to that camera is blocked, the
camera is pulled along it to just in front of the first occluder, at once; when the way clears it
eases back out to the rig's distance. Moving along the line to A keeps A on screen_a (the
orientation is the rig's), but leaves the torus, so B is no longer exactly placed. It reacts to
occlusion after it happens and never anticipates: the behaviour the paper improves on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.raycast import RayScene


@dataclass(frozen=True)
class ReactiveSettings:
    margin_m: float = 0.3        # the camera stops this far in front of the occluder, m. [0, 10]
    min_distance_m: float = 0.5  # never closer to A than this, m. (0, 100]
    ease_back_s: float = 0.5     # time constant of the return to the rig's distance (Cinemachine damping), s. [0.01, 60]
    settle_m: float = 0.01       # back at the rig's distance when this close, m. (0, 1]


class Deoccluder:
    def __init__(self, ray_scene: RayScene, settings: ReactiveSettings = ReactiveSettings()):
        self.ray_scene = ray_scene
        self.settings = settings
        self.distance_m: float | None = None  # current distance from A, None when not pulled in

    def run(self, proposed: CameraPose, a_world: np.ndarray, dt_s: float) -> tuple[CameraPose, bool]:
        """(pose, pulled_in): the proposed pose, or moved along A -> camera to stay unoccluded."""
        offset = proposed.position_world - a_world
        wanted = float(np.linalg.norm(offset))
        direction = offset / wanted
        t = float(self.ray_scene.first_hit(a_world[None], offset[None])[0])  # in units of `wanted`
        clear = wanted if not math.isfinite(t) or t >= 1.0 else max(self.settings.min_distance_m,
                                                                      t * wanted - self.settings.margin_m)
        if self.distance_m is None or clear < self.distance_m:
            distance = clear  # pull in at once
        else:
            ease = 1.0 - math.exp(-max(dt_s, 0.0) / self.settings.ease_back_s)
            distance = min(clear, self.distance_m + (wanted - self.distance_m) * ease)
        pulled = distance < wanted - self.settings.settle_m  # the exponential return never lands exactly
        self.distance_m = distance if pulled else None
        if not pulled:
            return proposed, False
        return CameraPose(a_world + direction * distance, proposed.rotation_xyzw, proposed.vertical_fov_deg), True
