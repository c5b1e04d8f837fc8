"""The TORIC rig's framing error (pipeline/toric/framing.py, `Framing.error`): how far the
framed points land from the style's screen points, in normalised screen units (the frame is
[-1, 1]), on tiny hand-built scenes with expected values, and through in-process sessions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from camdirector.geometry.camera import CameraPose, Lens, level_look_rotation, project_to_screen
from camdirector.geometry.toric import theta_max
from camdirector.geometry.transforms import matrix_to_quat, quat_to_matrix
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style
from camdirector.pipeline.toric.camera_motion import pose_on_torus
from camdirector.pipeline.toric.frame import ToricFrame
from camdirector.pipeline.toric.framing import Framing
from camdirector.v1 import director_pb2 as pb
from tests.pipeline.toric.test_visibility_modes import TARGETS, _frames, _pose, _session, _wall_between_camera_and_a

LENS, STYLE = Lens(), Style()
A_WORLD, B_WORLD = np.array([0.0, 1.5, 0.0]), np.array([3.0, 1.5, 1.0])


def framed(targets_world: list[np.ndarray]) -> tuple[Framing, FrameState]:
    """A frame of the targets framed by the rig's FRAMING stage, the camera on the torus composing
    them (halfway along theta, 20 deg up), as the FRAMING_ONLY rig places it."""
    framing = Framing(LENS, STYLE, np.array([0.0, 0.0, 0.0, 1.0]))
    state = FrameState(frame=1, time_s=0.0, dt_s=0.0, aim_points_world=targets_world, toric=ToricFrame())
    framing.run(state, state.toric)
    torus = state.toric.torus
    state.pose = pose_on_torus(torus, 0.5 * theta_max(torus.alpha), math.radians(20.0), STYLE, LENS, state.toric.b_is_gaze_point)
    return framing, state


@pytest.mark.parametrize("targets_world", [[A_WORLD], [A_WORLD, B_WORLD]], ids=["one target", "two targets"])
def test_targets_on_their_screen_points_have_no_error(targets_world):
    framing, state = framed(targets_world)
    assert framing.error(state.pose, state.toric) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("offset_screen", [(0.05, 0.0), (0.0, -0.2), (0.3, 0.5)])
def test_turning_the_camera_moves_a_off_its_point_by_the_turn(offset_screen):
    """One target: only A counts (B is the gaze-room point); the camera turned so that A lands at
    screen_a + offset: the error is the offset's larger axis."""
    framing, state = framed([A_WORLD])
    goal_screen = np.add(STYLE.screen_a, offset_screen)
    turned = level_look_rotation(state.pose.position_world, A_WORLD, goal_screen, LENS)
    state.pose = CameraPose(state.pose.position_world, turned, LENS.vertical_fov_deg)
    assert framing.error(state.pose, state.toric) == pytest.approx(max(map(abs, offset_screen)), abs=1e-9)


@pytest.mark.parametrize("shift_m", [0.05, 0.2, 0.6])
def test_sliding_the_camera_sideways_moves_the_nearer_target_most(shift_m):
    """Two targets: the camera slid shift_m along its own right axis moves each target's screen x
    by shift / (depth * tan(half horizontal fov)); the error is the nearer (larger) one."""
    framing, state = framed([A_WORLD, B_WORLD])
    rotation = quat_to_matrix(state.pose.rotation_xyzw)
    depths_m = [-(rotation.T @ (p - state.pose.position_world))[2] for p in (A_WORLD, B_WORLD)]
    state.pose = CameraPose(state.pose.position_world + shift_m * rotation[:, 0], state.pose.rotation_xyzw, LENS.vertical_fov_deg)
    assert framing.error(state.pose, state.toric) == pytest.approx(shift_m / (min(depths_m) * LENS.tan_half_fov_x), rel=1e-9)


def test_a_target_behind_the_camera_has_no_error_value():
    framing, state = framed([A_WORLD, B_WORLD])
    turned_round = quat_to_matrix(state.pose.rotation_xyzw) @ np.diag([-1.0, 1.0, -1.0])  # half a turn about its up
    state.pose = CameraPose(state.pose.position_world, matrix_to_quat(turned_round), LENS.vertical_fov_deg)
    assert math.isnan(framing.error(state.pose, state.toric))


@pytest.mark.parametrize("targets", [TARGETS[:1], TARGETS], ids=["one target", "two targets"])
def test_a_framing_only_session_keeps_its_targets_on_their_points(targets):
    table = _session(pb.FRAMING_ONLY, [], targets)
    _frames(table, 30)
    errors = [row["framing_error"] for row in table.timeline("s")["frames"]]
    assert len(errors) == 30 and errors == pytest.approx([0.0] * 30, abs=1e-4)


def test_a_reactive_pull_in_moves_b_off_its_point():
    """REACTIVE pulls the camera in front of a wall on the line to A and keeps A on its point:
    B, no longer composed, lands off screen_b (toward the frame's edge) by what its projection says."""
    wall, _ = _wall_between_camera_and_a()
    table = _session(pb.REACTIVE, [wall], TARGETS)
    updates = _frames(table, 30)
    rows = table.timeline("s")["frames"]
    for update, row in zip(updates, rows):
        assert "pulled_in" in row["flags"]
        b_screen = project_to_screen(_pose(update), LENS, B_WORLD[None])[0]
        expected = np.abs(b_screen - STYLE.screen_b).max()
        assert row["framing_error"] == pytest.approx(expected, abs=1e-4) and expected > 0.2
