"""The map backends (GL deferred projection, Embree ray casting, compiled ray casting) held against
Embree on small hand-built scenes, plus outcomes checked by hand, the window they share, and the
backend rule. The compiled backend casts the rays Embree casts, in float64 instead of float32: it
agrees with Embree but within rounding of an edge, and gives the same bits every time."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import TriMesh, box, cylinder, sphere
from camdirector.geometry.toric import composition_angle, make_torus, torus_position
from camdirector.geometry.toric_maps import (
    GL_MAX_TRIANGLES_ON_CPU,
    MapWindow,
    OccluderScene,
    WindowSettings,
    choose_backend,
    make_backend,
)
from camdirector.geometry.toric_maps.base import texture_velocity, torus_points, torus_tangents
from camdirector.geometry.toric_maps.embree import EmbreeMapBackend, EmbreeMapSettings
from camdirector.geometry.toric_maps.native import share_texels
from camdirector.geometry.transforms import RigidTransform

RES = 64
ALPHA = composition_angle((-1.0 / 3.0, 0.0), (1.0 / 3.0, 0.0), Lens())
A_WORLD = np.array([0.0, 1.0, 0.0])
B_WORLD = np.array([2.5, 1.0, 0.0])  # A -> B along +X
TORUS = make_torus(A_WORLD, B_WORLD, ALPHA)
THETA, PHI = 1.8, 1.2  # camera behind and above A, on the +Z side
WINDOW = MapWindow.around(TORUS, THETA, PHI, WindowSettings(resolution=RES))
CAMERA = torus_position(TORUS, THETA, PHI)
SAMPLES_A = A_WORLD + np.array([[0.0, 0.0, 0.0], [0.1, 0.2, 0.05], [-0.1, -0.15, 0.1]])


def _moved(mesh: TriMesh, offset) -> TriMesh:
    return TriMesh(mesh.vertices + np.asarray(offset, dtype=np.float64), mesh.faces)


def _toward_camera(fraction: float) -> np.ndarray:
    """The point this fraction of the way from A to the camera."""
    return A_WORLD + fraction * (CAMERA - A_WORLD)


@pytest.fixture(params=["gl", "native"])
def pair(request):
    """make(scene) -> (embree backend, the other backend) on that scene; closed afterwards."""
    made = []

    def make(scene: OccluderScene):
        backends = (EmbreeMapBackend(scene), make_backend(request.param, scene))
        made.extend(backends)
        return backends

    yield make
    for backend in made:
        backend.close()


def _both(make, scene, points=SAMPLES_A, torus=TORUS, window=WINDOW, **kwargs):
    embree, gl = make(scene)
    return (embree.compute(torus, window, points, **kwargs), gl.compute(torus, window, points, **kwargs))


def _assert_agree(ray, gl, shadow_share=0.97, direction_share=0.95):
    assert ray.shadow.shape == gl.shadow.shape
    assert np.mean(ray.shadow == gl.shadow) >= shadow_share
    both = (ray.shadow > 0) & (gl.shadow > 0)
    v_ray, v_gl = ray.velocity_rad_s[both], gl.velocity_rad_s[both]
    moving = np.linalg.norm(v_ray, axis=-1) > 1e-3
    if moving.sum() > 10:
        cos = np.einsum("ij,ij->i", v_ray[moving], v_gl[moving]) / (
            np.linalg.norm(v_ray[moving], axis=-1) * np.linalg.norm(v_gl[moving], axis=-1) + 1e-12
        )
        assert np.mean(cos > 0.9) >= direction_share
    if both.sum() > 10:  # the same occluder at the same distance, save along silhouettes
        assert np.median(np.abs(ray.depth_m[both] / gl.depth_m[both] - 1.0)) < 1e-2


# -- hand-checked outcomes, both backends ---------------------------------------------------------


def test_empty_scene_gives_empty_maps(pair):
    for maps in _both(pair, OccluderScene()):
        assert maps.shadow.shape == (3, RES, RES) and maps.shadow.dtype == np.float32
        assert maps.velocity_rad_s.shape == (3, RES, RES, 2)
        assert not maps.shadow.any() and not maps.velocity_rad_s.any()
        assert np.all(np.isinf(maps.depth_m))


def test_wall_between_target_and_window_shadows_every_texel(pair):
    normal = (CAMERA - A_WORLD) / np.linalg.norm(CAMERA - A_WORLD)
    nearest = float(((torus_points(TORUS, WINDOW) - A_WORLD) @ normal).min())
    assert nearest > 1.0  # the whole window lies beyond the wall built below
    side = np.cross(normal, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    frame = np.stack([side, np.cross(normal, side), normal], axis=1)  # local z -> normal
    slab = box((200.0, 200.0, 0.05))
    wall = TriMesh(slab.vertices @ frame.T + A_WORLD + 0.5 * nearest * normal, slab.faces)
    ray, gl = _both(pair, OccluderScene([wall]))
    for maps in (ray, gl):
        assert maps.shadow.all()
        assert not maps.velocity_rad_s.any()  # a still wall in front of a still torus
        rays = torus_points(TORUS, WINDOW) - SAMPLES_A[0]
        face_m = 0.5 * nearest - 0.025  # the slab's near face
        expected = face_m * np.linalg.norm(rays, axis=-1) / (rays @ normal)
        # GL reads the depth at the nearest occluder-map pixel: exact up to the slope over half a pixel.
        np.testing.assert_allclose(maps.depth_m[0], expected, rtol=1e-3 if maps is ray else 1e-2)


def test_pillar_partly_covering_the_window(pair):
    pillar = _moved(cylinder(0.25, 6.0), _toward_camera(0.4))
    ray, gl = _both(pair, OccluderScene([pillar]))
    assert 0.02 < ray.shadow.mean() < 0.9
    _assert_agree(ray, gl)


def test_box_moving_plus_x_moves_its_shadow_toward_b(pair):
    """+X is the A -> B direction: phi turns about the A-B axis, so the shadow has no phi rate; theta
    grows toward B wherever the arc heads toward B (beyond its apex, theta > pi/2 - alpha)."""
    scene = OccluderScene()
    scene.add_dynamic(
        "crate", box((0.6, 0.6, 0.6)), RigidTransform(position_world=_toward_camera(0.35)), linear_velocity_m_s=(2.0, 0.0, 0.0)
    )
    ray, gl = _both(pair, scene)
    assert ray.shadow.mean() > 0.02
    _assert_agree(ray, gl)
    d_theta, d_phi = torus_tangents(TORUS, WINDOW)
    expected = texture_velocity(np.array([2.0, 0.0, 0.0]), d_theta, d_phi)  # (res, res, 2)
    for maps in (ray, gl):
        hit = maps.shadow > 0
        v = maps.velocity_rad_s[hit]
        e = np.broadcast_to(expected, maps.velocity_rad_s.shape)[hit]
        np.testing.assert_allclose(v, e, rtol=1e-3, atol=1e-5)
        past_apex = np.broadcast_to(WINDOW.grid()[0] > math.pi / 2 - ALPHA, hit.shape)[hit]
        assert past_apex.sum() > 100 and np.all(v[past_apex, 0] > 0.0)
        assert np.all(np.abs(v[:, 1]) < 1e-5)


def test_spinning_object_agrees_in_direction(pair):
    scene = OccluderScene()
    scene.add_dynamic(
        "door",
        box((1.2, 1.5, 0.1)),
        RigidTransform(position_world=_toward_camera(0.45)),
        linear_velocity_m_s=(0.0, 0.3, 0.0),
        angular_velocity_rad_s=(0.0, 3.0, 0.0),
    )
    ray, gl = _both(pair, scene)
    assert ray.shadow.mean() > 0.02
    _assert_agree(ray, gl)


def test_two_targets_each_ignoring_itself(pair):
    """Camera beyond B: B hides part of the window from A's points; A hides nothing from B's."""
    theta, phi = 4.4, 1.2
    window = MapWindow.around(TORUS, theta, phi, WindowSettings(resolution=RES))
    scene = OccluderScene()
    scene.add_dynamic("a", sphere(0.4), RigidTransform(position_world=A_WORLD.copy()))
    scene.add_dynamic("b", sphere(0.4), RigidTransform(position_world=B_WORLD.copy()))
    points = np.concatenate([SAMPLES_A[:2], B_WORLD + (SAMPLES_A[:2] - A_WORLD)])
    owners = ["a", "a", "b", "b"]
    ray, gl = _both(pair, scene, points=points, window=window, exclude_ids=owners)
    _assert_agree(ray, gl)
    for maps in (ray, gl):
        assert 0.02 < maps.shadow[:2].mean() < 0.9
        assert not maps.shadow[2:].any()
    # Without the exclusion a point inside its own sphere is hidden from every torus point outside it.
    outside = np.linalg.norm(torus_points(TORUS, window) - B_WORLD, axis=-1) > 0.45
    assert 0 < outside.sum() < RES * RES  # the window's last row runs inside B's sphere
    for maps in _both(pair, scene, points=points, window=window):
        assert maps.shadow[0].all() and maps.shadow[2][outside].all()


def test_moving_torus_makes_still_occluders_move_back(pair):
    """The V-map is relative to the torus (section 4.1.2): targets moving +X at 2 m/s carry every torus
    point at 2 m/s +X, so a still pillar moves at -2 m/s +X relative to it (-theta past the apex)."""
    pillar = _moved(cylinder(0.25, 6.0), _toward_camera(0.4))
    before = make_torus(A_WORLD - [0.2, 0.0, 0.0], B_WORLD - [0.2, 0.0, 0.0], ALPHA)
    ray, gl = _both(pair, OccluderScene([pillar]), previous_torus=before, dt_s=0.1)
    _assert_agree(ray, gl)
    d_theta, d_phi = torus_tangents(TORUS, WINDOW)
    expected = texture_velocity(np.array([-2.0, 0.0, 0.0]), d_theta, d_phi)
    for maps in (ray, gl):
        hit = maps.shadow > 0
        np.testing.assert_allclose(
            maps.velocity_rad_s[hit], np.broadcast_to(expected, maps.velocity_rad_s.shape)[hit], rtol=1e-3, atol=1e-4
        )
        past_apex = np.broadcast_to(WINDOW.grid()[0] > math.pi / 2 - ALPHA, hit.shape)[hit]
        assert past_apex.sum() > 100 and np.all(maps.velocity_rad_s[hit][past_apex, 0] < 0.0)


def test_scene_changes_are_picked_up(pair):
    scene = OccluderScene()
    embree, gl = pair(scene)
    for backend in (embree, gl):
        assert not backend.compute(TORUS, WINDOW, SAMPLES_A[:1]).shadow.any()
    scene.add_dynamic("crate", box((0.6, 0.6, 0.6)), RigidTransform(position_world=_toward_camera(0.35)))
    first = [b.compute(TORUS, WINDOW, SAMPLES_A[:1]).shadow.mean() for b in (embree, gl)]
    scene.set_motion("crate", RigidTransform(position_world=_toward_camera(0.35) + [0.0, 5.0, 0.0]))
    moved = [b.compute(TORUS, WINDOW, SAMPLES_A[:1]).shadow.mean() for b in (embree, gl)]
    scene.remove_dynamic("crate")
    gone = [b.compute(TORUS, WINDOW, SAMPLES_A[:1]).shadow.mean() for b in (embree, gl)]
    assert min(first) > 0.02 and max(moved) == 0.0 and max(gone) == 0.0


def test_ray_casting_gives_the_same_maps_with_moving_objects_rebuilt_or_kept_local():
    """The two ways of casting against moving objects (one world scene per call, or one local scene
    per object with transformed rays) answer the same, own-target exclusion included."""
    scene = OccluderScene([_moved(cylinder(0.25, 6.0), _toward_camera(0.5) + [0.8, 0.0, 0.0])])
    for i in range(8):
        spot = _toward_camera(0.25 + 0.05 * i) + [0.35 * (i - 4), 0.0, 0.0]
        scene.add_dynamic(
            f"post{i}",
            cylinder(0.15, 3.0),
            RigidTransform(position_world=spot),
            linear_velocity_m_s=(0.5, 0.1 * i, -0.3),
            angular_velocity_rad_s=(0.2 * i, 1.0, 0.0),
        )
    scene.add_dynamic("a", sphere(0.4), RigidTransform(position_world=A_WORLD.copy()), linear_velocity_m_s=(1.0, 0.0, 0.0))
    points = A_WORLD + np.array([[0.0, 0.0, 0.0], [0.0, 0.38, 0.0], [0.0, 0.0, -0.38]])  # centre, top, far side
    rebuilt = EmbreeMapBackend(scene, EmbreeMapSettings(rebuild_triangles_per_ray=1000.0)).compute(
        TORUS, WINDOW, points, exclude_ids=["a"] * 3
    )
    local = EmbreeMapBackend(scene, EmbreeMapSettings(rebuild_triangles_per_ray=0.0)).compute(
        TORUS, WINDOW, points, exclude_ids=["a"] * 3
    )
    assert 0.05 < rebuilt.shadow.mean() < 0.95
    assert np.mean(rebuilt.shadow == local.shadow) > 0.999
    same = (rebuilt.shadow > 0) & (local.shadow > 0)
    np.testing.assert_allclose(rebuilt.velocity_rad_s[same], local.velocity_rad_s[same], rtol=1e-3, atol=1e-4)
    # Without the exclusion the far-side point is hidden by its own target from everywhere.
    assert rebuilt.shadow[2].mean() < 0.9
    assert EmbreeMapBackend(scene).compute(TORUS, WINDOW, points[2:]).shadow.all()


def test_many_objects_moved_together_agree_across_backends_after_every_move(pair):
    """set_motions moves 20 rotated boxes by transform with velocities, three times, without a
    geometry rebuild; after each move the backends agree with each other, ray casting against
    world-space copies and against the shared local scene gives the same maps, and the S-maps
    equal those of the same boxes built in place as static meshes."""
    rng = np.random.default_rng(11)
    meshes = [box(rng.uniform(0.2, 0.6, 3)) for _ in range(20)]
    ids = [f"box{k}" for k in range(len(meshes))]
    scene = OccluderScene()
    for object_id, mesh in zip(ids, meshes):
        scene.add_dynamic(object_id, mesh, RigidTransform(position_world=np.array([0.0, -50.0, 0.0])))
    embree, gl = pair(scene)
    local = EmbreeMapBackend(scene, EmbreeMapSettings(rebuild_triangles_per_ray=0.0))
    version = scene.geometry_version
    for _ in range(3):
        quats = rng.normal(size=(len(ids), 4))
        transforms = [
            RigidTransform(position_world=_toward_camera(f) + offset, rotation_xyzw=q / np.linalg.norm(q))
            for f, offset, q in zip(rng.uniform(0.2, 0.7, len(ids)), rng.normal(scale=0.7, size=(len(ids), 3)), quats)
        ]
        scene.set_motions(ids, transforms, rng.normal(size=(len(ids), 3)), rng.normal(size=(len(ids), 3)))
        assert scene.geometry_version == version
        ray, gl_maps = (b.compute(TORUS, WINDOW, SAMPLES_A) for b in (embree, gl))
        assert 0.05 < ray.shadow.mean() < 0.95 and np.abs(ray.velocity_rad_s).max() > 0.0
        _assert_agree(ray, gl_maps)
        kept_local = local.compute(TORUS, WINDOW, SAMPLES_A)
        assert np.mean(kept_local.shadow == ray.shadow) > 0.999
        same = (kept_local.shadow > 0) & (ray.shadow > 0)
        np.testing.assert_allclose(kept_local.velocity_rad_s[same], ray.velocity_rad_s[same], rtol=1e-3, atol=1e-4)
        in_place = EmbreeMapBackend(OccluderScene([TriMesh(tf.apply(m.vertices), m.faces) for m, tf in zip(meshes, transforms)]))
        assert np.mean(in_place.compute(TORUS, WINDOW, SAMPLES_A).shadow == ray.shadow) > 0.999


def _moving_scene() -> tuple[OccluderScene, np.ndarray, list[str]]:
    """Eight spinning, moving posts before a static pillar, and target a's sphere (its points ignore
    it): three sample points on a, their owners."""
    scene = OccluderScene([_moved(cylinder(0.25, 6.0), _toward_camera(0.5) + [0.8, 0.0, 0.0])])
    for i in range(8):
        spot = _toward_camera(0.25 + 0.05 * i) + [0.35 * (i - 4), 0.0, 0.0]
        rotation = np.array([0.0, math.sin(0.2 * i), 0.0, math.cos(0.2 * i)])
        scene.add_dynamic(
            f"post{i}",
            box((0.3, 3.0, 0.2)),
            RigidTransform(position_world=spot, rotation_xyzw=rotation, scale=np.array([1.0, 1.0 + 0.1 * i, 1.0])),
            linear_velocity_m_s=(0.5, 0.1 * i, -0.3),
            angular_velocity_rad_s=(0.2 * i, 1.0, 0.0),
        )
    scene.add_dynamic("a", sphere(0.4), RigidTransform(position_world=A_WORLD.copy()), linear_velocity_m_s=(1.0, 0.0, 0.0))
    return scene, A_WORLD + np.array([[0.0, 0.0, 0.0], [0.0, 0.38, 0.0], [0.0, 0.0, -0.38]]), ["a"] * 3


@pytest.mark.parametrize("torus_moved", [False, True])
def test_the_compiled_backend_casts_the_rays_embree_casts(torus_moved):
    """Moving, turned and scaled posts, a static pillar, own-target exclusion, and the torus moving
    or not: the S-maps agree but within rounding of an edge, and where both see an occluder its
    velocity and depth agree to Embree's float32 rounding of the hit point."""
    scene, points, owners = _moving_scene()
    before = make_torus(A_WORLD - [0.2, 0.05, 0.0], B_WORLD - [0.2, 0.0, 0.1], ALPHA) if torus_moved else None
    kwargs = {"exclude_ids": owners, "previous_torus": before, "dt_s": 0.1 if torus_moved else 0.0}
    ray = EmbreeMapBackend(scene).compute(TORUS, WINDOW, points, **kwargs)
    compiled = make_backend("native", scene).compute(TORUS, WINDOW, points, **kwargs)
    assert 0.05 < ray.shadow.mean() < 0.95 and np.abs(ray.velocity_rad_s).max() > 0.1
    assert np.mean(compiled.shadow == ray.shadow) > 0.999
    both = (compiled.shadow > 0) & (ray.shadow > 0)
    np.testing.assert_allclose(compiled.velocity_rad_s[both], ray.velocity_rad_s[both], rtol=1e-3, atol=1e-4)
    np.testing.assert_allclose(compiled.depth_m[both], ray.depth_m[both], rtol=1e-5)
    assert not compiled.velocity_rad_s[compiled.shadow == 0].any()


