"""Sample points on the targets (pipeline/toric/target_sampling.py): uniform over the area, on the surface,
reproducible from the seed, re-drawn slot by slot."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.geometry.meshes import TriMesh, box, sphere
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.toric.target_sampling import SurfaceSampler, TargetSampler, TargetSamplingSettings

SIZE = np.array([1.0, 2.0, 4.0])  # a box whose face pairs have areas 8 : 4 : 2 (normal x : y : z)


def test_points_are_uniform_over_the_area():
    points = SurfaceSampler(box(SIZE)).sample(40_000, np.random.default_rng(0))
    on_face = np.isclose(np.abs(points), SIZE / 2.0, atol=1e-9)  # (n, 3): which face
    assert np.all(on_face.sum(axis=1) >= 1)  # on the surface
    share = on_face.mean(axis=0)
    np.testing.assert_allclose(share, np.array([8.0, 4.0, 2.0]) / 14.0, atol=0.01)
    # Within a face: uniform, so each half of the big +-x faces gets half of their points.
    big = points[on_face[:, 0]]
    assert abs(np.mean(big[:, 2] > 0.0) - 0.5) < 0.02 and abs(np.mean(big[:, 1] > 0.0) - 0.5) < 0.02


def test_points_are_uniform_inside_a_triangle():
    triangle = TriMesh(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.array([[0, 1, 2]], np.int32))
    p = SurfaceSampler(triangle).sample(40_000, np.random.default_rng(1))
    assert np.all(p[:, 0] >= 0) and np.all(p[:, 1] >= 0) and np.all(p[:, 0] + p[:, 1] <= 1 + 1e-12)
    assert abs(np.mean(p[:, 0] < 0.5) - 0.75) < 0.01  # area share of x < 1/2
    np.testing.assert_allclose(p.mean(axis=0), [1 / 3, 1 / 3, 0.0], atol=0.01)


def test_the_same_seed_gives_the_same_points():
    meshes = [sphere(0.5), box(SIZE)]
    a = TargetSampler(meshes, np.random.default_rng(42))
    b = TargetSampler(meshes, np.random.default_rng(42))
    c = TargetSampler(meshes, np.random.default_rng(43))
    np.testing.assert_array_equal(a.points_local, b.points_local)
    assert not np.allclose(a.points_local, c.points_local)
    rng_a, rng_b = np.random.default_rng(9), np.random.default_rng(9)
    a.redraw([1, 7], rng_a)
    b.redraw([1, 7], rng_b)
    np.testing.assert_array_equal(a.points_local, b.points_local)


def test_slots_are_numbered_per_target_and_redrawn_one_by_one():
    sampler = TargetSampler([sphere(0.5), box(SIZE)], np.random.default_rng(0), TargetSamplingSettings(samples_per_target=5))
    assert sampler.slot_count == 10 and [sampler.target_of(s) for s in (0, 4, 5, 9)] == [0, 0, 1, 1]
    radius = np.linalg.norm(sampler.points_local[:5], axis=1)
    assert np.all(radius <= 0.5 + 1e-9) and np.all(radius > 0.45)  # on the sphere's surface
    assert np.all(np.isclose(np.abs(sampler.points_local[5:]), SIZE / 2.0).any(axis=1))
    before = sampler.points_local.copy()
    sampler.redraw([2, 6], np.random.default_rng(1))
    changed = np.any(sampler.points_local != before, axis=1)
    assert changed.tolist() == [i in (2, 6) for i in range(10)]
    with pytest.raises(ValueError):
        sampler.target_of(10)


def test_a_redraw_is_a_one_point_sample_per_slot_in_order_from_one_draw():
    """redraw draws each slot's face, u and v at once, as sample(1) drew them one call at a time:
    the same points, bit for bit, and the generator left where those calls left it."""
    meshes = [sphere(0.5), box(SIZE)]
    one_call, one_by_one = TargetSampler(meshes, np.random.default_rng(1)), TargetSampler(meshes, np.random.default_rng(1))
    rng_a, rng_b = np.random.default_rng(9), np.random.default_rng(9)
    for slots in ([0, 5], [3], list(range(10)), [9, 2]):
        one_call.redraw(slots, rng_a)
        for slot in slots:
            one_by_one.points_local[slot] = one_by_one._samplers[one_by_one.target_of(slot)].sample(1, rng_b)[0]
        assert one_call.points_local.tobytes() == one_by_one.points_local.tobytes()
    assert rng_a.random() == rng_b.random()


def test_points_follow_the_targets_transforms():
    sampler = TargetSampler([box(SIZE)], np.random.default_rng(3))
    quarter_turn_y = np.array([0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)])
    transform = RigidTransform(position_world=np.array([10.0, 0.0, -2.0]), rotation_xyzw=quarter_turn_y)
    world = sampler.points_world([transform])
    np.testing.assert_allclose(world, transform.apply(sampler.points_local), atol=1e-12)
    np.testing.assert_allclose(sampler.points_world([transform], [3, 0]), world[[3, 0]])
    with pytest.raises(ValueError):
        sampler.points_world([transform, transform])


def test_bad_targets_are_refused():
    with pytest.raises(ValueError):
        TargetSampler([box(SIZE)] * 3, np.random.default_rng(0))
    flat = TriMesh(np.zeros((3, 3)), np.array([[0, 1, 2]], np.int32))
    with pytest.raises(ValueError):
        SurfaceSampler(flat)
    with pytest.raises(ValueError):
        TargetSamplingSettings(samples_per_target=0)
