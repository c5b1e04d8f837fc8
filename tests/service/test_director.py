"""The Director contract over both transports, with a client written only from the .proto file:
composition, ordering, style updates, stale frames, close, resume."""

from __future__ import annotations

import math

import grpc
import numpy as np
import pytest

from camdirector.v1 import director_pb2 as pb
from tests.service.wire_client import RpcFailed, capsule_target, two_target_request, walk


def project(update: pb.CameraUpdate, points_world: np.ndarray, fov_deg: float, aspect: float) -> np.ndarray:
    """Screen positions from the wire conventions alone: (x, y, z, w) quaternion camera-to-world,
    camera looking down -Z with +Y up, screen x right, y up in [-1, 1]."""
    q = update.pose.rotation
    x, y, z, w = q.x, q.y, q.z, q.w
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    c = np.array([update.pose.position.x, update.pose.position.y, update.pose.position.z])
    p_cam = (points_world - c) @ r
    t = math.tan(math.radians(fov_deg) / 2)
    return np.stack([p_cam[:, 0] / (-p_cam[:, 2] * t * aspect), p_cam[:, 1] / (-p_cam[:, 2] * t)], axis=1)


def aim_points(frame: pb.FrameUpdate, request: pb.CreateSessionRequest, positions: dict) -> np.ndarray:
    for state in frame.states:
        positions[state.id] = np.array([state.transform.position.x, state.transform.position.y, state.transform.position.z])
    return np.stack([positions[t.id] + [t.aim_offset.x, t.aim_offset.y, t.aim_offset.z] for t in request.targets])


def test_600_frames_frame_both_targets_exactly(raw):
    screen_a, screen_b = pb.ScreenPoint(x=-0.4, y=0.1), pb.ScreenPoint(x=0.3, y=-0.05)
    request = two_target_request(
        lens=pb.Lens(vertical_fov_deg=40, aspect=1.5),
        style=pb.Style(screen_a=screen_a, screen_b=screen_b, visibility=pb.FRAMING_ONLY),
        seed=11,
    )
    session_id = raw.call("CreateSession", request).session_id
    frames = list(walk(session_id, 600))
    updates = raw.stream(frames)
    assert [u.frame for u in updates] == [f.frame for f in frames]
    positions = {
        t.id: np.array([t.transform.position.x, t.transform.position.y, t.transform.position.z]) for t in request.targets
    }
    worst = 0.0
    for frame, update in zip(frames, updates):
        screen = project(update, aim_points(frame, request, positions), 40, 1.5)
        worst = max(worst, np.abs(screen - [[screen_a.x, screen_a.y], [screen_b.x, screen_b.y]]).max())
        q = update.pose.rotation
        assert abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) < 1e-9
        assert 0.0 <= update.visibility <= 1.0 and update.compute_ms > 0.0
        assert update.pose.vertical_fov_deg == 40
    assert worst < 1e-3, worst
    assert updates[0].cut and not any(u.cut for u in updates[1:])
    assert len({u.shot_id for u in updates}) == 1
    assert raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id)).frames == 600


def test_one_target_gets_gaze_room_ahead_and_moves_smoothly(raw):
    request = pb.CreateSessionRequest(targets=[capsule_target("solo")], seed=1)
    session_id = raw.call("CreateSession", request).session_id
    frames = [
        pb.FrameUpdate(
            session_id=session_id,
            frame=i,
            time_s=i / 60,
            states=[pb.ObjectState(id="solo", transform=pb.Transform(position=pb.Vec3(x=1.5 * i / 60, y=0.9)))],
        )
        for i in range(1, 301)
    ]
    updates = raw.stream(frames)
    last = frames[-1].states[0].transform.position
    target = np.array([[last.x, last.y + 0.6, last.z]])
    # default composition: the target exactly on screen_a = (-1/3, 0); walking along +x, the lead
    # point 2.5 m ahead lands near screen_b = (1/3, 0) (level horizon first), so the target faces
    # the free side of the frame
    assert np.allclose(project(updates[-1], target, 50, 16 / 9), [[-1 / 3, 0.0]], atol=1e-6)
    ahead = project(updates[-1], target + [[2.5, 0.0, 0.0]], 50, 16 / 9)[0]
    assert abs(ahead[0] - 1 / 3) < 0.05 and abs(ahead[1]) < 0.3
    cam = np.array([[u.pose.position.x, u.pose.position.y, u.pose.position.z] for u in updates])
    step = np.linalg.norm(np.diff(cam, axis=0), axis=1)
    assert step.max() < 0.2  # a walking target (2.5 cm per frame) never makes the camera jump
    for u in updates:  # level horizon (camera x axis horizontal), camera upright
        x, y, z, w = u.pose.rotation.x, u.pose.rotation.y, u.pose.rotation.z, u.pose.rotation.w
        assert abs(2 * (x * y + w * z)) < 1e-9 and 1 - 2 * (x * x + z * z) > 0.3


