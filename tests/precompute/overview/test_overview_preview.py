"""Preview rendering (preview.py): capsule character through the camera, shot marking, the mp4
and the contact sheet, on the 72-frame run clip."""

from __future__ import annotations

import dataclasses
import functools

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.pipeline import plan_overview
from camdirector.precompute.overview.preview import (
    PART_RGB,
    CharacterScene,
    PreviewCamera,
    PreviewSettings,
    contact_sheet_frames,
    even_size,
    mark_frame,
    preview_frames,
    render_preview,
    shot_rgb,
)

from .overview_mocap import load_clip


def test_sizes_and_frame_sampling():
    assert even_size(16 / 9, 270) == (480, 270)
    assert even_size(1.0, 271) == (270, 270)
    frames, fps = preview_frames(100, 1 / 120, 30.0)
    assert fps == pytest.approx(30.0) and list(frames[:3]) == [0, 4, 8]
    frames, fps = preview_frames(10, 1 / 30, 30.0)
    assert fps == pytest.approx(30.0) and len(frames) == 10
    assert contact_sheet_frames(np.array([[0, 9], [10, 30]])) == [
        (0, "start", 0),
        (0, "middle", 4),
        (1, "start", 10),
        (1, "middle", 20),
    ]
    with pytest.raises(ValueError):
        PreviewSettings(height_px=8)


def test_shot_marking_draws_a_border_only_when_flashing():
    image = np.full((90, 160, 3), 200, np.uint8)
    plain = mark_frame(image, 1, 3, 0.5, False, 4)
    flashed = mark_frame(image, 1, 3, 0.5, True, 4)
    assert tuple(flashed[0, 80]) == shot_rgb(1) and tuple(flashed[45, 0]) == shot_rgb(1)
    assert tuple(plain[0, 80]) == (200, 200, 200)
    assert (plain != image).any()  # the label is drawn


@functools.cache
def _planned(shared_data):
    clip = load_clip(shared_data, "run")
    return clip, plan_overview(clip, OverviewSettings(), np.random.default_rng(0))


@pytest.mark.shared_data
def test_character_is_rendered_in_frame(shared_data):
    clip, result = _planned(shared_data)
    camera = PreviewCamera.from_result(result)
    w, h = even_size(camera.aspect, 180)
    with CharacterScene(clip, result.analysis.parts, w, h) as scene:
        image = scene.render(36, camera)
    assert image.shape == (h, w, 3)
    # every body part's colour shows somewhere (lit, so compare hue loosely: the dominant channel)
    body = np.zeros(image.shape[:2], bool)
    for rgb in PART_RGB.values():
        target = np.array(rgb) * 255
        close = (
            np.abs(image.astype(float) / np.maximum(image.max(axis=2, keepdims=True), 1) - target / target.max()).max(axis=2)
            < 0.12
        )
        body |= close
    ys, xs = np.nonzero(body)
    assert len(ys) > 50
    assert 0.15 * w < xs.mean() < 0.85 * w and 0.1 * h < ys.mean() < 0.9 * h


@pytest.mark.shared_data
def test_render_preview_writes_video_and_contact_sheet(shared_data, tmp_path):
    clip, result = _planned(shared_data)
    camera = PreviewCamera.from_result(result)
    # two shots, to see the sheet's layout and the flash
    camera = dataclasses.replace(camera, shots=np.array([[0, 39], [40, 71]]))
    settings = PreviewSettings(height_px=144, tile_height_px=72)
    timings = render_preview(clip, result.analysis.parts, camera, tmp_path / "p.mp4", tmp_path / "s.png", settings)
    assert set(timings) == {"preview_setup", "preview_video", "contact_sheet"}
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(tmp_path / "p.mp4"))
    assert frames == clip.frame_count
    reader = imageio_ffmpeg.read_frames(str(tmp_path / "p.mp4"))
    meta = next(reader)
    assert tuple(meta["size"]) == even_size(camera.aspect, 144)
    video = [np.frombuffer(f, np.uint8).reshape(144, meta["size"][0], 3) for f in reader]
    red = np.array(shot_rgb(1))
    assert np.abs(video[41][72, 1].astype(int) - red).max() < 40  # border at the cut
    assert np.abs(video[60][72, 1].astype(int) - red).max() > 40  # gone later
    sheet = Image.open(tmp_path / "s.png")
    tw, th = even_size(camera.aspect, 72)
    assert sheet.size[0] > 4 * tw and th < sheet.size[1] < 2 * th  # 4 tiles in one row
    with pytest.raises(ValueError, match="frames"):
        render_preview(clip, result.analysis.parts, dataclasses.replace(camera, position_m=camera.position_m[:10]), None, None)


@pytest.mark.shared_data
def test_video_rendered_in_two_processes_matches_one(shared_data, tmp_path):
    """The frame range split between this process and a child, joined without re-encoding: same
    frames, same pictures (up to the encoder's different keyframes), nothing left behind."""
    clip, result = _planned(shared_data)
    camera = dataclasses.replace(PreviewCamera.from_result(result), shots=np.array([[0, 39], [40, 71]]))
    one = PreviewSettings(height_px=144, processes=1)
    two = dataclasses.replace(one, processes=2, min_frames_per_process=20, head_start_frames=0)
    videos = []
    for settings in (one, two):
        out = tmp_path / f"p{settings.processes}.mp4"
        render_preview(clip, result.analysis.parts, camera, out, None, settings)
        assert imageio_ffmpeg.count_frames_and_secs(str(out))[0] == clip.frame_count
        reader = imageio_ffmpeg.read_frames(str(out))
        w = next(reader)["size"][0]
        videos.append(np.stack([np.frombuffer(f, np.uint8).reshape(144, w, 3) for f in reader]))
    one_v, two_v = (v.astype(int) for v in videos)
    diff = np.abs(one_v - two_v).mean(axis=(1, 2, 3))  # per frame, 0..255
    # Two encoder runs instead of one (different keyframes and frame types around the join), so
    # not bit for bit; each frame of the child's part is still nearer to the same frame than to
    # its neighbours, so none was dropped or doubled at the join.
    assert diff.max() < 4.0, diff.max()
    shifted = [np.abs(one_v[37:-1] - two_v[37 + s : len(two_v) - 1 + s]).mean(axis=(1, 2, 3)) for s in (-1, 1)]
    assert np.all(diff[37:-1] < np.minimum(*shifted))
    red = np.array(shot_rgb(1))
    assert np.abs(videos[1][41][72, 1].astype(int) - red).max() < 40  # the child's part
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p1.mp4", "p2.mp4"]

    # A child that fails (a zero field of view in its part only) fails the whole video.
    fov = camera.vertical_fov_deg.copy()
    fov[60:] = 0.0
    bad = dataclasses.replace(camera, vertical_fov_deg=fov)
    with pytest.raises(RuntimeError, match="preview part 1 failed"):
        render_preview(clip, result.analysis.parts, bad, tmp_path / "bad.mp4", None, two)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p1.mp4", "p2.mp4"]
