"""MOTION stage of the REACTIVE baseline: what game engines ship, Cinemachine's Deoccluder (the
CinemachineCollider of Cinemachine 2) with its "pull camera forward" strategy, post-processing
the FRAMING_ONLY rig.

Cinemachine 3, Runtime/Behaviours/CinemachineDeoccluder.cs (PreserveLineOfSight,
PullCameraInFrontOfNearestObstacle, the damping in PostPipelineStageCallback), with its
documented defaults (ObstacleAvoidance.Default, MinimumDistanceFromTarget), each below:

- One cast from the LookAt target (our A) toward the rig's camera, starting
  max(minimum_distance_m, camera_radius_m) from A, so obstacles nearer A than that are ignored
  (Cinemachine starts its ray at the one and its sphere at the other); the first obstacle on
  the way is the one nearest A. With PullCameraForward and a camera radius the cast is a sphere
  cast of that radius, and the camera goes where the sphere first touches: in front of the
  obstacle, on the line to A.
- The correction (displacement from the rig's pose) is damped: growing (pulling in) with
  DampingWhenOccluded, shrinking (going back out) with Damping; a damping time is the time to
  reach 99 % of the way (Cinemachine's Damper: decay constant ln(100) / time). When there is no
  correction any more, the damping time itself decays, so the camera settles onto the rig.
  The damped quantity is the camera's offset from A carried along with A, as Cinemachine does.
- Cinemachine re-aims after this stage (its Aim stage); we turn the rig's orientation by the
  rotation that takes the old view direction of A onto the new one, so A stays exactly on
  screen_a and the roll is the rig's. The camera leaves the torus: B (or the gaze-room point) is
  no longer placed, and the shot gets tighter. It reacts to occlusion after it happens and never
  anticipates: the behaviour the paper improves on.

Deviations, stated because they change behaviour: Cinemachine's default strategy is
PreserveCameraHeight (pull forward, then walk along the obstacle back toward the original height);
the issue asks for pull-forward, the strategy most engines' follow cameras use (a spring arm).
The sphere cast is approximated by 1 + 2 * 8 parallel rays (the axis and two rings, at the camera
radius and at radius / sqrt 2): the camera stops where the first ray hit, minus the sphere's depth
at that ray's offset. SmoothingTime and MinimumOcclusionTime are left out: both default to 0
(off), and with 0 Cinemachine's code skips them. RotationDampingBypass is identity (our rigs have
no rotation damping).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import matrix_to_quat, quat_to_matrix

_EPSILON = 1e-4  # Cinemachine's UnityVectorExtensions.Epsilon
_LOG_RESIDUAL = math.log(100.0)  # Cinemachine's Damper: a damping time reaches 99 % of the way
_RING_RAYS = 8  # rays per ring of the sampled sphere cast
_Amount = TypeVar("_Amount", float, npt.NDArray[np.float64])  # what `damp` damps: a time, or a displacement


@dataclass(frozen=True)
class ReactiveSettings:
    """Cinemachine 3's defaults (CinemachineDeoccluder: MinimumDistanceFromTarget,
    ObstacleAvoidance.Default)."""

    minimum_distance_m: float = 0.1  # obstacles nearer A than this are ignored (MinimumDistanceFromTarget), m. [0.01, 100]
    camera_radius_m: float = 0.1  # the camera keeps this far from an obstacle (CameraRadius), m. [0, 10]
    damping_s: float = 0.2  # time to go 99 % of the way back out once clear (Damping), s. [0, 10]
    damping_when_occluded_s: float = 0.0  # time to go 99 % of the way in when occluded (DampingWhenOccluded), s. [0, 10]

    def __post_init__(self) -> None:
        if not (
            0.01 <= self.minimum_distance_m <= 100.0
            and 0.0 <= self.camera_radius_m <= 10.0
            and 0.0 <= self.damping_s <= 10.0
            and 0.0 <= self.damping_when_occluded_s <= 10.0
        ):
            raise ValueError(f"ReactiveSettings out of range: {self}")


def damp(amount: _Amount, damp_time_s: float, dt_s: float) -> _Amount:
    """The part of `amount` applied over dt_s with a damping time (Cinemachine's Damper.Damp):
    all of it when damp_time_s is ~0, none of it when dt_s is ~0."""
    if damp_time_s < _EPSILON:
        return amount
    if dt_s < _EPSILON:
        return amount * 0.0
    return amount * (1.0 - math.exp(-_LOG_RESIDUAL / damp_time_s * dt_s))


def _ring_offsets(direction: npt.NDArray[np.float64], radius_m: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(offsets (m, 3) perpendicular to direction, depth (m,)) of the sampled sphere cast: the
    axis, and rings at radius and radius / sqrt 2; depth is how far the sphere's front reaches
    ahead of its centre at that offset, sqrt(r^2 - offset^2)."""
    helper = np.array([0.0, 1.0, 0.0]) if abs(direction[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(direction, helper)
    u /= np.linalg.norm(u)
    v = np.cross(direction, u)
    angles = np.arange(_RING_RAYS) * (math.tau / _RING_RAYS)
    ring = np.cos(angles)[:, None] * u + np.sin(angles)[:, None] * v
    offsets = np.concatenate([np.zeros((1, 3)), radius_m * ring, radius_m / math.sqrt(2.0) * ring])
    depth = np.concatenate([[radius_m], np.zeros(_RING_RAYS), np.full(_RING_RAYS, radius_m / math.sqrt(2.0))])
    return offsets, depth


class Deoccluder:
    """Cinemachine's Deoccluder state for one session: the last correction and damping time."""

    def __init__(self, ray_scene: RayScene, settings: ReactiveSettings = ReactiveSettings()) -> None:
        self.ray_scene = ray_scene
        self.settings = settings
        self._offset_from_a: npt.NDArray[np.float64] | None = None  # last camera position - A, m (PreviousCameraOffset)
        self._displacement = np.zeros(3)  # last correction, m (PreviousDisplacement)
        self._damp_time_s = 0.0  # last damping time, s (PreviousDampTime)
        self._time_s: float | None = None  # when it last ran, s

    def clear_position(self, camera_world: npt.NDArray[np.float64], a_world: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Where pull-forward puts a camera wanted at camera_world (3,) looking at a_world (3,):
        camera_world itself when the line to A is clear, else just in front of the obstacle
        nearest A (PullCameraInFrontOfNearestObstacle)."""
        s = self.settings
        offset = camera_world - a_world
        distance = float(np.linalg.norm(offset))
        if distance <= _EPSILON:
            return camera_world
        direction = offset / distance
        if distance < s.minimum_distance_m + _EPSILON:
            return a_world + direction * s.minimum_distance_m
        start = max(s.minimum_distance_m, s.camera_radius_m)  # the sphere starts radius from A
        length = distance - start
        if length <= _EPSILON:
            return camera_world
        if s.camera_radius_m >= _EPSILON:
            offsets, depth = _ring_offsets(direction, s.camera_radius_m)
        else:
            offsets, depth = np.zeros((1, 3)), np.zeros(1)
        origins = a_world + direction * start + offsets
        t = self.ray_scene.first_hit(origins, np.broadcast_to(direction * length, origins.shape))
        hit = np.isfinite(t) & (t <= 1.0)
        if not hit.any():
            return camera_world
        along = float(np.min(t[hit] * length - depth[hit]))  # sphere centre at first contact, from start
        return a_world + direction * (start + max(along, 0.0))

    def run(self, proposed: CameraPose, a_world: npt.NDArray[np.float64], time_s: float, dt_s: float) -> tuple[CameraPose, bool]:
        """(pose, displaced): the rig's proposed pose at time_s, dt_s after the session's previous
        frame, corrected to keep the line to A clear and damped as Cinemachine damps it.
        displaced: the camera is not where the rig put it. When it did not run on the previous
        frame (the first frame, or the mode was another) there is nothing to damp from, as for
        Cinemachine's PreviousStateIsValid."""
        s = self.settings
        wanted = proposed.position_world
        displacement = self.clear_position(wanted, a_world) - wanted
        damp_time = s.damping_when_occluded_s
        continuing = self._time_s is not None and abs(time_s - dt_s - self._time_s) < 1e-9
        self._time_s = time_s
        if continuing and s.damping_s + s.damping_when_occluded_s > _EPSILON:
            growing = displacement @ displacement > self._displacement @ self._displacement
            damp_time = s.damping_when_occluded_s if growing else s.damping_s
            if displacement @ displacement < _EPSILON:  # ease the damping time itself out
                damp_time = self._damp_time_s - damp(self._damp_time_s, damp_time, dt_s)
            assert self._offset_from_a is not None  # set by the run on the previous frame
            previous = a_world + self._offset_from_a - wanted
            displacement = previous + damp(displacement - previous, damp_time, dt_s)
        camera = wanted + displacement
        self._displacement = displacement
        self._offset_from_a = camera - a_world
        self._damp_time_s = damp_time
        displaced = bool(np.linalg.norm(displacement) > 1e-3)
        if not displaced:
            return proposed, False
        return CameraPose(
            camera, _turn_toward(proposed.rotation_xyzw, wanted - a_world, camera - a_world), proposed.vertical_fov_deg
        ), True


def _turn_toward(
    rotation_xyzw: npt.NDArray[np.float64], from_offset: npt.NDArray[np.float64], to_offset: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """The camera rotation turned by the least rotation taking A's direction seen from a camera at
    A + from_offset to the direction seen from A + to_offset: A keeps its place on screen."""
    a = -from_offset / np.linalg.norm(from_offset)
    b = -to_offset / np.linalg.norm(to_offset)
    axis = np.cross(a, b)
    sin, cos = float(np.linalg.norm(axis)), float(a @ b)
    if sin < 1e-12:
        return rotation_xyzw  # same direction (opposite cannot happen: the camera stays on A's side)
    k = axis / sin
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    turn = np.eye(3) + sin * kx + (1.0 - cos) * (kx @ kx)
    return matrix_to_quat(turn @ quat_to_matrix(rotation_xyzw))