def test_the_compiled_backend_repeats_bit_for_bit_and_survives_a_pickle():
    scene, points, owners = _moving_scene()
    backend = make_backend("native", scene)
    first, second = (backend.compute(TORUS, WINDOW, points, exclude_ids=owners) for _ in range(2))
    again = pickle.loads(pickle.dumps(backend)).compute(TORUS, WINDOW, points, exclude_ids=owners)
    for maps in (second, again):
        for name in ("shadow", "velocity_rad_s", "depth_m"):
            assert getattr(maps, name).tobytes() == getattr(first, name).tobytes()


@pytest.mark.parametrize("threads", [2, 3, 7])
def test_the_compiled_backend_gives_the_same_bits_on_any_number_of_threads(threads):
    """The texels (3 samples' 64 x 64) shared among threads in contiguous runs
    (ServerSettings.map_threads): runs that end inside a sample's map with 2 and 7 threads, on its
    edges with 3. Each texel is the one the caller's thread alone makes."""
    scene, points, owners = _moving_scene()
    before = make_torus(A_WORLD - [0.2, 0.05, 0.0], B_WORLD - [0.2, 0.0, 0.1], ALPHA)
    kwargs = {"exclude_ids": owners, "previous_torus": before, "dt_s": 0.1}
    backend = make_backend("native", scene)
    try:
        share_texels(1)
        alone = backend.compute(TORUS, WINDOW, points, **kwargs)
        share_texels(threads)
        shared = backend.compute(TORUS, WINDOW, points, **kwargs)
    finally:
        share_texels(1)
    assert 0.05 < alone.shadow.mean() < 0.95
    for name in ("shadow", "velocity_rad_s", "depth_m"):
        assert getattr(shared, name).tobytes() == getattr(alone, name).tobytes()


