"""camdirector._native.Scene (native/src/scene.rs), RayScene's compiled twin, against RayScene:
hand-built scenes with a box moved, turned and scaled between queries (known answers), the demo
scene stepped through its obstacles' motion with thousands of camera-to-target segments and rays,
and the same bits twice.

Embree casts in float32, the Scene in float64, so the two may disagree on a segment or ray within
rounding of an edge or of a face; on the demo scene the disagreements are counted (`pytest -s`)
and must stay under 1 - MIN_AGREEMENT."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from camdirector._native import Scene, carry
from camdirector.demo.scene import DemoScene, build_demo_scene
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.toric.visibility import VisibilityEstimate

MIN_AGREEMENT = 0.999  # share of segments and rays on which RayScene and Scene agree on the demo scene
EXACT_RTOL = 1e-12  # the Scene's float64 distances against the hand-computed ones
DISTANCE_RTOL = 1e-4  # Embree's float32 distances against the Scene's float64
FRAMES = 40  # demo scene moments, 0.5 s apart (the obstacles' tracks take a few seconds each way)
SEGMENTS_PER_FRAME = 128


def _yaw(angle_rad: float) -> npt.NDArray[np.float64]:
    return np.array([0.0, np.sin(angle_rad / 2.0), 0.0, np.cos(angle_rad / 2.0)])


def _both(static: list[TriMesh]) -> tuple[Scene, RayScene]:
    return Scene(static), RayScene(static)


def _check(native: Scene, embree: RayScene, origins, targets, occluded, distances) -> None:
    """Both scenes give `occluded` for the segments and `distances` for the rays origins -> targets."""
    np.testing.assert_array_equal(native.occluded(origins, targets), occluded)
    np.testing.assert_array_equal(embree.occluded(origins, targets), occluded)
    np.testing.assert_allclose(native.first_hit(origins, targets - origins), distances, rtol=EXACT_RTOL)
    np.testing.assert_allclose(embree.first_hit(origins, targets - origins), distances, rtol=DISTANCE_RTOL)


def test_a_box_moved_turned_and_scaled_between_queries():
    """A 1 m cube (local -0.5..0.5) before a static wall at z = -10: looked at along -z from
    z = 10 through x = 0 and x = 2 (rays of length 20, so t = distance / 20)."""
    wall = TriMesh(
        np.array([[-5.0, -5.0, -10.0], [5.0, -5.0, -10.0], [5.0, 5.0, -10.0], [-5.0, 5.0, -10.0]]),
        np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32),
    )
    native, embree = _both([wall])
    origins = np.array([[0.0, 0.0, 10.0], [2.0, 0.0, 10.0]])
    targets = np.array([[0.0, 0.0, -10.0], [2.0, 0.0, -10.0]])  # on the wall: seen, but for the cube
    _check(native, embree, origins, targets, [False, False], [1.0, 1.0])
    for scene in (native, embree):
        scene.add_dynamic("cube", box((1.0, 1.0, 1.0)), RigidTransform())
    _check(native, embree, origins, targets, [True, False], [0.475, 1.0])  # front face at z = 0.5
    moved = RigidTransform(np.array([2.0, 0.0, 4.0]))
    for scene in (native, embree):
        scene.set_transform("cube", moved)
    _check(native, embree, origins, targets, [False, True], [1.0, 0.275])  # front face at z = 4.5
    # turned 45 degrees about y at x = 0: its front edge (0.5 sqrt 2 from the centre) faces the ray
    turned = RigidTransform(np.zeros(3), _yaw(np.pi / 4.0))
    for scene in (native, embree):
        scene.set_transform("cube", turned)
    t = native.first_hit(origins, targets - origins)
    np.testing.assert_allclose(t, [(10.0 - 0.5 * np.sqrt(2.0)) / 20.0, 1.0], rtol=EXACT_RTOL)
    np.testing.assert_array_equal(embree.occluded(origins, targets), native.occluded(origins, targets))
    # scaled 5 along x at x = 0: 5 m wide, so x = 2 is behind it too; 3 deep: front face at z = 1.5
    scaled = RigidTransform(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.array([5.0, 1.0, 3.0]))
    for scene in (native, embree):
        scene.set_transform("cube", scaled)
    _check(native, embree, origins, targets, [True, True], [0.425, 0.425])
    with pytest.raises(KeyError):
        native.set_transform("sphere", scaled)
    with pytest.raises(ValueError, match="already added"):
        native.add_dynamic("cube", box((1.0, 1.0, 1.0)), RigidTransform())


def test_many_objects_and_no_static_geometry():
    """Ten cubes in a row along x, no static mesh (RayScene then casts them all in one shared
    scene, past SOLO_MAX_OBJECTS): a segment along the row stops at the first; one beside it
    meets none; a target on a cube's face is not hidden by that face, a segment
    that starts on one is met at once."""
    native, embree = _both([])
    for k in range(10):
        for scene in (native, embree):
            scene.add_dynamic(f"cube_{k}", box((1.0, 1.0, 1.0)), RigidTransform(np.array([3.0 * k, 0.0, 0.0])))
    origins = np.array(
        [[-10.0, 0.0, 0.0], [-10.0, 2.0, 0.0], [-10.0, 0.0, 0.0], [14.5, 0.0, 0.0]]
    )  # the last on cube_5's face: met there, at t = 0
    targets = np.array([[40.0, 0.0, 0.0], [40.0, 2.0, 0.0], [-0.5, 0.0, 0.0], [40.0, 0.0, 0.0]])
    np.testing.assert_array_equal(native.occluded(origins, targets), [True, False, False, True])
    np.testing.assert_array_equal(embree.occluded(origins, targets), [True, False, False, True])
    np.testing.assert_allclose(native.first_hit(origins, targets - origins), [9.5 / 50.0, np.inf, 1.0, 0.0], rtol=EXACT_RTOL)
    np.testing.assert_allclose(embree.first_hit(origins, targets - origins), [9.5 / 50.0, np.inf, 1.0, 0.0], rtol=DISTANCE_RTOL)


def _demo(scene_seed: int) -> tuple[DemoScene, Scene, RayScene]:
    demo = build_demo_scene(scene_seed)
    static = [TriMesh(o.transform.apply(o.vertices), o.faces) for o in demo.static_objects]
    native, embree = _both(static)
    for o in demo.dynamic_objects:
        mesh = TriMesh(o.vertices, o.faces)
        for scene in (native, embree):
            scene.add_dynamic(o.id, mesh, o.transform)
    return demo, native, embree


def _camera_segments(
    demo: DemoScene, time_s: float, rng: np.random.Generator
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Camera-like origins (2-12 m from the avatar, 0.5-5 m up) and target points on the avatar's
    surface (vertices, moved), (SEGMENTS_PER_FRAME, 3) each."""
    avatar = demo.transforms_at(time_s)[demo.avatar.id]
    centre = avatar.position_world
    angle = rng.uniform(0.0, 2.0 * np.pi, SEGMENTS_PER_FRAME)
    distance = rng.uniform(2.0, 12.0, SEGMENTS_PER_FRAME)
    origins = centre + np.stack(
        [distance * np.cos(angle), rng.uniform(0.5, 5.0, SEGMENTS_PER_FRAME), distance * np.sin(angle)], axis=1
    )
    targets = avatar.apply(demo.avatar.vertices[rng.integers(0, len(demo.avatar.vertices), SEGMENTS_PER_FRAME)])
    return origins, targets


