"""Smoke test of the top-down map of a demo run."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from camdirector.demo.scene import build_demo_scene
from camdirector.demo.topdown import draw_topdown


def _run_paths(scene) -> tuple[np.ndarray, np.ndarray]:
    times_s = np.arange(0.0, scene.duration_s, 0.1)
    target_xz = scene.avatar_position_xz(times_s)
    camera_xz = target_xz + np.array([3.0, -2.0])
    camera_xz[80:] = target_xz[80:] + np.array([-4.0, 1.0])  # a cut at frame 80
    return target_xz, camera_xz


def test_draws_a_png_of_plausible_size(tmp_path):
    scene = build_demo_scene(seed=7)
    target_xz, camera_xz = _run_paths(scene)
    out = draw_topdown(scene, target_xz, camera_xz, tmp_path / "map.png", cut_indices=(80,))
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 20_000
    with Image.open(out) as image:
        assert 600 <= image.width <= 2000 and 600 <= image.height <= 2000


def test_refuses_bad_paths_and_cuts(tmp_path):
    scene = build_demo_scene(seed=7)
    target_xz, camera_xz = _run_paths(scene)
    with pytest.raises(ValueError):
        draw_topdown(scene, target_xz[:, :1], camera_xz, tmp_path / "a.png")
    with pytest.raises(ValueError):
        draw_topdown(scene, target_xz, camera_xz, tmp_path / "b.png", cut_indices=(len(camera_xz),))