def test_set_motions_rejects_bad_velocities():
    scene = OccluderScene()
    scene.add_dynamic("crate", box((0.6, 0.6, 0.6)), RigidTransform())
    with pytest.raises(ValueError, match="linear_velocities_m_s must be"):
        scene.set_motions(["crate"], [RigidTransform()], np.full((1, 3), np.nan), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="angular_velocities_rad_s must be"):
        scene.set_motions(["crate"], [RigidTransform()], np.zeros((1, 3)), np.zeros((2, 3)))


@pytest.mark.parametrize("backend_name", ["embree", "gl", "native"])
def test_compute_rejects_bad_input(backend_name):
    backend = make_backend(backend_name, OccluderScene())
    try:
        with pytest.raises(ValueError):
            backend.compute(TORUS, WINDOW, np.zeros((2, 2)))
        with pytest.raises(ValueError):
            backend.compute(TORUS, WINDOW, [[np.nan, 0.0, 0.0]])
        with pytest.raises(ValueError):
            backend.compute(TORUS, WINDOW, SAMPLES_A, exclude_ids=["a"])
        with pytest.raises(ValueError):
            backend.compute(TORUS, WINDOW, SAMPLES_A, previous_torus=TORUS, dt_s=0.0)
    finally:
        backend.close()


# -- the window ------------------------------------------------------------------------------------