@pytest.mark.parametrize("scene_seed", [7, 11])
def test_the_demo_scene_through_its_motion_agrees_with_ray_scene(scene_seed):
    demo, native, embree = _demo(scene_seed)
    static_only = Scene([TriMesh(o.transform.apply(o.vertices), o.faces) for o in demo.static_objects])
    rng = np.random.default_rng(scene_seed)
    segments = segment_mismatches = rays = ray_mismatches = occluded_count = by_obstacles = 0
    distances_apart = []
    for frame in range(FRAMES):
        time_s = 0.5 * frame
        for object_id, transform in demo.transforms_at(time_s).items():
            if object_id != demo.avatar.id:
                native.set_transform(object_id, transform)
                embree.set_transform(object_id, transform)
        origins, targets = _camera_segments(demo, time_s, rng)
        hidden = native.occluded(origins, targets)
        segment_mismatches += int((hidden != embree.occluded(origins, targets)).sum())
        segments += len(hidden)
        occluded_count += int(hidden.sum())
        by_obstacles += int((hidden & ~static_only.occluded(origins, targets)).sum())
        t, t_embree = native.first_hit(origins, targets - origins), embree.first_hit(origins, targets - origins)
        ray_mismatches += int((np.isfinite(t) != np.isfinite(t_embree)).sum())
        rays += len(t)
        both = np.isfinite(t) & np.isfinite(t_embree)
        distances_apart.append(np.abs(t[both] - t_embree[both]) > DISTANCE_RTOL * t_embree[both])
    apart = int(np.concatenate(distances_apart).sum())
    print(
        f"\ndemo scene {scene_seed}: {segments} segments, {occluded_count} occluded ({by_obstacles} by moving obstacles "
        f"alone), {segment_mismatches} disagree; "
        f"{rays} rays, {ray_mismatches} disagree on hit or miss, {apart} distances beyond {DISTANCE_RTOL:g} of Embree's"
    )
    assert 0 < by_obstacles and occluded_count < segments  # the sample means something, the obstacles too
    assert 1.0 - segment_mismatches / segments >= MIN_AGREEMENT
    assert 1.0 - ray_mismatches / rays >= MIN_AGREEMENT
    assert apart <= (1.0 - MIN_AGREEMENT) * rays


