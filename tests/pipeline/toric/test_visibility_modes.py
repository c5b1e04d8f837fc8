"""The rig's visibility modes on tiny hand-built scenes with expected outcomes (in-process sessions)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.table import SessionTable
from tests.service.wire_client import box_object, capsule_target


def _session(mode, objects, targets, seed=3):
    table = SessionTable(ServerSettings(workers=0, checkpoint_store="off"))
    table.create("s", pb.CreateSessionRequest(objects=objects, targets=targets, seed=seed, style=pb.Style(visibility=mode)))
    return table


def _frames(table, n, start=1, states=lambda t: []):
    return [
        table.frame(pb.FrameUpdate(session_id="s", frame=i, time_s=i / 60, states=states(i / 60)))
        for i in range(start, start + n)
    ]


def _pose(u):
    p, q = u.pose.position, u.pose.rotation
    return CameraPose(np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]), u.pose.vertical_fov_deg)


def _default_camera() -> np.ndarray:
    """Where FRAMING_ONLY puts the camera for two targets a=(0,.9,0), b=(3,.9,1) with no obstacle."""
    table = _session(pb.FRAMING_ONLY, [], [capsule_target("a"), capsule_target("b", (3.0, 0.9, 1.0))])
    u = _frames(table, 1)[0]
    return np.array([u.pose.position.x, u.pose.position.y, u.pose.position.z])


def _wall_between_camera_and_a():
    """A thin wide wall halfway between A and the default camera, square to that line."""
    a = np.array([0.0, 1.5, 0.0])
    camera = _default_camera()
    middle = 0.5 * (a + camera)
    wall = box_object("wall", tuple(middle), size=(2.5, 2.5, 0.1))
    yaw = math.atan2(camera[0] - a[0], camera[2] - a[2])  # face the wall's thin side along the line
    wall.transform.rotation.CopyFrom(pb.Quat(y=math.sin(yaw / 2), w=math.cos(yaw / 2)))
    return wall, camera


TARGETS = [capsule_target("a"), capsule_target("b", (3.0, 0.9, 1.0))]


def test_framing_only_ignores_the_wall():
    wall, camera = _wall_between_camera_and_a()
    updates = _frames(_session(pb.FRAMING_ONLY, [wall], TARGETS), 30)
    assert updates[-1].visibility < 0.75  # the wall hides A's samples: the framing rig does not care


def test_reactive_pulls_in_front_of_the_wall_keeping_a_on_screen():
    wall, camera = _wall_between_camera_and_a()
    updates = _frames(_session(pb.REACTIVE, [wall], TARGETS), 30)
    a = np.array([0.0, 1.5, 0.0])
    last = updates[-1]
    c = np.array([last.pose.position.x, last.pose.position.y, last.pose.position.z])
    assert "pulled_in" in last.diagnostics.flags
    assert np.linalg.norm(c - a) < 0.5 * np.linalg.norm(camera - a)  # in front of the wall (halfway)
    assert np.allclose(project_to_screen(_pose(last), Lens(), a[None]), [[-1 / 3, 0.0]], atol=1e-6)


def test_raycast_search_leaves_the_occluded_place_without_breaking_the_composition():
    wall, _ = _wall_between_camera_and_a()
    updates = _frames(_session(pb.RAYCAST, [wall], TARGETS), 240)
    assert updates[0].visibility < 0.75 and updates[-1].visibility == 1.0
    aims = np.array([[0.0, 1.5, 0.0], [3.0, 1.5, 1.0]])
    for u in updates:
        assert np.allclose(project_to_screen(_pose(u), Lens(), aims), [[-1 / 3, 0.0], [1 / 3, 0.0]], atol=1e-6)


def test_cuts_obey_the_30_degree_rule_and_motion_stays_within_the_limits_between_cuts():
    # a wide wall sweeps back and forth across the line between the camera and the targets, too
    # wide for any local move to escape: the search has to cut, again and again
    focus = np.array([1.5, 1.5, 0.5])
    camera = _default_camera()
    line = (camera - focus) / np.linalg.norm(camera - focus)
    across = np.cross(line, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    middle = focus + 0.5 * (camera - focus)
    yaw = math.atan2(line[0], line[2])
    wall = box_object("sweeper", tuple(middle), (8.0, 8.0, 0.2), dynamic=True)
    objects = [wall]

    def slide(t):
        p = middle + across * 9.0 * math.sin(0.8 * t)
        return [
            pb.ObjectState(
                id="sweeper",
                transform=pb.Transform(
                    position=pb.Vec3(x=p[0], y=p[1], z=p[2]), rotation=pb.Quat(y=math.sin(yaw / 2), w=math.cos(yaw / 2))
                ),
            )
        ]

    table = _session(pb.RAYCAST, objects, TARGETS, seed=11)
    updates = _frames(table, 900, states=slide)
    cams = np.array([[u.pose.position.x, u.pose.position.y, u.pose.position.z] for u in updates])
    cuts = [i for i, u in enumerate(updates) if u.cut and i > 0]
    assert cuts, "the scene must force a cut for this test to mean anything"
    for i in cuts:
        before, after = focus - cams[i - 1], focus - cams[i]
        angle = math.degrees(math.acos(np.clip(before @ after / np.linalg.norm(before) / np.linalg.norm(after), -1, 1)))
        assert angle >= 30.0 - 1e-6, f"cut at frame {i} turns the view by only {angle:.1f} deg"
    velocity = np.diff(cams, axis=0) * 60  # velocity[i - 1]: from frame i - 1 to i
    cut_set = set(cuts)
    moving = [i for i in range(1, len(cams)) if i not in cut_set]
    assert max(np.linalg.norm(velocity[i - 1]) for i in moving) <= 8.0 + 1e-6  # default speed limit
    steady = [i for i in moving if i + 1 in moving]
    accel = [np.linalg.norm(velocity[i] - velocity[i - 1]) * 60 for i in steady]
    assert max(accel) <= 12.0 + 1e-3  # default acceleration limit (targets are still: no torus motion)


@pytest.mark.parametrize("mode", [pb.REACTIVE, pb.RAYCAST])
def test_modes_switch_live_without_a_jump(mode):
    wall, _ = _wall_between_camera_and_a()
    table = _session(pb.FRAMING_ONLY, [wall], TARGETS)
    before = _frames(table, 10)
    table.update_style(pb.UpdateStyleRequest(session_id="s", style=pb.Style(visibility=mode)))
    after = _frames(table, 10, start=11)
    p0, p1 = before[-1].pose.position, after[0].pose.position
    assert not after[0].cut
    if mode == pb.RAYCAST:  # continues from where the framing rig left the camera
        assert math.dist((p0.x, p0.y, p0.z), (p1.x, p1.y, p1.z)) < 0.2


def test_the_cut_search_never_picks_a_place_within_30_degrees():
    """Only places within 25 deg of the current view are clear: no cut. Open one beyond 30 deg: cut there."""
    from camdirector.geometry.toric import make_torus, torus_position
    from camdirector.pipeline.toric.occlusion_search import OcclusionSearch, SearchSettings

    torus = make_torus([0.0, 1.5, 0.0], [3.0, 1.5, 1.0], 0.6)
    search = OcclusionSearch(SearchSettings(cut_samples=2000), np.random.default_rng(0))
    search.start(1.0, 1.2, 0.0)
    here = torus_position(torus, 1.0, 1.2)
    focus = 0.5 * (torus.a_world + torus.b_world)

    def angle_deg(places):
        u = (focus - here) / np.linalg.norm(focus - here)
        v = (focus - places) / np.linalg.norm(focus - places, axis=1, keepdims=True)
        return np.degrees(np.arccos(np.clip(v @ u, -1, 1)))

    near_only = lambda places: np.where(angle_deg(places) < 25.0, 0.0, 1.0) if len(places) > 1 else np.ones(1)
    assert search._cut(torus, here, near_only, side=1.0) is None
    far_band = lambda places: (
        np.where((angle_deg(places) > 40.0) & (angle_deg(places) < 60.0), 0.0, 1.0) if len(places) > 1 else np.ones(1)
    )
    theta, phi, occluded = search._cut(torus, here, far_band, side=1.0)
    assert occluded == 0.0 and 40.0 < angle_deg(torus_position(torus, theta, phi)[None])[0] < 60.0


def test_anticipation_moves_before_the_occluder_arrives_and_raycast_only_after():
    """A wall slides toward the line of sight at 1.5 m/s: the A-map predicts it, the ray caster
    only sees it once it hides samples (the paper's key claim, section 4.2)."""
    focus = np.array([1.5, 1.5, 0.5])
    camera = _default_camera()
    line = (camera - focus) / np.linalg.norm(camera - focus)
    across = np.cross(line, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    middle = focus + 0.6 * (camera - focus)
    turn = pb.Quat(y=math.sin(math.atan2(line[0], line[2]) / 2), w=math.cos(math.atan2(line[0], line[2]) / 2))

    def slide(t):
        p = middle + across * (6.0 - 1.5 * t)
        return [pb.ObjectState(id="w", transform=pb.Transform(position=pb.Vec3(x=p[0], y=p[1], z=p[2]), rotation=turn))]

    first = {}
    for mode in (pb.RAYCAST, pb.ANTICIPATION):
        wall = box_object("w", tuple(middle + across * 6.0), (1.5, 4.0, 0.2), dynamic=True)
        wall.transform.rotation.CopyFrom(turn)
        updates = _frames(_session(mode, [wall], TARGETS), 300, states=slide)
        occluded = [i for i, u in enumerate(updates) if u.visibility < 1.0]
        moved = [
            i
            for i, u in enumerate(updates)
            if {"search_single_frame", "search_look_ahead", "search_cut"} & set(u.diagnostics.flags)
        ]
        first[mode] = (occluded[0] if occluded else len(updates), moved[0])
    assert first[pb.RAYCAST][1] >= first[pb.RAYCAST][0]  # reacts once occluded
    assert first[pb.ANTICIPATION][1] < first[pb.ANTICIPATION][0] - 5  # moves well before


# -- REACTIVE: Cinemachine's Deoccluder, pull camera forward (pipeline/toric/reactive.py) ---------------


def _deoccluder_scene(pieces):
    """A RayScene of boxes (size, centre) that can move: each is a dynamic object "o<i>"."""
    from camdirector.geometry import meshes
    from camdirector.geometry.raycast import RayScene
    from camdirector.geometry.transforms import RigidTransform

    scene = RayScene([])
    for i, (size, centre) in enumerate(pieces):
        scene.add_dynamic(f"o{i}", meshes.box(size), RigidTransform(np.asarray(centre, dtype=float)))
    return scene


A_POINT = np.array([0.0, 1.5, 0.0])
RIG_CAMERA = np.array([0.0, 1.5, -6.0])  # the rig wants the camera 6 m from A, along -Z
LOOKING_AT_A = np.array([0.0, 1.0, 0.0, 0.0])  # half a turn about +Y: the view (-Z) points at A, A at the centre


def test_reactive_defaults_are_cinemachines():
    from camdirector.pipeline.toric.reactive import ReactiveSettings

    s = ReactiveSettings()
    # CinemachineDeoccluder: MinimumDistanceFromTarget 0.1, CameraRadius 0.1, Damping 0.2, DampingWhenOccluded 0
    assert (s.minimum_distance_m, s.camera_radius_m, s.damping_s, s.damping_when_occluded_s) == (0.1, 0.1, 0.2, 0.0)


def test_reactive_stops_a_camera_radius_in_front_of_the_obstacle_nearest_a():
    from camdirector.pipeline.toric.reactive import Deoccluder

    # two walls across the line, 2 m and 4 m from A: the one nearest A decides (its face at z = -1.95)
    scene = _deoccluder_scene([((3.0, 3.0, 0.1), (0.0, 1.5, -2.0)), ((3.0, 3.0, 0.1), (0.0, 1.5, -4.0))])
    c = Deoccluder(scene).clear_position(RIG_CAMERA, A_POINT)
    assert np.allclose(c[:2], A_POINT[:2]) and c[2] == pytest.approx(-1.95 + 0.1, abs=1e-3)
    assert np.allclose(Deoccluder(_deoccluder_scene([])).clear_position(RIG_CAMERA, A_POINT), RIG_CAMERA)


def test_reactive_ignores_obstacles_within_the_minimum_distance_and_catches_near_misses():
    from camdirector.pipeline.toric.reactive import Deoccluder, ReactiveSettings

    hugging_a = _deoccluder_scene([((3.0, 3.0, 0.02), (0.0, 1.5, -0.05))])  # a slab 5 cm in front of A
    assert np.allclose(Deoccluder(hugging_a).clear_position(RIG_CAMERA, A_POINT), RIG_CAMERA)
    # a thin pole 7 cm beside the line: the ray misses it, the camera's sphere (radius 0.1) does not
    pole = _deoccluder_scene([((0.04, 3.0, 0.04), (0.07, 1.5, -3.0))])
    assert np.allclose(Deoccluder(pole, ReactiveSettings(camera_radius_m=0.0)).clear_position(RIG_CAMERA, A_POINT), RIG_CAMERA)
    c = Deoccluder(pole).clear_position(RIG_CAMERA, A_POINT)
    assert -3.0 < c[2] < -2.85


def test_reactive_pulls_in_at_once_and_eases_back_with_cinemachines_damping():
    from camdirector.geometry.transforms import RigidTransform
    from camdirector.pipeline.toric.reactive import Deoccluder

    scene = _deoccluder_scene([((3.0, 3.0, 0.1), (0.0, 1.5, -2.0))])
    deoccluder = Deoccluder(scene)
    rig = CameraPose(RIG_CAMERA, LOOKING_AT_A, 50.0)
    dt = 1.0 / 60.0
    pose, displaced = deoccluder.run(rig, A_POINT, 0.0, 0.0)
    assert displaced and pose.position_world[2] == pytest.approx(-1.85, abs=1e-3)  # DampingWhenOccluded 0

    def frame(k):
        pose, displaced = deoccluder.run(rig, A_POINT, k * dt, dt)
        # A stays where the rig framed it (the centre of the frame here) all the way
        assert np.allclose(project_to_screen(pose, Lens(), A_POINT[None]), [[0.0, 0.0]], atol=1e-9)
        return float(pose.position_world[2]), displaced

    # the wall backs away from A by 0.1 m a frame: the correction shrinks, damped (Damping 0.2 s),
    # so the camera lags behind the place it could have, on the safe side (nearer A)
    z = [-1.85]
    for k in range(1, 11):
        scene.set_transform("o0", RigidTransform(np.array([0.0, 1.5, -2.0 - 0.1 * k])))
        z.append(frame(k)[0])
        assert z[-1] < z[-2] and z[-1] > -2.0 - 0.1 * k + 0.05 + 0.1
    # then it is gone: back out to the rig's place, eased (the damping time itself decays), in a few frames
    scene.set_transform("o0", RigidTransform(np.array([50.0, 1.5, -2.0])))
    back = [frame(k) for k in range(11, 41)]
    gap_before, gap_first = z[-1] - RIG_CAMERA[2], back[0][0] - RIG_CAMERA[2]
    assert 0.2 * gap_before < gap_first < 0.9 * gap_before  # part of the way, not a jump
    assert back[-1] == (-6.0, False)
    # a pause in REACTIVE (another mode ran meanwhile): nothing to damp from, the correction is immediate
    scene.set_transform("o0", RigidTransform(np.array([0.0, 1.5, -2.0])))
    pose, _ = deoccluder.run(rig, A_POINT, 100.0, dt)
    assert pose.position_world[2] == pytest.approx(-1.85, abs=1e-3)