def test_window_texel_coordinates_round_trip_and_wrap_phi():
    i, j = np.meshgrid(np.arange(RES, dtype=float), np.arange(RES, dtype=float), indexing="ij")
    theta, phi = WINDOW.angles(i, j)
    back_i, back_j = WINDOW.texel_coords(theta, phi + 2.0 * math.pi)
    np.testing.assert_allclose(back_i, i, atol=1e-9)
    np.testing.assert_allclose(back_j, j, atol=1e-9)
    assert WINDOW.contains(THETA, PHI) and not WINDOW.contains(THETA + math.pi, PHI)


def test_window_is_square_in_metres_at_the_camera_and_follows_the_sizing_rule():
    settings = WindowSettings(resolution=RES)
    d_theta, d_phi = torus_tangents(TORUS, MapWindow(THETA - 1e-3, PHI - 1e-3, 1e-3, 1e-3, 2))
    texel_m = (WINDOW.theta_step_rad * np.linalg.norm(d_theta[1, 1]), WINDOW.phi_step_rad * np.linalg.norm(d_phi[1, 1]))
    np.testing.assert_allclose(texel_m[0], texel_m[1], rtol=1e-2)
    half_m = np.linalg.norm(CAMERA - TORUS.mid_world) * math.tan(math.radians(settings.half_view_angle_deg))
    np.testing.assert_allclose(texel_m[0] * RES / 2.0, half_m, rtol=1e-2)
    np.testing.assert_allclose(WINDOW.center_rad, (THETA, PHI), atol=1e-12)


