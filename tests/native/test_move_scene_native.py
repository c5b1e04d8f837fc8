"""camdirector._native.move_scene (native/src/move_scene_py.rs): a frame's decoded rows put in a
Scene in one call, against its reference, Scene.set_transform of each moving object's
RigidTransform made of the same row (what the compiled rig did before, and still does for an
object moved otherwise): the same answers to the same bits, on the demo scene's obstacles moved
through their tracks with the targets' rows among theirs, and every refusal."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector._native import Scene, move_scene
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.transforms import RigidTransform

FRAMES = 30  # demo scene moments, 0.4 s apart
SEGMENTS_PER_FRAME = 256


def _row(transform: RigidTransform) -> list[float]:
    return [*transform.position_world, *transform.rotation_xyzw, *transform.scale]


def test_rows_move_the_scene_as_each_objects_transform_does():
    demo = build_demo_scene(3, duration_s=FRAMES * 0.4 + 1.0)
    static = [TriMesh(o.transform.apply(o.vertices), o.faces) for o in demo.static_objects]
    reference, batched = Scene(static), Scene(static)
    for o in demo.dynamic_objects:
        for scene in (reference, batched):
            scene.add_dynamic(o.id, TriMesh(o.vertices, o.faces), o.transform)
    rng = np.random.default_rng(5)
    for k in range(FRAMES):
        # the rows as the decoder gives them: the avatar's (a target, not in the Scene) among the obstacles', shuffled
        moved = list(demo.transforms_at(0.4 * k).items())
        ids, transforms = zip(*(moved[i] for i in rng.permutation(len(moved))))
        rows = np.array([_row(tf) for tf in transforms])
        made = [RigidTransform(r[0:3], r[3:7], r[7:10]) for r in rows]  # codec.frame_from_wire's
        obstacles = [object_id for object_id in ids if object_id != demo.avatar.id]
        for object_id, transform in zip(ids, made):
            if object_id != demo.avatar.id:
                reference.set_transform(object_id, transform)
        assert move_scene(batched, list(ids), rows) == obstacles
        x_m, z_m = demo.avatar_position_xz(0.4 * k)
        origins = rng.uniform(-15.0, 15.0, (SEGMENTS_PER_FRAME, 3))
        targets = np.array([x_m, 1.0, z_m]) + rng.uniform(-1.0, 1.0, (SEGMENTS_PER_FRAME, 3))
        occluded = reference.occluded(origins, targets)
        assert 0 < occluded.sum() < SEGMENTS_PER_FRAME  # the obstacles and columns are in some segments' way
        np.testing.assert_array_equal(batched.occluded(origins, targets), occluded)
        directions = targets - origins
        np.testing.assert_array_equal(batched.first_hit(origins, directions), reference.first_hit(origins, directions))


def test_a_later_row_of_the_same_object_wins_and_unknown_ids_are_passed_over():
    reference, batched = Scene([]), Scene([])
    for scene in (reference, batched):
        scene.add_dynamic("cube", box((1.0, 1.0, 1.0)), RigidTransform())
    first, last = RigidTransform(np.array([0.0, 0.0, 3.0])), RigidTransform(np.array([2.0, 0.0, 0.0]), scale=np.full(3, 2.0))
    reference.set_transform("cube", last)
    assert move_scene(batched, ["cube", "target", "cube"], np.array([_row(first), _row(first), _row(last)])) == ["cube", "cube"]
    origins, targets = np.array([[2.0, 0.0, 10.0], [0.0, 0.0, 10.0]]), np.array([[2.0, 0.0, -10.0], [0.0, 0.0, -10.0]])
    np.testing.assert_array_equal(batched.first_hit(origins, targets - origins), reference.first_hit(origins, targets - origins))
    np.testing.assert_array_equal(batched.occluded(origins, targets), [True, False])


_MOVED_AWAY = [5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]  # a good row first: refused rows move nothing, not even it


@pytest.mark.parametrize(
    ("ids", "rows", "message"),
    [
        (["cube"], np.zeros((1, 9)), "rows must be"),
        (["cube", "cube"], np.array([_MOVED_AWAY]), "rows must be"),
        (["cube", "cube"], np.array([_MOVED_AWAY, [0.0, np.nan, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]]), "finite"),
        (["cube", "cube"], np.array([_MOVED_AWAY, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0]]), "zero scale"),
    ],
)
def test_refusals_move_nothing(ids, rows, message):
    scene = Scene([])
    scene.add_dynamic("cube", box((1.0, 1.0, 1.0)), RigidTransform())
    with pytest.raises(ValueError, match=message):
        move_scene(scene, ids, rows)
    np.testing.assert_array_equal(scene.occluded(np.array([[0.0, 0.0, 10.0]]), np.array([[0.0, 0.0, -10.0]])), [True])