def test_update_style_cuts_to_the_new_composition(raw):
    request = two_target_request(seed=2)
    session_id = raw.call("CreateSession", request).session_id
    first = raw.stream(list(walk(session_id, 30)))
    new_a, new_b = pb.ScreenPoint(x=-0.6, y=0.2), pb.ScreenPoint(x=0.6, y=0.2)
    raw.call("UpdateStyle", pb.UpdateStyleRequest(session_id=session_id, style=pb.Style(screen_a=new_a, screen_b=new_b)))
    frames = list(walk(session_id, 30, start_frame=31))
    after = raw.stream(frames)
    assert after[0].cut and after[0].shot_id == first[0].shot_id + 1 and not any(u.cut for u in after[1:])
    positions = {
        t.id: np.array([t.transform.position.x, t.transform.position.y, t.transform.position.z]) for t in request.targets
    }
    for frame, update in zip(frames, after):
        screen = project(update, aim_points(frame, request, positions), 50, 16 / 9)
        assert np.allclose(screen, [[-0.6, 0.2], [0.6, 0.2]], atol=1e-6)


def test_repeated_and_late_frames_are_answered_stale(raw):
    session_id = raw.call("CreateSession", two_target_request()).session_id
    updates = raw.stream(list(walk(session_id, 10)))
    late = list(walk(session_id, 1, start_frame=5))[0]
    repeated = list(walk(session_id, 1, start_frame=10))[0]
    for frame in (late, repeated):  # each answered with its own answer (worker/table.py's answers kept)
        reply = raw.call("Frame", frame)
        assert reply.stale and reply.frame == frame.frame and "not newer" in reply.message
        assert reply.pose == updates[frame.frame - 1].pose
    assert updates[4].pose != updates[-1].pose  # the late frame's own pose is not the newest
    nxt = raw.call("Frame", list(walk(session_id, 1, start_frame=11))[0])
    assert not nxt.stale and nxt.frame == 11


def test_dropped_frames_are_tolerated(raw):
    session_id = raw.call("CreateSession", two_target_request()).session_id
    frames = [f for f in walk(session_id, 120) if f.frame % 7]  # every 7th frame never arrives
    updates = raw.stream(frames)
    assert [u.frame for u in updates] == [f.frame for f in frames] and not any(u.stale for u in updates)


def test_closed_session_is_gone(raw):
    session_id = raw.call("CreateSession", two_target_request()).session_id
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    with pytest.raises(RpcFailed) as err:
        raw.call("Frame", list(walk(session_id, 1))[0])
    assert err.value.code == grpc.StatusCode.NOT_FOUND and session_id in err.value.message


@pytest.mark.parametrize("mode", [pb.FRAMING_ONLY, pb.REACTIVE, pb.RAYCAST, pb.NO_ANTICIPATION, pb.ANTICIPATION])
def test_every_visibility_mode_keeps_the_composition_over_the_wire(raw, mode):
    request = two_target_request(style=pb.Style(visibility=mode, map_resolution=32, mask=pb.STYLE_MASK_SOFT_BEHIND))
    session_id = raw.call("CreateSession", request).session_id
    frames = list(walk(session_id, 60))
    updates = raw.stream(frames)
    positions = {
        t.id: np.array([t.transform.position.x, t.transform.position.y, t.transform.position.z]) for t in request.targets
    }
    for frame, update in zip(frames, updates):
        screen = project(update, aim_points(frame, request, positions), 50, 16 / 9)
        if mode != pb.REACTIVE:  # REACTIVE leaves the torus when it pulls in: only A stays exact
            assert np.allclose(screen, [[-1 / 3, 0.0], [1 / 3, 0.0]], atol=1e-6)
        else:
            assert np.allclose(screen[0], [-1 / 3, 0.0], atol=1e-6)
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
