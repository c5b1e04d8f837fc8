"""camdirector._native.Bvh (native/src/bvh.rs) against a loop over every triangle with the same
watertight test: the tree (its shape, the wide nodes' layout, the boxes' padding, the traversal's
order) must change no bit of any answer, on the hard rays above all: through shared edges and
vertices, along an axis, with zero (and negative zero) direction components, from a face.

`_every_triangle` is bvh.rs's Ray::new and Ray::hits over all the triangles at once in numpy:
the same float64 operations in the same order, each rounded once (numpy never fuses a multiply
and an add), so its bits are the BVH's wherever the BVH visits the right triangles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from camdirector._native import Bvh
from camdirector.geometry.meshes import TriMesh, box
from camdirector.precompute.tracks.level_mesh import load_level_mesh

LEVELS = ("recast/nav_test.obj", "recast/dungeon.obj", "recast/undulating.obj", "sauerbraten/zdm2.obj")
RAYS_PER_KIND = 150  # per level and kind of ray: each costs a pass over every triangle in numpy
GRID_STEP_M = 0.5  # the hand-built floor's and wall's squares (exact in binary, so ties are exact)


def _every_triangle(
    triangles: npt.NDArray[np.float64], origin: npt.NDArray[np.float64], direction: npt.NDArray[np.float64], t_max: float
) -> float:
    """The least t with 0 <= t <= t_max at which Woop et al.'s watertight test meets one of
    `triangles` (m, 3, 3), as bvh.rs computes it; inf where none."""
    magnitude = np.abs(direction)
    kz = 0 if magnitude[0] >= magnitude[1] and magnitude[0] >= magnitude[2] else 1 if magnitude[1] >= magnitude[2] else 2
    if direction[kz] == 0.0:
        return np.inf
    kx, ky = (kz + 1) % 3, (kz + 2) % 3
    if direction[kz] < 0.0:
        kx, ky = ky, kx
    sx, sy, sz = direction[kx] / direction[kz], direction[ky] / direction[kz], 1.0 / direction[kz]
    x, y, z = (triangles[:, :, k] - origin[k] for k in (kx, ky, kz))  # (m, 3) each, vertex by vertex
    x, y, z = x - sx * z, y - sy * z, sz * z
    (ax, bx, cx), (ay, by, cy), (az, bz, cz) = x.T, y.T, z.T
    u, v, w = cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax
    outside = ((u < 0.0) | (v < 0.0) | (w < 0.0)) & ((u > 0.0) | (v > 0.0) | (w > 0.0))
    det = u + v + w
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (u * az + v * bz + w * cz) / det + 0.0
    met = t[~outside & (det != 0.0) & (t >= 0.0) & (t <= t_max)]
    return float(met.min()) if len(met) else np.inf


def _assert_same_bits(mesh: TriMesh, origins: npt.NDArray[np.float64], directions: npt.NDArray[np.float64]) -> None:
    """first_hit along each ray (unbounded, and within a bound), and occluded on the segment to o +
    d, equal the loop's to the bit."""
    bvh = Bvh(mesh.vertices, mesh.faces)
    triangles = mesh.vertices[mesh.faces]
    t = bvh.first_hit(origins, directions)
    expected = np.array([_every_triangle(triangles, o, d, np.inf) for o, d in zip(origins, directions)])
    wrong = np.flatnonzero(t.view(np.int64) != expected.view(np.int64))
    assert wrong.size == 0, (
        f"first_hit differs on {wrong.size} of {len(t)} rays, first {wrong[:5]}: {t[wrong[:5]]} != {expected[wrong[:5]]}"
    )
    for t_max in (0.5, 2.0 / 3.0, 1.0):  # bounded, as the maps cast: a hit at exactly t_max counts
        bounded = bvh.first_hit(origins, directions, t_max)
        expected_bounded = np.where(expected <= t_max, expected, np.inf)
        wrong = np.flatnonzero(bounded.view(np.int64) != expected_bounded.view(np.int64))
        assert wrong.size == 0, f"first_hit within {t_max} differs on {wrong.size} of {len(t)} rays, first {wrong[:5]}"
    targets = origins + directions
    occluded = bvh.occluded(origins, targets)
    expected_occluded = np.array(
        [np.isfinite(_every_triangle(triangles, o, e - o, Bvh.SEGMENT_END)) for o, e in zip(origins, targets)]
    )
    np.testing.assert_array_equal(occluded, expected_occluded)
    assert np.isfinite(t).any() and occluded.any()  # the sample means something


def _grid_scene() -> TriMesh:
    """A floor of 12 x 12 squares at z = 0 and a wall of 12 x 6 at x = 3 (each square two
    triangles, so every inner vertex is shared by six and every inner edge by two), and two boxes
    on the floor, one against the wall: enough triangles for a tree of several levels."""
    n = 12
    grid = np.arange(n + 1) * GRID_STEP_M
    gx, gy = np.meshgrid(grid, grid, indexing="ij")
    floor = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    wall = np.stack([np.full(gx.size, 3.0), gx.ravel(), gy.ravel() * 0.5], axis=1)
    corner = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    squares = np.concatenate(
        [np.stack([corner, corner + n + 1, corner + n + 2], axis=1), np.stack([corner, corner + n + 2, corner + 1], axis=1)]
    )
    meshes = [TriMesh(floor, squares), TriMesh(wall, squares), box((1.0, 1.0, 1.0)), box((0.5, 2.0, 1.5))]
    offsets = [0.0, 0.0, np.array([1.5, 1.5, 0.5]), np.array([2.75, 4.0, 0.75])]
    vertices = np.concatenate([m.vertices + o for m, o in zip(meshes, offsets)])
    starts = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return TriMesh(vertices, np.concatenate([m.faces + s for m, s in zip(meshes, starts)]).astype(np.int32))


