"""OffscreenRenderer (EGL, llvmpipe here) and VideoWriter on hand-built one-box scenes."""

from __future__ import annotations

import math

import imageio_ffmpeg
import numpy as np
import pytest
import trimesh

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.gl_context import egl_context
from camdirector.geometry.render import OffscreenRenderer, top_down_matrix
from camdirector.geometry.transforms import IDENTITY_QUAT, RigidTransform
from camdirector.geometry.video import VideoWriter, concat_videos

WIDTH_PX, HEIGHT_PX = 160, 90
LENS = Lens(vertical_fov_deg=50.0, aspect=WIDTH_PX / HEIGHT_PX)
AT_ORIGIN = CameraPose(np.zeros(3), IDENTITY_QUAT.copy(), LENS.vertical_fov_deg)


@pytest.fixture(scope="module")
def renderer():
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    with OffscreenRenderer(WIDTH_PX, HEIGHT_PX) as r:
        r.add_mesh("box", box.vertices, box.faces, (1.0, 0.0, 0.0))
        yield r


def _box_mask(image: np.ndarray) -> np.ndarray:
    """(h, w) bool: pixels of the pure red box, whatever their shading (the sky is pale blue)."""
    rgb = image.astype(np.int32)
    return (rgb[..., 0] > 50) & (rgb[..., 1] < rgb[..., 0] // 2) & (rgb[..., 2] < rgb[..., 0] // 2)


def _render_box_at(renderer: OffscreenRenderer, position_world, pose: CameraPose = AT_ORIGIN):
    renderer.set_transform("box", RigidTransform(position_world=np.asarray(position_world)).matrix())
    return renderer.render(pose, LENS)


def _centroid_px(mask: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return np.array([cols.mean(), rows.mean()])


def test_box_ahead_covers_the_centre_and_not_the_corners(renderer):
    image = _render_box_at(renderer, (0.0, 0.0, -5.0))
    assert image.shape == (HEIGHT_PX, WIDTH_PX, 3) and image.dtype == np.uint8
    mask = _box_mask(image)
    assert mask[HEIGHT_PX // 2, WIDTH_PX // 2]
    assert not mask[[0, 0, -1, -1], [0, -1, 0, -1]].any()


@pytest.mark.parametrize("position_world", [(1.5, 0.0, -5.0), (0.0, 1.2, -5.0), (-2.0, -1.0, -8.0)])
def test_box_lands_where_project_to_screen_says(renderer, position_world):
    mask = _box_mask(_render_box_at(renderer, position_world))
    expected_xy = project_to_screen(AT_ORIGIN, LENS, np.array([position_world]))[0]
    # Normalised screen (x right, y up) to pixels (column right, row down, top row first).
    expected_px = np.array([(expected_xy[0] + 1) / 2 * WIDTH_PX, (1 - expected_xy[1]) / 2 * HEIGHT_PX])
    # A box's silhouette centroid sits within a pixel or two of its projected centre here.
    assert np.allclose(_centroid_px(mask), expected_px, atol=2.5)


def test_box_to_the_right_moves_the_centroid_right(renderer):
    centred = _centroid_px(_box_mask(_render_box_at(renderer, (0.0, 0.0, -5.0))))
    right = _centroid_px(_box_mask(_render_box_at(renderer, (1.5, 0.0, -5.0))))
    assert right[0] > centred[0] + 10 and abs(right[1] - centred[1]) < 1.0


def test_box_above_the_axis_is_in_the_top_half(renderer):
    rows, _ = np.nonzero(_box_mask(_render_box_at(renderer, (0.0, 1.5, -5.0))))
    assert len(rows) and rows.max() < HEIGHT_PX // 2


def test_box_behind_the_camera_is_not_drawn(renderer):
    assert not _box_mask(_render_box_at(renderer, (0.0, 0.0, 5.0))).any()


def test_rotation_is_camera_to_world(renderer):
    # A turn of +90 degrees about +Y points the camera's -Z along world -X.
    turned = CameraPose(np.zeros(3), np.array([0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4)]), 50.0)
    mask = _box_mask(_render_box_at(renderer, (-5.0, 0.0, 0.0), turned))
    assert mask[HEIGHT_PX // 2, WIDTH_PX // 2]
    assert not _box_mask(_render_box_at(renderer, (0.0, 0.0, -5.0), turned)).any()


def test_bad_meshes_and_ids_are_refused(renderer):
    with pytest.raises(ValueError):
        renderer.add_mesh("flat", np.zeros((4, 2)), np.array([[0, 1, 2]]), (0.5, 0.5, 0.5))
    with pytest.raises(ValueError):
        renderer.add_mesh("oob", np.zeros((3, 3)), np.array([[0, 1, 3]]), (0.5, 0.5, 0.5))
    with pytest.raises(ValueError):
        renderer.add_mesh("box", np.eye(3), np.array([[0, 1, 2]]), (0.5, 0.5, 0.5))
    with pytest.raises(KeyError):
        renderer.set_transform("missing", np.eye(4))


def test_batched_transforms_draw_what_single_ones_draw():
    """set_transforms places each mesh exactly as set_transform does, scaled ones included."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    a = RigidTransform(position_world=np.array([-0.8, 0.0, -4.0])).matrix()
    b = np.diag([0.5, 2.0, 1.0, 1.0])
    b[:3, 3] = (0.9, 0.2, -5.0)
    with OffscreenRenderer(WIDTH_PX, HEIGHT_PX) as one, OffscreenRenderer(WIDTH_PX, HEIGHT_PX) as many:
        for r in (one, many):
            r.add_mesh("a", box.vertices, box.faces, (1.0, 0.0, 0.0))
            r.add_mesh("b", box.vertices, box.faces, (0.0, 0.0, 1.0))
        one.set_transform("a", a)
        one.set_transform("b", b)
        many.set_transforms(["a", "b"], np.stack([a, b]))
        assert np.array_equal(one.render(AT_ORIGIN, LENS), many.render(AT_ORIGIN, LENS))
        with pytest.raises(KeyError):
            many.set_transforms(["a", "missing"], np.stack([a, b]))
        with pytest.raises(ValueError):
            many.set_transforms(["a", "b"], np.stack([a, np.zeros((4, 4))]))
        with pytest.raises(ValueError):
            many.set_transforms(["a", "b"], a[None])


def test_instanced_meshes_draw_what_separate_meshes_draw():
    """Meshes with the same vertices and faces share one instanced draw call; each keeps its own
    transform, colour and checker. The separate scene gets its copies with the faces listed in
    different orders, so nothing is shared there and every mesh is its own draw call."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    rng = np.random.default_rng(3)
    colors = [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.2, 0.8, 0.1), (0.9, 0.9, 0.2)]
    placed = [
        RigidTransform(position_world=np.array(p)).matrix() for p in ((-1.2, 0.0, -4.0), (0.9, 0.3, -5.0), (0.0, -1.0, -6.0))
    ]
    ground = np.diag([8.0, 0.1, 8.0, 1.0])
    ground[:3, 3] = (0.0, -1.6, -6.0)
    matrices = np.stack([*placed, ground])
    ids = ["a", "b", "c", "ground"]
    images = []
    for instanced, closed in ((True, False), (False, False), (True, True)):
        with OffscreenRenderer(WIDTH_PX, HEIGHT_PX) as r:
            for _k, (mesh_id, color) in enumerate(zip(ids, colors)):
                faces = box.faces if instanced else box.faces[rng.permutation(len(box.faces))]
                r.add_mesh(mesh_id, box.vertices, faces, color, closed=closed, checker_m=0.5 if mesh_id == "ground" else 0.0)
            assert r.mesh_ids() == ids
            assert len(r._geometries) == (1 if instanced else len(ids))
            r.set_transforms(ids, matrices)
            images.append(r.render(AT_ORIGIN, LENS))
            if closed:
                with pytest.raises(ValueError, match="mirrored"):
                    r.set_transform("a", np.diag([-1.0, 1.0, 1.0, 1.0]))
    for mesh_id, color in zip(ids[:3], colors):  # each box shows in its own colour
        assert (np.abs(images[0] / 255.0 - color).max(axis=2) < 0.5).any(), mesh_id
    assert np.array_equal(images[0], images[1])
    # Culling the back faces of closed meshes seen from outside changes at most a few silhouette
    # pixels: a pixel centre exactly on a silhouette edge can fall to the back face under the
    # fill rule (the edge runs the other way round it).
    assert (images[0] != images[2]).any(axis=2).sum() <= 4


def test_top_down_view_puts_x_across_and_z_down():
    """A box at world (x, z) lands at column (x - x0) / (x1 - x0) and row (z - z0) / (z1 - z0) of
    the orthographic top view, as the dashboard's top view draws x right and z down."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    view = top_down_matrix((-10.0, 10.0), (-5.0, 5.0), (-1.0, 3.0))
    with OffscreenRenderer(200, 100, fog_start_m=1e6, fog_end_m=2e6) as r:
        r.add_mesh("box", box.vertices, box.faces, (1.0, 0.0, 0.0))
        for x, z in [(6.0, -3.0), (-4.0, 2.0), (0.0, 0.0)]:
            r.set_transform("box", RigidTransform(position_world=np.array([x, 0.5, z])).matrix())
            mask = _box_mask(r.render_view(view, (0.0, 100.0, 0.0)))
            np.testing.assert_allclose(
                _centroid_px(mask), [(x + 10.0) / 20.0 * 200 - 0.5, (z + 5.0) / 10.0 * 100 - 0.5], atol=1.0
            )
            assert 80 <= mask.sum() <= 120  # a 1 m square at 10 px per metre
    with pytest.raises(ValueError):
        top_down_matrix((1.0, 1.0), (0.0, 1.0), (0.0, 1.0))


def test_renderers_sharing_a_context_keep_their_own_scenes():
    """Two renderers on one GL context (the monitors' render process keeps several) each draw
    only their own meshes, whatever the order of their calls."""
    ctx = egl_context()
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    a = OffscreenRenderer(WIDTH_PX, HEIGHT_PX, context=ctx)
    b = OffscreenRenderer(WIDTH_PX, HEIGHT_PX, context=ctx)
    a.add_mesh("box", box.vertices, box.faces, (1.0, 0.0, 0.0))
    b.add_mesh("box", box.vertices, box.faces, (1.0, 0.0, 0.0))
    a.set_transform("box", RigidTransform(position_world=np.array([-1.0, 0.0, -4.0])).matrix())
    b.set_transform("box", RigidTransform(position_world=np.array([1.0, 0.0, -4.0])).matrix())
    left, right = a.render(AT_ORIGIN, LENS), b.render(AT_ORIGIN, LENS)
    assert _centroid_px(_box_mask(left))[0] < WIDTH_PX / 2 < _centroid_px(_box_mask(right))[0]
    a.release()
    np.testing.assert_array_equal(b.render(AT_ORIGIN, LENS), right)  # the shared context outlives a
    b.release()
    ctx.release()


def test_video_writer_writes_a_readable_mp4(tmp_path):
    path = tmp_path / "clip.mp4"
    frame_count = 12
    with VideoWriter(path, fps=24, size_wh=(64, 48)) as video:
        for i in range(frame_count):
            frame = np.zeros((48, 64, 3), dtype=np.uint8)
            frame[:, : 5 * (i + 1)] = (230, 90, 30)  # a bar that grows, so frames differ
            video.write(frame)
    frames, secs = imageio_ffmpeg.count_frames_and_secs(str(path))
    assert frames == frame_count
    assert secs == pytest.approx(frame_count / 24, abs=0.05)


def test_video_writer_refuses_odd_sizes_and_wrong_frames(tmp_path):
    with pytest.raises(ValueError):
        VideoWriter(tmp_path / "odd.mp4", fps=24, size_wh=(63, 48))
    with VideoWriter(tmp_path / "wrong.mp4", fps=24, size_wh=(64, 48)) as video:
        with pytest.raises(ValueError):
            video.write(np.zeros((64, 48, 3), dtype=np.uint8))
        video.write(np.zeros((48, 64, 3), dtype=np.uint8))


def test_concat_videos_joins_parts_without_losing_frames(tmp_path):
    parts = []
    for k, count in enumerate((7, 5)):
        parts.append(tmp_path / f"part{k}.mp4")
        with VideoWriter(parts[-1], fps=24, size_wh=(64, 48)) as video:
            for i in range(count):
                video.write(np.full((48, 64, 3), 40 * k + 10 * i, dtype=np.uint8))
    concat_videos(parts, tmp_path / "all.mp4")
    frames, secs = imageio_ffmpeg.count_frames_and_secs(str(tmp_path / "all.mp4"))
    assert frames == 12 and secs == pytest.approx(12 / 24, abs=0.05)
    reader = imageio_ffmpeg.read_frames(str(tmp_path / "all.mp4"))
    next(reader)
    levels = [np.frombuffer(f, np.uint8).mean() for f in reader]
    assert np.allclose(levels, [10 * i for i in range(7)] + [40 + 10 * i for i in range(5)], atol=3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["all.mp4", "part0.mp4", "part1.mp4"]
    with pytest.raises(RuntimeError, match="2 video parts"):
        concat_videos([parts[0], tmp_path / "missing.mp4"], tmp_path / "bad.mp4")
    assert not (tmp_path / "bad.mp4").exists()
