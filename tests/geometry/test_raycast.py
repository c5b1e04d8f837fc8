"""RayScene's dynamic objects, culled by bounding spheres in one shared scene or cast one by one
(a few of them), answer exactly as the same geometry built in the world frame as static meshes."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.geometry.meshes import TriMesh, box, capsule
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform


def _random_transform(rng: np.random.Generator) -> RigidTransform:
    q = rng.normal(size=4)
    return RigidTransform(rng.uniform(-6, 6, 3), q / np.linalg.norm(q), rng.uniform(0.5, 2.0, 3))


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize(
    "count, solo_max_objects",
    [(30, 4), (30, 30), (3, 4), (3, 0)],
    ids=["many-shared", "many-one-by-one", "few-one-by-one", "few-shared"],
)
def test_culled_dynamic_objects_match_world_frame_geometry(seed, count, solo_max_objects):
    rng = np.random.default_rng(seed)
    meshes = [box(rng.uniform(0.3, 2.0, 3)) if k % 2 else capsule(0.4, 1.8) for k in range(count)]
    # Off-centre local frames too: the bounding sphere must follow the mesh, not the origin.
    meshes = [TriMesh(m.vertices + rng.uniform(-1, 1, 3), m.faces) for m in meshes]
    floor = box((30.0, 0.1, 30.0))
    scene = RayScene([floor], solo_max_objects=solo_max_objects)
    start = [_random_transform(rng) for _ in meshes]
    for k, (mesh, tf) in enumerate(zip(meshes, start)):
        scene.add_dynamic(f"o{k}", mesh, tf)
    for _ in range(3):  # move everything, then ask again
        moved = [_random_transform(rng) for _ in meshes]
        for k, tf in enumerate(moved):
            scene.set_transform(f"o{k}", tf)
        reference = RayScene([floor] + [TriMesh(tf.apply(m.vertices), m.faces) for m, tf in zip(meshes, moved)])
        origins = rng.uniform(-9, 9, (400, 3))
        targets = rng.uniform(-9, 9, (400, 3))
        occluded = scene.occluded(origins, targets)
        assert 0 < occluded.sum() < len(occluded)  # the case tests something
        np.testing.assert_array_equal(occluded, reference.occluded(origins, targets))
        directions = targets - origins
        np.testing.assert_allclose(
            scene.first_hit(origins, directions), reference.first_hit(origins, directions), rtol=1e-5, atol=1e-5
        )


@pytest.mark.parametrize("seed", range(5))
def test_objects_cast_one_by_one_away_from_a_camera_query_are_skipped_and_answers_stay_exact(seed):
    """A visibility query (one camera, points on a target a few metres off) leaves most moving
    objects outside the box around its segments: those are not cast, and the answers are the
    world-frame geometry's."""
    rng = np.random.default_rng(seed)
    # far left; small, in the middle of the path; centred outside the segments' box but reaching into
    # it near the targets (its sphere, not its centre, decides); far right
    meshes = [box(rng.uniform(0.3, 1.0, 3)), box((0.4, 0.4, 0.4)), box((1.2, 0.4, 0.4)), box(rng.uniform(0.3, 1.0, 3))]
    floor = box((30.0, 0.1, 30.0))
    scene = RayScene([floor], solo_max_objects=4)
    moved = [
        RigidTransform(np.array(p), np.array([0.0, 0.0, 0.0, 1.0]))
        for p in ([-8.0, 0.5, 0.0], [0.0, 0.5, 0.0], [0.9, 0.5, 5.0], [8.0, 0.5, 0.0])
    ]
    for k, (mesh, tf) in enumerate(zip(meshes, moved)):
        scene.add_dynamic(f"o{k}", mesh, tf)
    reference = RayScene([floor] + [TriMesh(tf.apply(m.vertices), m.faces) for m, tf in zip(meshes, moved)])
    camera = np.array([0.0, 0.5, -6.0 + rng.uniform(-0.5, 0.5)])
    targets = np.array([0.0, 0.5, 6.0]) + rng.uniform(-0.5, 0.5, (32, 3))
    occluded = scene.occluded(camera, targets)
    assert 0 < occluded.sum() < len(occluded)  # the case tests something
    reaching = RayScene([TriMesh(moved[2].apply(meshes[2].vertices), meshes[2].faces)])
    assert reaching.occluded(camera, targets).any()  # the object centred outside the box hides some
    np.testing.assert_array_equal(occluded, reference.occluded(camera, targets))
    box_around = np.minimum(camera, targets).min(axis=0), np.maximum(camera, targets).max(axis=0)
    assert len(scene._each(box_around)) == 2  # the far objects at x = +-8 are skipped
    assert len(scene._each()) == 4