def test_windows_on_one_lattice_shift_by_whole_texels_and_resample_exactly():
    moved = MapWindow.around(
        TORUS,
        THETA + 3.3 * WINDOW.theta_step_rad,
        PHI - 5.6 * WINDOW.phi_step_rad,
        WindowSettings(resolution=RES),
        lattice=WINDOW,
    )
    assert moved.theta_step_rad == WINDOW.theta_step_rad and moved.phi_step_rad == WINDOW.phi_step_rad
    shift_i = (moved.theta_min_rad - WINDOW.theta_min_rad) / WINDOW.theta_step_rad
    shift_j = (moved.phi_min_rad - WINDOW.phi_min_rad) / WINDOW.phi_step_rad
    assert (round(shift_i), round(shift_j)) == (3, -6)
    values = np.random.default_rng(3).random((2, RES, RES)).astype(np.float32)
    out, covered = WINDOW.resample(values, moved)
    np.testing.assert_array_equal(out[:, : RES - 3, 6:], values[:, 3:, : RES - 6])
    assert covered[: RES - 3, 6:].all() and not covered[RES - 3 :, :].any() and not covered[:, :6].any()
    same, all_covered = WINDOW.resample(values, WINDOW)
    np.testing.assert_array_equal(same, values)
    assert all_covered.all()


def test_window_settings_are_validated():
    with pytest.raises(ValueError):
        WindowSettings(resolution=4)
    with pytest.raises(ValueError):
        WindowSettings(half_view_angle_deg=80.0)


# -- the backend rule --------------------------------------------------------------------------------


def test_backend_rule():
    assert choose_backend(10_000_000, "NVIDIA H100 80GB HBM3/PCIe/SSE2") == "gl"
    assert choose_backend(10, None) == "embree"
    software = "llvmpipe (LLVM 15.0.6, 256 bits)"
    assert choose_backend(GL_MAX_TRIANGLES_ON_CPU, software) == "gl"
    assert choose_backend(GL_MAX_TRIANGLES_ON_CPU + 1, software) == "embree"
    with pytest.raises(ValueError):
        make_backend("vulkan", OccluderScene())