def test_the_same_inputs_give_the_same_bits():
    demo, native, _ = _demo(7)
    _, again, _ = _demo(7)
    rng = np.random.default_rng(3)
    for time_s in (0.0, 3.3, 7.1):
        for scene in (native, again):
            for object_id, transform in demo.transforms_at(time_s).items():
                if object_id != demo.avatar.id:
                    scene.set_transform(object_id, transform)
        origins, targets = _camera_segments(demo, time_s, rng)
        assert native.occluded(origins, targets).tobytes() == again.occluded(origins, targets).tobytes()
        assert native.first_hit(origins, targets - origins).tobytes() == again.first_hit(origins, targets - origins).tobytes()


def test_visible_share_is_the_visibility_stage_answer():
    demo, native, embree = _demo(7)
    rng = np.random.default_rng(5)
    estimate = VisibilityEstimate(embree, [TriMesh(demo.avatar.vertices, demo.avatar.faces)], rng)
    for time_s in np.linspace(0.0, 19.0, 20):
        for object_id, transform in demo.transforms_at(time_s).items():
            if object_id != demo.avatar.id:
                native.set_transform(object_id, transform)
                embree.set_transform(object_id, transform)
        points = estimate.points_world([demo.transforms_at(time_s)[demo.avatar.id]])
        origins, _ = _camera_segments(demo, time_s, rng)
        for camera in origins[:8]:
            expected = 1.0 - float(estimate.occluded_fraction(camera[None], points)[0])
            hidden = native.occluded(camera, points)
            assert native.visible_share(camera, points) == 1.0 - hidden.mean()
            assert abs(native.visible_share(camera, points) - expected) <= 1.0 / len(points)  # one edge ray at most
    with pytest.raises(ValueError, match="empty"):
        native.visible_share(np.zeros(3), np.zeros((0, 3)))


def test_visible_share_of_carries_each_targets_samples_as_carry_does():
    """visible_share_of(camera, samples, transforms) is visible_share of the samples carried one
    `carry` call a target and concatenated in target order, to the bit; pairs as zip takes them."""
    demo, native, _ = _demo(7)
    rng = np.random.default_rng(11)
    samples = [rng.normal(size=(16, 3)) * 0.4, rng.normal(size=(9, 3)) * 0.3]
    for time_s in np.linspace(0.0, 19.0, 12):
        placed = demo.transforms_at(time_s)
        for object_id, transform in placed.items():
            if object_id != demo.avatar.id:
                native.set_transform(object_id, transform)
        first = placed[demo.avatar.id]
        second = RigidTransform(first.position_world + rng.normal(size=3), _yaw(rng.uniform(0.0, 6.0)), np.array([1.0, 1.2, 0.8]))
        transforms = [first, second]
        points = np.concatenate([carry(local, transform) for local, transform in zip(samples, transforms)])
        for camera in _camera_segments(demo, time_s, rng)[0][:6]:
            share = native.visible_share_of(camera, samples, transforms)
            assert share == native.visible_share(camera, points)
            assert native.visible_share_of(camera, samples, transforms[:1]) == native.visible_share(camera, points[:16])
    with pytest.raises(ValueError, match="empty"):
        native.visible_share_of(np.zeros(3), [], [])


def test_arrays_as_the_toric_rig_passes_them_and_bad_ones_refused():
    """One origin (3,) for many segments, directions as np.broadcast_to's read-only view with zero
    strides (Deoccluder.clear_position's), (vertices, faces) pairs: the same answers as RayScene's;
    bad shapes, NaN and a zero scale are refused with the reason."""
    demo, native, embree = _demo(7)
    origins, targets = _camera_segments(demo, 2.0, np.random.default_rng(9))
    camera = origins[0]
    np.testing.assert_array_equal(native.occluded(camera, targets), embree.occluded(camera, targets))
    direction = np.broadcast_to(targets[0] - camera, targets.shape)
    np.testing.assert_allclose(native.first_hit(origins, direction), embree.first_hit(origins, direction), rtol=DISTANCE_RTOL)
    pairs = Scene([(o.transform.apply(o.vertices), o.faces.astype(np.int64)) for o in demo.static_objects])
    static = Scene([TriMesh(o.transform.apply(o.vertices), o.faces) for o in demo.static_objects])
    assert pairs.first_hit(origins, targets - origins).tobytes() == static.first_hit(origins, targets - origins).tobytes()
    with pytest.raises(ValueError, match="3 origins and 4 targets"):
        native.occluded(np.zeros((3, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="NaN or infinite"):
        native.first_hit(camera, np.array([[0.0, np.nan, 1.0]]))
    with pytest.raises(ValueError, match="scale has a zero"):
        native.set_transform(demo.dynamic_objects[0].id, RigidTransform(scale=np.array([1.0, 0.0, 1.0])))
    with pytest.raises(ValueError, match="out of range"):
        Scene([(np.zeros((3, 3)), np.array([[0, 1, 3]]))])
