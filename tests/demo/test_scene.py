"""The procedural demo scene: determinism, layout guarantees and valid motion."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.demo.scene import (
    AVATAR_RADIUS_M,
    COLUMN_CLEARANCE_M,
    COLUMN_REACH_M,
    DemoScene,
    build_demo_scene,
    distance_to_polyline,
)
from camdirector.geometry.transforms import quat_to_matrix

SEEDS = (0, 3, 7, 11, 19)
STEP_S = 0.05


@pytest.fixture(scope="module", params=SEEDS, ids=lambda seed: f"seed{seed}")
def scene(request) -> DemoScene:
    return build_demo_scene(seed=request.param)


def _times_s(scene: DemoScene) -> np.ndarray:
    return np.arange(0.0, scene.duration_s + STEP_S, STEP_S)


def _footprint_radius_m(vertices: np.ndarray) -> float:
    """Radius of the smallest circle about the local origin containing the mesh seen from above."""
    return float(np.max(np.hypot(vertices[:, 0], vertices[:, 2])))


def test_same_seed_same_scene_other_seed_other_scene():
    a, b, c = build_demo_scene(seed=5), build_demo_scene(seed=5), build_demo_scene(seed=6)
    np.testing.assert_array_equal(a.avatar_path_xz, b.avatar_path_xz)
    np.testing.assert_array_equal(a.column_centers_xz, b.column_centers_xz)
    assert [o.id for o in a.all_objects()] == [o.id for o in b.all_objects()]
    for oa, ob in zip(a.all_objects(), b.all_objects()):
        np.testing.assert_array_equal(oa.vertices, ob.vertices)
        np.testing.assert_array_equal(oa.transform.matrix(), ob.transform.matrix())
    for object_id, transform in a.transforms_at(9.3).items():
        np.testing.assert_array_equal(transform.matrix(), b.transforms_at(9.3)[object_id].matrix())
    assert not np.array_equal(a.avatar_path_xz[-1], c.avatar_path_xz[-1])


def test_counts_sizes_and_walk(scene):
    assert 10 <= len(scene.column_radii_m) <= 20
    assert 3 <= len(scene.dynamic_objects) <= 6
    assert 1.3 <= scene.avatar_speed_m_s <= 1.6
    heights_m = scene.avatar.vertices[:, 1]
    assert heights_m.min() == pytest.approx(0.0, abs=1e-9)
    assert heights_m.max() == pytest.approx(1.8, abs=0.05)
    assert _footprint_radius_m(scene.avatar.vertices) <= AVATAR_RADIUS_M
    walked_m = np.sum(np.linalg.norm(np.diff(scene.avatar_path_xz, axis=0), axis=1))
    assert walked_m == pytest.approx(scene.avatar_speed_m_s * scene.duration_s, rel=0.01)
    # The path turns: at least a quarter turn of heading change in all.
    assert np.sum(np.abs(np.diff(scene.avatar_heading_rad))) > np.pi / 2
    ground = next(o for o in scene.static_objects if o.kind == "ground")
    assert ground.vertices[:, 1].max() == pytest.approx(0.0)


def test_columns_keep_clear_of_the_path_but_near_it(scene):
    avatar_xz = scene.avatar_position_xz(_times_s(scene))  # (k, 2) where the avatar really walks
    for center, radius_m in zip(scene.column_centers_xz, scene.column_radii_m):
        surface_gap_m = np.linalg.norm(avatar_xz - center, axis=1) - radius_m
        assert surface_gap_m.min() >= COLUMN_CLEARANCE_M - 0.01
    # Every column is close enough to the path to come between the avatar and a nearby camera.
    gap_m = distance_to_polyline(scene.column_centers_xz, scene.avatar_path_xz)
    assert np.all(gap_m - scene.column_radii_m <= COLUMN_REACH_M + 1e-9)
    columns = [o for o in scene.static_objects if o.kind == "column"]
    world_xz = [c.transform.position_world[[0, 2]] for c in columns]
    np.testing.assert_allclose(world_xz, scene.column_centers_xz)


def test_obstacles_never_enter_columns_nor_the_avatar(scene):
    times_s = _times_s(scene)
    avatar_xz = scene.avatar_position_xz(times_s)
    for obj, track in zip(scene.dynamic_objects, scene.obstacle_tracks):
        assert obj.id == track.object_id
        footprint_m = _footprint_radius_m(obj.vertices)
        obstacle_xz = np.array([scene.transforms_at(t)[obj.id].position_world[[0, 2]] for t in times_s[::4]])
        gap_m = np.linalg.norm(obstacle_xz[:, None] - scene.column_centers_xz[None], axis=2)
        assert np.all(gap_m >= scene.column_radii_m + footprint_m)
        # Checked densely on the track too, for the instants between the samples above.
        dense_xz = track.position_xz(times_s)
        gap_m = np.linalg.norm(dense_xz[:, None] - scene.column_centers_xz[None], axis=2)
        assert np.all(gap_m >= scene.column_radii_m + footprint_m)
        assert np.min(np.linalg.norm(dense_xz - avatar_xz, axis=1)) >= footprint_m + AVATAR_RADIUS_M
        # Each obstacle does cross the avatar's path.
        assert distance_to_polyline(dense_xz, scene.avatar_path_xz).min() < 0.1


def test_transforms_are_valid_and_the_avatar_faces_its_walk(scene):
    expected_ids = {scene.avatar.id, *(o.id for o in scene.dynamic_objects)}
    for t in np.arange(0.0, scene.duration_s, 0.5):
        transforms = scene.transforms_at(t)
        assert set(transforms) == expected_ids
        for transform in transforms.values():
            assert np.all(np.isfinite(transform.position_world))
            assert np.linalg.norm(transform.rotation_xyzw) == pytest.approx(1.0, abs=1e-9)
            assert transform.position_world[1] == 0.0  # everything stands on the ground
        forward = quat_to_matrix(transforms[scene.avatar.id].rotation_xyzw) @ np.array([0, 0, 1.0])
        step = scene.avatar_position_xz(t + 0.1) - scene.avatar_position_xz(t)
        walk = np.array([step[0], 0.0, step[1]]) / np.linalg.norm(step)
        assert forward @ walk > 0.99


def test_the_avatar_stops_at_the_end_and_aims_at_chest_height(scene):
    end = scene.avatar_position_xz(scene.duration_s)
    np.testing.assert_allclose(scene.avatar_position_xz(scene.duration_s + 5.0), end)
    np.testing.assert_allclose(end, scene.avatar_path_xz[-1], atol=1e-6)
    aim = scene.aim_point_world(3.0)
    np.testing.assert_allclose(aim[[0, 2]], scene.avatar_position_xz(3.0))
    assert aim[1] == pytest.approx(1.5)


def test_duration_out_of_range_is_refused():
    with pytest.raises(ValueError):
        build_demo_scene(duration_s=0.0)
    with pytest.raises(ValueError):
        build_demo_scene(duration_s=1e4)
