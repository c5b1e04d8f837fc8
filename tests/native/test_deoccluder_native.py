"""camdirector._native.DeoccluderCore (native/src/deoccluder.rs), reactive.py's Deoccluder compiled,
against the Deoccluder: a known answer (a wall between the camera and A: the camera stops its
radius in front of it), and a camera circling a target past a wall and a moving box, with a frame
gap, under the default settings and damped ones, the Python twin casting its rays in the same
`Scene` (Embree's float32 distances would differ in their last ~7 digits: test_scene_native.py):
every frame and the state kept between frames agree within rounding.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from camdirector._native import DeoccluderCore, Scene
from camdirector.geometry.camera import CameraPose
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.transforms import RigidTransform, matrix_to_quat
from camdirector.pipeline.toric.reactive import Deoccluder, ReactiveSettings

TOL = 1e-12  # m and unit quaternion: the same operations, libm's exp, sin and cos against the system's


def _wall_scene() -> Scene:
    """A wall 4 m wide, 6 m tall, from z = 5 to 6, in front of A at the origin; a 1 m box that
    moves (added dynamic)."""
    solid = box((4.0, 6.0, 1.0))
    scene = Scene([TriMesh(solid.vertices + [0.0, 0.0, 5.5], solid.faces)])
    scene.add_dynamic("cart", box((1.0, 1.0, 1.0)), RigidTransform(np.array([6.0, 0.0, 3.0])))
    return scene


def _pose(position: np.ndarray, a_world: np.ndarray) -> CameraPose:
    """A camera at `position` looking at A, level (its right axis horizontal)."""
    forward = (a_world - position) / np.linalg.norm(a_world - position)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    return CameraPose(position, matrix_to_quat(np.stack([right, np.cross(right, forward), -forward], axis=1)), 50.0)


def test_a_camera_behind_a_wall_is_put_its_radius_in_front_of_it():
    scene = _wall_scene()
    core = DeoccluderCore(ReactiveSettings())
    a = np.zeros(3)
    wanted = np.array([0.0, 0.0, 10.0])
    position, rotation, displaced = core.run(wanted, _pose(wanted, a).rotation_xyzw, a, 0.0, 1 / 60, scene)
    # DampingWhenOccluded 0: at once; the sphere's centre stops camera_radius_m (0.1) before z = 5
    assert displaced and np.allclose(position, [0.0, 0.0, 4.9], rtol=0.0, atol=TOL)
    np.testing.assert_allclose(rotation, _pose(wanted, a).rotation_xyzw, atol=TOL)  # straight in: A stays ahead
    clear = np.array([0.0, 0.0, -10.0])  # on the open side: untouched
    position, rotation, displaced = core.run(clear, _pose(clear, a).rotation_xyzw, a, 10.0, 1 / 60, scene)
    assert not displaced and np.array_equal(position, clear)


@pytest.mark.parametrize(
    "settings",
    [
        ReactiveSettings(),
        ReactiveSettings(camera_radius_m=0.3, damping_s=0.5, damping_when_occluded_s=0.25),
        ReactiveSettings(camera_radius_m=0.0),
    ],
    ids=["defaults", "damped", "ray"],
)
def test_every_frame_and_the_state_agree_with_the_python_deoccluder(settings):
    scene = _wall_scene()
    python, core = Deoccluder(scene, settings), DeoccluderCore(settings)  # the Python twin casts in the same Scene
    dt_s, displaced_frames = 1 / 60, 0
    for frame in range(600):
        time_s = frame * dt_s + (0.5 if frame >= 300 else 0.0)  # a gap: nothing to damp from after it
        a = np.array([0.3 * math.sin(frame / 50), 1.0, 0.2 * frame / 600])
        angle = frame * 0.02  # the camera circles A, 8 m off, passing behind the wall and the cart
        wanted = a + np.array([8.0 * math.sin(angle), 1.5, 8.0 * math.cos(angle)])
        scene.set_transform("cart", RigidTransform(np.array([6.0 - frame / 60, 0.0, 3.0])))
        proposed = _pose(wanted, a)
        want, want_displaced = python.run(proposed, a, time_s, dt_s)
        position, rotation, displaced = core.run(proposed.position_world, proposed.rotation_xyzw, a, time_s, dt_s, scene)
        assert displaced == want_displaced, frame
        np.testing.assert_allclose(position, want.position_world, rtol=0.0, atol=TOL, err_msg=str(frame))
        np.testing.assert_allclose(rotation, want.rotation_xyzw, rtol=0.0, atol=TOL, err_msg=str(frame))
        np.testing.assert_allclose(core.offset_from_a, python._offset_from_a, rtol=0.0, atol=TOL)
        np.testing.assert_allclose(core.displacement, python._displacement, rtol=0.0, atol=TOL)
        assert core.damp_time_s == pytest.approx(python._damp_time_s, abs=TOL) and core.time_s == python._time_s
        displaced_frames += displaced
    assert 60 < displaced_frames < 540  # both sides of the wall were seen


def test_the_state_is_handed_over_and_bad_arrays_refused():
    core = DeoccluderCore(ReactiveSettings())
    assert core.offset_from_a is None and core.time_s is None and core.damp_time_s == 0.0
    assert np.array_equal(core.displacement, np.zeros(3))
    core.offset_from_a, core.displacement, core.damp_time_s, core.time_s = [1.0, 2.0, 3.0], (0.5, 0.0, 0.0), 0.1, 2.0
    assert core.offset_from_a.tolist() == [1.0, 2.0, 3.0] and core.displacement.tolist() == [0.5, 0.0, 0.0]
    assert (core.damp_time_s, core.time_s) == (0.1, 2.0)
    core.offset_from_a = None
    assert core.offset_from_a is None
    with pytest.raises(ValueError, match="rotation_xyzw"):
        core.run(np.zeros(3), np.zeros(3), np.ones(3), 0.0, 0.1, _wall_scene())
    with pytest.raises(ValueError, match="displacement"):
        core.displacement = [1.0, 2.0]