def test_rays_through_shared_edges_and_vertices_match_every_triangle():
    mesh = _grid_scene()
    rng = np.random.default_rng(5)
    points = np.arange(25) * GRID_STEP_M / 2.0  # grid lines and the middles between them
    px, py = (a.ravel() for a in np.meshgrid(points, points, indexing="ij"))
    on_floor = np.stack([px, py, np.zeros_like(px)], axis=1)  # vertices, edge middles, square middles
    down = np.tile([0.0, 0.0, -2.0], (len(px), 1))
    slanted = on_floor + rng.uniform(-3.0, 3.0, on_floor.shape) * [1.0, 1.0, 0.0] + [0.0, 0.0, 1.5]
    origins = np.concatenate([on_floor + [0.0, 0.0, 1.0], slanted])
    directions = np.concatenate([down, (on_floor - slanted) * 1.5])  # each meets the floor at t = 0.5 or 2/3
    _assert_same_bits(mesh, origins, directions)


def test_axis_parallel_and_zero_components_match_every_triangle():
    mesh = _grid_scene()
    lines = np.arange(13) * GRID_STEP_M
    count = len(lines)
    # along the floor's grid lines in its plane (parallel to those faces: det 0), and a grid step above
    along_x = np.stack([np.full(count, -1.0), lines, np.zeros(count)], axis=1)
    along_y = np.stack([lines, np.full(count, -1.0), np.full(count, GRID_STEP_M)], axis=1)
    origins = np.concatenate([along_x, along_y, along_x + [8.0, 0.0, 0.0]])
    directions = np.concatenate(
        [
            np.tile([10.0, 0.0, 0.0], (count, 1)),  # across the wall at x = 3
            np.tile([-0.0, 10.0, -0.0], (count, 1)),  # negative zeros: the slabs' other side
            np.tile([-10.0, 0.0, -0.0], (count, 1)),  # back towards the wall from beyond it
        ]
    )
    # vertical rays on the wall's plane and through the boxes' edges, and no direction at all
    vertical = np.array([[3.0, 1.0, 5.0], [1.0, 1.0, 5.0], [2.0, 2.0, 5.0], [2.5, 3.0, 5.0], [2.0, 1.0, -1.0]])
    origins = np.concatenate([origins, vertical, [[1.0, 1.0, 1.0]]])
    directions = np.concatenate([directions, np.tile([0.0, 0.0, -1.0], (4, 1)), [[0.0, 0.0, 1.0]], [[0.0, 0.0, 0.0]]])
    _assert_same_bits(mesh, origins, directions)


def test_rays_from_a_face_match_every_triangle():
    """From points of the floor, of its edges and vertices, and of the boxes' faces: t = 0 there
    (or a later face for a ray leaving along the face's own plane: det 0)."""
    mesh = _grid_scene()
    rng = np.random.default_rng(9)
    on_floor = np.concatenate([rng.uniform(0.0, 6.0, (60, 2)), rng.integers(0, 13, (30, 2)) * GRID_STEP_M], axis=0)
    origins = np.concatenate(
        [np.column_stack([on_floor, np.zeros(len(on_floor))]), [[1.5, 1.5, 1.0], [1.0, 1.2, 0.5], [2.5, 4.0, 1.5]]]
    )
    directions = rng.normal(size=origins.shape)
    directions[:10, 2] = 0.0  # along the floor
    _assert_same_bits(mesh, origins, directions)


def _level_rays(mesh: TriMesh, rng: np.random.Generator) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Origins and directions (4 RAYS_PER_KIND, 3): random, aimed at points of triangle edges
    (vertices a third of them), axis-parallel from a vertex's coordinates, and from points of faces."""
    n = RAYS_PER_KIND
    low, high = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    triangles = mesh.vertices[mesh.faces]
    faces = rng.integers(0, mesh.triangle_count, (2, n))
    random_origins = rng.uniform(low, high, (2, n, 3))
    corner = rng.integers(0, 3, n)
    share = np.where(rng.uniform(size=(n, 1)) < 1.0 / 3.0, 1.0, rng.uniform(size=(n, 1)))
    aims = triangles[faces[0], corner] * share + triangles[faces[0], (corner + 1) % 3] * (1.0 - share)
    axis = rng.integers(0, 3, n)
    along = np.zeros((n, 3))
    along[np.arange(n), axis] = rng.choice([-1.0, 1.0], n) * (high - low)[axis]
    vertex = mesh.vertices[rng.integers(0, len(mesh.vertices), n)]
    axis_origins = np.where(np.arange(3) == axis[:, None], random_origins[1], vertex)  # on a vertex's line
    weights = rng.dirichlet(np.ones(3), n)
    on_face = (triangles[faces[1]] * weights[:, :, None]).sum(axis=1)
    origins = np.concatenate([random_origins[0], random_origins[1], axis_origins, on_face])
    directions = np.concatenate([rng.normal(size=(n, 3)), aims - random_origins[1], along, rng.normal(size=(n, 3))])
    return origins, directions


@pytest.mark.shared_data
@pytest.mark.parametrize("name", LEVELS, ids=lambda name: Path(name).stem)
def test_rays_on_the_levels_match_every_triangle(shared_data, name):
    mesh = load_level_mesh(shared_data / "levels" / name)
    origins, directions = _level_rays(mesh, np.random.default_rng(43))
    _assert_same_bits(mesh, origins, directions)
