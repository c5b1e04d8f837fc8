"""Measurement on tiny hand-built scenes whose answers are known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from camdirector.evaluation.scenario_file import parse_scenario
from camdirector.evaluation.scenario_schema import FORMAT
from camdirector.evaluation.toric.measure import (
    CameraTrack,
    VisibilityMeter,
    camera_kinematics,
    measure,
    measure_visibility,
    summarize,
)
from camdirector.v1 import director_pb2 as pb

TARGET = {"id": "ball", "shape": {"sphere": {"radius": 0.5}}, "position": [0.0, 1.0, 0.0]}
CAMERA = np.array([0.0, 1.0, -10.0])  # looking at the ball along +Z
FACING_PLUS_Z = [0.0, 1.0, 0.0, 0.0]  # camera-to-world: half a turn about +Y, so the view (-Z) is +Z


def scene(objects=(), targets=(TARGET,), duration_s=1.0, rate=10.0, **extra):
    return parse_scenario(
        {
            "format": FORMAT,
            "name": "probe",
            "duration_s": duration_s,
            "frame_rate_hz": rate,
            "targets": list(targets),
            "objects": list(objects),
            **extra,
        }
    )


def track(times, positions, cut=None, rotation=FACING_PLUS_Z) -> CameraTrack:
    n = len(times)
    return CameraTrack(
        frame=np.arange(1, n + 1),
        time_s=np.asarray(times, dtype=float),
        position=np.asarray(positions, dtype=float),
        rotation=np.tile(rotation, (n, 1)).astype(float),
        vertical_fov_deg=np.full(n, 50.0),
        cut=np.zeros(n, bool) if cut is None else np.asarray(cut),
        shot_id=np.ones(n, int),
        rig_visibility=np.ones(n),
        compute_ms=np.ones(n),
        stage_ms={},
    )


def visibility_from(camera, objects=(), targets=(TARGET,)) -> float:
    s = scene(objects, targets, duration_s=0.1)
    return float(measure_visibility(s, s.timeline(), track([0.0], [camera])).pooled[0])


def box(object_id, size, position, **extra):
    return {"id": object_id, "shape": {"box": {"size": size}}, "position": position, **extra}


def test_nothing_in_between_sees_everything():
    assert visibility_from(CAMERA) == 1.0
    assert visibility_from(CAMERA, [box("behind", [4, 4, 0.2], [0, 1, 5])]) == 1.0


def test_a_wall_in_between_hides_everything():
    assert visibility_from(CAMERA, [box("wall", [4, 4, 0.2], [0, 1, -5])]) == 0.0


def test_a_wall_over_half_the_view_hides_about_half():
    # a wall over x < 0 between camera and ball; the camera far away so rays are nearly parallel
    far = np.array([0.0, 1.0, -200.0])
    v = visibility_from(far, [box("half", [4, 4, 0.2], [-2.0, 1, -5])])
    assert v == pytest.approx(0.5, abs=0.08)


def test_targets_do_not_hide_each_other():
    behind = {"id": "behind", "shape": {"sphere": {"radius": 0.5}}, "position": [0.0, 1.0, 3.0]}
    assert visibility_from(CAMERA, targets=[TARGET, behind]) == 1.0


def test_visibility_pools_the_vertices_of_both_targets():
    aside = {"id": "aside", "shape": {"sphere": {"radius": 0.5}}, "position": [3.0, 1.0, 3.0]}
    wall_on_first = box("wall", [1.5, 1.5, 0.2], [0, 1, -1])  # hides the first ball only
    s = scene([wall_on_first], [TARGET, aside], duration_s=0.1)
    seen = measure_visibility(s, s.timeline(), track([0.0], [CAMERA]))
    assert seen.per_target[0].tolist() == [0.0, 1.0]
    assert seen.pooled[0] == pytest.approx(0.5)  # same mesh, same vertex count


def test_a_camera_inside_an_object_sees_nothing():
    assert visibility_from([0.0, 1.0, -5.0], [box("crate", [2, 2, 2], [0, 1, -5])]) == 0.0


def test_a_target_out_of_frame_is_not_visible_though_nothing_hides_it():
    s = scene(duration_s=0.1)
    facing_away = measure_visibility(s, s.timeline(), track([0.0], [CAMERA], rotation=[0.0, 0.0, 0.0, 1.0]))
    assert facing_away.pooled[0] == 0.0 and facing_away.line_of_sight[0] == 1.0
    # turned by half the horizontal field of view (50 deg vertical, 16:9): the frame's edge runs
    # through the ball's centre
    yaw = math.pi + math.atan(math.tan(math.radians(25.0)) * 16 / 9)
    half = measure_visibility(s, s.timeline(), track([0.0], [CAMERA], rotation=[0, math.sin(yaw / 2), 0, math.cos(yaw / 2)]))
    assert 0.2 < half.pooled[0] < 0.8 and half.line_of_sight[0] == 1.0


def test_a_close_up_crops_the_target():
    tall = {"id": "pole", "shape": {"capsule": {"radius": 0.3, "height": 1.8}}, "position": [0.0, 1.0, 0.0]}
    assert visibility_from(CAMERA, targets=[tall]) == 1.0
    assert visibility_from([0.0, 1.0, -0.8], targets=[tall]) < 0.6  # half a metre from its surface


def test_composition_error_and_distance():
    s = scene(duration_s=0.1, style={"screen_a": [0.0, 0.0]})
    m = measure(s, s.timeline(), track([0.0], [CAMERA]))
    assert m.composition_error[0] == pytest.approx(0.0, abs=1e-9) and m.distance_to_a_m[0] == pytest.approx(10.0)
    s = scene(duration_s=0.1)  # the default style puts A at (-1/3, 0)
    m = measure(s, s.timeline(), track([0.0], [CAMERA]))
    assert m.composition_error[0] == pytest.approx(1.0 / 3.0)
    summary = m.summary()
    assert summary["composition_error"]["median"] == pytest.approx(1.0 / 3.0)
    assert summary["line_of_sight"]["median"] == 1.0 and summary["distance_to_a_m"]["median"] == pytest.approx(10.0)


def test_the_occluded_share_counts_frames_not_fully_visible():
    # the ball walks behind a wall (1 m in front of its path, x from 4.5 to 7.5) in the last frames
    walker = dict(TARGET, motion={"position_keys": [[0.0, 0, 1, 0], [1.0, 6, 1, 0]]})
    s = scene([box("wall", [3, 4, 0.2], [6, 1, -1])], [walker], duration_s=1.0)
    m = measure(s, s.timeline(), track(s.frame_times(), [CAMERA] * 11))
    hidden = int(np.sum(m.visibility < 1.0))
    assert 0 < hidden < 11 and m.summary()["occluded_share"] == pytest.approx(hidden / 11)


def test_dynamic_occluders_move_and_spawn():
    # frame 1 (t=0): the slab is off to the side; frame 2 (t=0.1): between camera and ball
    slab = box("slab", [2, 2, 0.2], [10, 1, -5], dynamic=True, motion={"position_keys": [[0.0, 10, 1, -5], [0.1, 0, 1, -5]]})
    late = box("late", [2, 2, 0.2], [0, 1, -3], dynamic=True, spawn_s=0.15)  # parked until 0.15 s
    s = scene([slab], duration_s=0.2)
    assert measure_visibility(s, s.timeline(), track([0.0, 0.1, 0.2], [CAMERA] * 3)).pooled.tolist() == [1.0, 0.0, 0.0]
    s = scene([late], duration_s=0.2)
    assert measure_visibility(s, s.timeline(), track([0.0, 0.1, 0.2], [CAMERA] * 3)).pooled.tolist() == [1.0, 1.0, 0.0]


def test_a_moving_target_is_measured_where_it_is():
    walker = dict(TARGET, motion={"position_keys": [[0.0, 0, 1, 0], [1.0, 6, 1, 0]]})
    wall = box("wall", [3, 4, 0.2], [6, 1, -5])  # in front of where the ball ends
    s = scene([wall], [walker], duration_s=1.0)
    cameras = [[x, 1.0, -10.0] for x in np.linspace(0, 6, 11)]  # the camera follows along x
    m = measure(s, s.timeline(), track(s.frame_times(), cameras))
    assert m.visibility[0] == 1.0 and m.visibility[-1] == 0.0
    assert np.allclose(m.target_position["ball"][-1], [6, 1, 0])


def test_constant_speed_gives_that_speed_and_no_acceleration():
    t = np.array([0.0, 0.1, 0.25, 0.3, 0.5, 0.8, 0.85])  # uneven steps
    direction = np.array([3.0, 0.0, 4.0]) / 5.0
    speed, accel = camera_kinematics(t, 2.5 * t[:, None] * direction + [1, 2, 3])
    assert math.isnan(speed[0]) and np.allclose(speed[1:], 2.5)
    assert math.isnan(accel[0]) and math.isnan(accel[-1]) and np.allclose(accel[1:-1], 0.0, atol=1e-9)


def test_constant_acceleration_is_recovered():
    t = np.array([0.0, 0.1, 0.25, 0.3, 0.5, 0.8])
    _, accel = camera_kinematics(t, 0.5 * 4.0 * t[:, None] ** 2 * [0.0, 1.0, 0.0])
    assert np.allclose(accel[1:-1], 4.0)


def test_a_cut_is_counted_not_measured_as_motion():
    t = np.arange(6) / 10.0
    p = np.zeros((6, 3))
    p[:, 0] = t
    p[3:, 0] += 50.0  # teleport between frames 2 and 3
    cut = np.array([True, False, False, True, False, False])
    speed, accel = camera_kinematics(t, p, cut)
    assert np.isnan(speed[3]) and np.allclose(speed[[1, 2, 4, 5]], 1.0)
    assert np.isnan(accel[2]) and np.isnan(accel[3]) and np.allclose(accel[[1, 4]], 0.0)
    s = scene(duration_s=0.5)
    m = measure(s, s.timeline(), track(t, p + [0, 1, -10], cut))
    assert m.cuts == 1 and m.summary()["speed_m_s"]["max"] == pytest.approx(1.0)


def test_camera_track_from_updates_drops_stale_replies():
    def update(frame, x, stale=False, cut=False):
        u = pb.CameraUpdate(
            frame=frame,
            time_s=frame / 10,
            cut=cut,
            stale=stale,
            visibility=0.5,
            compute_ms=2.0,
            shot_id=1,
            pose=pb.CameraPose(position=pb.Vec3(x=x), rotation=pb.Quat(w=1), vertical_fov_deg=50),
        )
        u.diagnostics.stage_ms.update({"ingest": 0.1, "motion": 0.3})
        if frame == 2:
            u.diagnostics.flags.append("degenerate_torus")
        return u

    t = CameraTrack.from_updates([update(1, 0.0, cut=True), update(2, 1.0), update(2, 1.0, stale=True), update(3, 2.0)])
    assert t.frame.tolist() == [1, 2, 3] and t.stale == 1
    assert t.position[:, 0].tolist() == [0.0, 1.0, 2.0] and t.rotation[0].tolist() == [0, 0, 0, 1]
    assert list(t.stage_ms) == ["ingest", "motion"] and t.stage_ms["motion"].tolist() == [0.3] * 3
    assert t.flags == {"degenerate_torus": 1} and t.cut.tolist() == [True, False, False]


def test_summary_statistics():
    s = summarize(np.array([1.0, 2.0, np.nan, 3.0, 4.0, 5.0]))
    assert (s["n"], s["median"], s["q1"], s["q3"], s["min"], s["max"]) == (5, 3.0, 2.0, 4.0, 1.0, 5.0)
    assert summarize(np.array([np.nan]))["median"] is None


def test_dynamic_objects_hide_only_the_rays_they_cross():
    near = box("near", [2, 2, 0.2], [0, 1, -5], dynamic=True)
    far = box("far", [2, 2, 0.2], [40, 1, -5], dynamic=True)
    s = scene([far, near], duration_s=0.1)
    meter = VisibilityMeter(s)
    hidden = meter.hidden(CAMERA, np.array([[0.0, 1.0, 0.0], [30.0, 1.0, 0.0]]), s.timeline(), 0)
    assert hidden.tolist() == [True, False]
