"""Non-linear MDS and motion saliency (saliency.py)."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.precompute.overview.body_parts import map_body_parts
from camdirector.precompute.overview.character_track import sample_frames, track_character
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.saliency import classical_mds, compute_saliency, pairwise_distances, sammon_mapping

from .overview_mocap import load_clip


def test_classical_mds_recovers_planar_distances():
    rng = np.random.default_rng(1)
    points = np.zeros((40, 5))
    points[:, :2] = rng.normal(size=(40, 2))
    coords = classical_mds(points, 2)
    np.testing.assert_allclose(pairwise_distances(coords), pairwise_distances(points), atol=1e-6)


def _sammon_stress(points, coords):
    target, d = pairwise_distances(points), pairwise_distances(coords)
    iu = np.triu_indices(len(points), 1)
    return float(((target[iu] - d[iu]) ** 2 / target[iu]).sum() / target[iu].sum())


def test_sammon_lowers_stress_of_a_curved_curve():
    t = np.linspace(0, 4 * np.pi, 120)
    helix = np.stack([np.cos(t), np.sin(t), 0.3 * t, np.sin(3 * t)], axis=1)
    start = classical_mds(helix, 2)
    refined = sammon_mapping(helix, 2, 40)
    assert _sammon_stress(helix, refined) < _sammon_stress(helix, start)


@pytest.mark.shared_data
def test_kick_saliency_peaks_at_the_three_kicks(shared_data):
    # SOURCES.md: three high kicks at about 2.0, 6.5 and 10.8 s.
    clip = load_clip(shared_data, "kick")
    settings = OverviewSettings()
    parts = map_body_parts(clip)
    frames = sample_frames(clip.frame_count, clip.frame_time_s, settings.analysis_rate_hz)
    saliency = compute_saliency(track_character(clip, parts, settings, frames), parts, settings)
    times = frames * clip.frame_time_s
    assert saliency.pose.max() == pytest.approx(1.0)
    np.testing.assert_allclose(saliency.limbs.sum(axis=1), 1.0)
    for kick_s in (2.0, 6.5, 10.8):
        window = np.abs(times - kick_s) < 0.5
        assert saliency.pose[window].max() > 0.8, kick_s
    calm = np.abs(times - 4.3) < 0.5
    assert saliency.pose[calm].max() < 0.5
