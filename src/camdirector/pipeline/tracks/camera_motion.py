"""Force-based camera motion between cuts (Section 5.4).

Mass 1; a spring pulls the camera to the target on the tracks (`attraction_per_s2` per metre),
the actor pushes it away inside a radius (the director's: at least `repulsion_radius_m`, farther
when its shot size cannot be framed nearer), up to `repulsion_m_s2` at contact and linearly less
to zero at the radius, and speed is capped at `max_speed_m_s`. A camera on its way to a target
across the actor went straight through it (0.5 m from a LONG shot's actor, its body far out of
the frame); it now never comes nearer than the distance at which its shot size still fits, and
slides around the actor there. The paper sets
the mass to 1 "to avoid overshooting"; with a spring alone a unit mass still oscillates, so we add
the damping of a `damping_ratio`-damped spring (1: critical, the fastest approach without
overshoot), as Cinemachine's damped spring does. The damping acts on the camera's velocity
relative to the target's: damping the absolute velocity makes a camera trail a target moving at
speed v by 2 zeta v / sqrt(k) (1.1 m at a walker's 1.4 m/s), so an actor walking towards the
camera came closer than its shot size allows while the target retreated ahead of it.
Integration: semi-implicit Euler in substeps of at most `max_substep_s`, so the motion is the
same at any frame rate.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from camdirector.pipeline.tracks.settings import DirectorSettings


def move_camera(
    position_world: npt.NDArray[np.float64],
    velocity_m_s: npt.NDArray[np.float64],
    target_world: npt.NDArray[np.float64],
    target_velocity_m_s: npt.NDArray[np.float64],
    actor_world: npt.NDArray[np.float64],
    dt_s: float,
    settings: DirectorSettings,
    repulsion_radius_m: float,
    nearest_m: float = 0.0,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(position (3,), velocity (3,)) after dt_s seconds; target_velocity_m_s (3,): the target's
    over the last frame; actor_world (3,) is the repelling point, pushing inside
    repulsion_radius_m (the director's, from its shot size); the camera never comes nearer to it
    than nearest_m (m: it slides around the actor instead)."""
    if dt_s <= 0.0:
        return position_world, velocity_m_s
    steps = max(1, math.ceil(dt_s / settings.max_substep_s))
    h = dt_s / steps
    k = settings.attraction_per_s2
    c = 2.0 * settings.damping_ratio * math.sqrt(k)
    p, v = position_world.astype(np.float64).copy(), velocity_m_s.astype(np.float64).copy()
    for _ in range(steps):
        a = k * (target_world - p) + c * (target_velocity_m_s - v)
        away = p - actor_world
        r = float(np.linalg.norm(away))
        if repulsion_radius_m > 0.0 and 1e-9 < r < repulsion_radius_m:
            a += settings.repulsion_m_s2 * (1.0 - r / repulsion_radius_m) * away / r
        v += h * a
        speed = float(np.linalg.norm(v))
        if speed > settings.max_speed_m_s:
            v *= settings.max_speed_m_s / speed
        p += h * v
        away = p - actor_world
        r = float(np.linalg.norm(away))
        if 1e-9 < r < nearest_m:  # onto the sphere, the inward part of the velocity dropped
            normal = away / r
            p = actor_world + normal * nearest_m
            v -= min(0.0, float(v @ normal)) * normal
    return p, v
