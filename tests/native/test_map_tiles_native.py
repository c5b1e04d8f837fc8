"""The compiled maps' rays culled a tile of texels at a time (native/src/maps.rs, bvh.rs `Bundle`):
over scenes built to graze (a ground plane and a wall through the sample points), dense random
boxes and cylinders, moving, turned and scaled objects, targets ignoring their own object, tori
moving and still, and on two real levels, the maps are the bits the segment-by-segment casts gave
before the cull (digests taken from that code), whatever the number of threads."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import TriMesh, box, cylinder, sphere
from camdirector.geometry.toric import composition_angle, make_torus
from camdirector.geometry.toric_maps import MapWindow, OccluderScene, WindowSettings, make_backend
from camdirector.geometry.toric_maps.native import share_texels
from camdirector.geometry.transforms import RigidTransform
from camdirector.precompute.tracks.level_mesh import load_level_mesh

#: sha256 of every map below, computed segment by segment, each from its own BVH walk (the code
#: before the tiles' cull, e5dbf3f).
SEGMENT_BY_SEGMENT_SHA256 = "827479ca8f8f08ed71112844a5eedb3d275d23840c9d3b8c584719ba3cca45cd"
#: the same for maps on two of ../shared/data's levels (_level_cases)
LEVEL_SHA256 = {
    "recast/dungeon.obj": "8a28f15a3813fabe5fde056c8f2c58f62d67722cf52460205b4d941984410e51",
    "sauerbraten/zdm2.obj": "d36e6d7057b61d5d1984c2314bca8a458567271289462722949b956939c05cf7",
}
LEVEL_TARGETS = 12


def _moved(mesh: TriMesh, offset) -> TriMesh:
    return TriMesh(mesh.vertices + np.asarray(offset, dtype=np.float64), mesh.faces)


def _quad(corner, u, v) -> TriMesh:
    """The parallelogram corner + [0, 1] u + [0, 1] v, two triangles."""
    c, u, v = (np.asarray(x, dtype=np.float64) for x in (corner, u, v))
    return TriMesh(np.array([c, c + u, c + u + v, c + v]), np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64))


def _quat(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def _cases():
    """(scene, torus, window, sample points, exclude ids, previous torus, dt_s) for each map call."""
    rng = np.random.default_rng(43)
    alpha = composition_angle((-1.0 / 3.0, 0.0), (1.0 / 3.0, 0.0), Lens())
    for k in range(8):
        sparse = k >= 6  # no ground or wall, few objects: most tiles meet nothing
        a = np.array([rng.uniform(-3, 3), 1.0 if k % 2 == 0 else rng.uniform(0.5, 2.0), rng.uniform(-3, 3)])
        b = a + np.array([rng.uniform(1.5, 4.0), rng.uniform(-0.3, 0.3), rng.uniform(-2.0, 2.0)])
        torus = make_torus(a, b, alpha)
        statics = (
            []
            if sparse
            else [
                # the ground through the sample point a (k even): segments start on its plane
                _quad([a[0] - 20.0, a[1] if k % 2 == 0 else 0.0, a[2] - 20.0], [40.0, 0.0, 0.0], [0.0, 0.0, 40.0]),
                # a wall whose plane holds a, and so some segments
                _quad([a[0], a[1] - 3.0, a[2] - 6.0], [0.0, 6.0, 0.0], [0.0, 0.0, 12.0]),
            ]
        )
        for _ in range(3 if sparse else 10 + 15 * k):
            size = rng.uniform(0.05, 1.2, 3)
            where = a + rng.normal(scale=2.5, size=3) + [0.0, 1.0, 0.0]
            statics.append(_moved(box(size) if rng.random() < 0.7 else cylinder(size[0], size[1] * 3), where))
        scene = OccluderScene(statics)
        for i in range(2 if sparse else 4 + 2 * k):
            mesh = box(rng.uniform(0.1, 0.8, 3)) if i % 3 else sphere(rng.uniform(0.1, 0.5))
            pose = RigidTransform(
                position_world=a + rng.normal(scale=2.0, size=3) + [0.0, 1.0, 0.0],
                rotation_xyzw=_quat(rng),
                scale=rng.uniform(0.5, 1.5, 3),
            )
            scene.add_dynamic(
                f"mover{i}",
                mesh,
                pose,
                linear_velocity_m_s=rng.normal(size=3),
                angular_velocity_rad_s=rng.normal(size=3),
            )
        scene.add_dynamic("target", sphere(0.3), RigidTransform(position_world=a.copy()), linear_velocity_m_s=(0.5, 0.0, 0.2))
        points = a + np.array([[0.0, 0.0, 0.0], [0.1, 0.25, 0.05], [-0.12, -0.2, 0.1]])
        if k % 2 == 0:
            points[1, 1] = a[1]  # on the ground plane too
        owners = ["target", "target", None]
        for theta, phi in ((1.8, 1.2), (math.pi / 2, 0.0), (0.6, -2.5)):
            for resolution in (64, 37):
                window = MapWindow.around(torus, theta, phi, WindowSettings(resolution=resolution))
                moved = make_torus(a - [0.2, 0.05, 0.0], b - [0.2, 0.0, 0.1], alpha)
                yield scene, torus, window, points, owners, (moved if resolution == 64 else None), 0.1


def _level_cases(mesh: TriMesh):
    """The maps of targets a metre above random points of a level's triangles (some in its walls,
    some in the open), the level static, a moving crate beside the first target."""
    rng = np.random.default_rng(7)
    alpha = composition_angle((-1.0 / 3.0, 0.0), (1.0 / 3.0, 0.0), Lens())
    scene = OccluderScene([mesh])
    scene.add_dynamic("crate", box((0.8, 0.8, 0.8)), RigidTransform(), linear_velocity_m_s=(1.0, 0.0, 0.0))
    triangles = mesh.vertices[mesh.faces]
    for face in rng.choice(len(mesh.faces), LEVEL_TARGETS, replace=False):
        a = triangles[face].mean(axis=0) + [0.0, 1.0, 0.0]
        b = a + np.array([rng.uniform(-4.0, 4.0), rng.uniform(-0.5, 0.5), rng.uniform(-4.0, 4.0)])
        crate = RigidTransform(position_world=a + rng.normal(scale=1.5, size=3), rotation_xyzw=_quat(rng))
        scene.set_motions(["crate"], [crate], [(1.0, 0.0, 0.0)], [(0.0, 0.5, 0.0)])
        torus = make_torus(a, b, alpha)
        window = MapWindow.around(torus, rng.uniform(0.3, 2.8), rng.uniform(-math.pi, math.pi), WindowSettings(resolution=64))
        points = np.array([a, b, a + [0.0, 0.3, 0.0]])
        yield scene, torus, window, points, [None, None, None], make_torus(a - [0.1, 0.0, 0.05], b, alpha), 0.05


def _digest(cases, threads: int) -> str:
    digest = hashlib.sha256()
    backends = {}
    try:
        share_texels(threads)
        for scene, torus, window, points, owners, before, dt_s in cases:
            backend = backends.setdefault(id(scene), make_backend("native", scene))
            maps = backend.compute(torus, window, points, exclude_ids=owners, previous_torus=before, dt_s=dt_s if before else 0.0)
            for array in (maps.shadow, maps.velocity_rad_s, maps.depth_m):
                digest.update(np.ascontiguousarray(array).tobytes())
    finally:
        share_texels(1)
    return digest.hexdigest()


@pytest.mark.parametrize("threads", [1, 3])
def test_the_tiles_give_the_segment_by_segment_bits(threads):
    assert _digest(_cases(), threads) == SEGMENT_BY_SEGMENT_SHA256


@pytest.mark.parametrize("level", sorted(LEVEL_SHA256))
def test_the_tiles_give_the_segment_by_segment_bits_on_the_levels(shared_data, level):
    mesh = load_level_mesh(shared_data / "levels" / level)
    assert _digest(_level_cases(mesh), 2) == LEVEL_SHA256[level]


if __name__ == "__main__":  # prints the digests of this build, for a change that means to alter the maps
    import sys

    print(_digest(_cases(), 1))
    for level in sorted(LEVEL_SHA256):
        print(level, _digest(_level_cases(load_level_mesh(Path(sys.argv[1]) / "levels" / level)), 1))
