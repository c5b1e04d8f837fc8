"""Force-based camera motion (pipeline/tracks/camera_motion.py): the camera keeps pace with a
target moving at constant speed, and the actor pushes it out to the radius it is given."""

from __future__ import annotations

import numpy as np

from camdirector.pipeline.tracks.camera_motion import move_camera
from camdirector.pipeline.tracks.settings import DirectorSettings

SETTINGS = DirectorSettings()
FAR_ACTOR = np.array([0.0, 0.0, 100.0])  # out of every repulsion radius


def follow(speed_m_s: float, seconds: float, feed_forward: bool, dt_s: float = 1.0 / 30.0) -> float:
    """Distance from the camera to a target moving along +x at speed_m_s after `seconds`, m."""
    camera, velocity = np.zeros(3), np.zeros(3)
    target_velocity = np.array([speed_m_s, 0.0, 0.0])
    for k in range(1, int(seconds / dt_s) + 1):
        target = target_velocity * k * dt_s
        camera, velocity = move_camera(
            camera,
            velocity,
            target,
            target_velocity if feed_forward else np.zeros(3),
            FAR_ACTOR,
            dt_s,
            SETTINGS,
            SETTINGS.repulsion_radius_m,
        )
    return float(np.linalg.norm(camera - target))


def test_the_camera_keeps_pace_with_a_walking_target_instead_of_trailing_it():
    # a damped spring on the absolute velocity trails by 2 zeta v / sqrt(k), 1.14 m at 1.4 m/s (a
    # little less here: the target steps once a frame); matched to the target's velocity, the lag
    # is what one frame's step leaves, centimetres
    lag_m = 2.0 * SETTINGS.damping_ratio * 1.4 / np.sqrt(SETTINGS.attraction_per_s2)
    assert 0.9 * lag_m < follow(1.4, 5.0, feed_forward=False) < lag_m
    assert follow(1.4, 5.0, feed_forward=True) < 1.4 / 30.0


def test_the_actor_pushes_the_camera_out_to_the_radius_it_is_given():
    actor = np.zeros(3)
    for radius_m in (1.0, 2.5):
        camera, velocity = np.array([0.5, 0.0, 0.0]), np.zeros(3)
        for _ in range(300):  # the target sits on the actor: only the repulsion keeps the camera off
            camera, velocity = move_camera(camera, velocity, actor, np.zeros(3), actor, 1.0 / 30.0, SETTINGS, radius_m)
        assert 0.3 * radius_m < np.linalg.norm(camera) < radius_m


def test_a_camera_bound_across_the_actor_goes_round_it_no_nearer_than_it_is_told():
    actor, target = np.zeros(3), np.array([-3.0, 0.0, 0.05])  # straight through the actor from +x
    position, velocity, nearest = np.array([3.0, 0.0, 0.0]), np.zeros(3), []
    for _ in range(300):
        position, velocity = move_camera(
            position, velocity, target, np.zeros(3), actor, 1.0 / 30.0, SETTINGS, SETTINGS.repulsion_radius_m, 2.0
        )
        nearest.append(np.linalg.norm(position - actor))
    assert min(nearest) >= 2.0 - 1e-9  # without the bound it passes 4 cm from the actor
    assert np.linalg.norm(position - target) < 1e-3  # and it got round to the other side
