"""Artifact and registry persistence, continuity rules, shot durations and the director on tiny levels."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
from scipy import stats

from camdirector.evaluation.tracks.measure import ActorBody, frame_view, shot_pose, visible_share
from camdirector.geometry.camera import Lens
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.style import Movement, ShotSize
from camdirector.pipeline.tracks.continuity import cut_angle_deg, keeps_line_of_action, screen_motion
from camdirector.pipeline.tracks.cutting import CutReason, draw_shot_duration_s
from camdirector.pipeline.tracks.director import DirectorStyle, GraphDirector
from camdirector.pipeline.tracks.settings import DirectorSettings
from camdirector.pipeline.tracks.shot_sizes import fit_ratio, framed_ends_world
from camdirector.precompute.tracks.artifact import FORMAT_VERSION, ArtifactVersionError, load_artifact, save_artifact
from camdirector.precompute.tracks.pipeline import precompute_level
from camdirector.precompute.tracks.registry import LevelRegistry
from camdirector.precompute.tracks.track_settings import TrackSettings
from tests.precompute.tracks.tiny_levels import corridor


@pytest.fixture(scope="module")
def corridor_artifact():
    return precompute_level(corridor(), TrackSettings(), np.random.default_rng(0))


def test_artifact_round_trip_and_version_refusal(tmp_path, corridor_artifact):
    path = tmp_path / "c.npz"
    save_artifact(corridor_artifact, path)
    back = load_artifact(path)
    np.testing.assert_array_equal(back.nodes_world, corridor_artifact.nodes_world)
    np.testing.assert_array_equal(back.visibility.triangle_nodes, corridor_artifact.visibility.triangle_nodes)
    assert back.settings == corridor_artifact.settings and back.timings_ms == corridor_artifact.timings_ms
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    header = json.loads(np.load(path)["header"].tobytes())
    header["format_version"] = 99
    np.save(tmp_path / "h.npy", np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
    members["header.npy"] = (tmp_path / "h.npy").read_bytes()
    with zipfile.ZipFile(tmp_path / "old.npz", "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    with pytest.raises(ArtifactVersionError, match=f"version 99, this build reads version {FORMAT_VERSION}"):
        load_artifact(tmp_path / "old.npz")


def test_registry_survives_a_reopen_and_deletes(tmp_path):
    level = tmp_path / "corridor.obj"
    mesh = corridor()
    level.write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces)
    )
    first = LevelRegistry(tmp_path / "data")
    record = first.add_level("corridor", level, scale=1.0)
    assert record.counts["nodes"] > 0
    again = LevelRegistry(tmp_path / "data")
    assert [r.name for r in again.list()] == ["corridor"]
    assert len(again.load("corridor").nodes_world) == record.counts["nodes"]
    first.add_level("corridor", level, scale=1.0)  # replaced: one file left
    assert len(list((tmp_path / "data" / "levels").glob("*.npz"))) == 1
    assert again.delete("corridor") and again.list() == [] and not again.delete("corridor")
    with pytest.raises(ValueError):
        again.add_level("../bad", level)


def test_continuity_rules_on_constructed_cuts():
    actor = np.zeros(3)
    before_cam = np.array([0.0, 0.0, 5.0])
    cams = np.array([[1.0, 0, 5.0], [5.0, 0, 0.0], [-5.0, 0, 0.0], [0.0, 0, -5.0]])
    angle = cut_angle_deg(before_cam, cams, actor)
    assert angle[0] < 30 and np.allclose(angle[1:], [90, 90, 180])
    motion = np.array([1.0, 0, 0])  # along +x: the line of action is the x axis
    before = screen_motion(before_cam[None], actor, motion)[0]
    same_side = keeps_line_of_action(before, screen_motion(np.array([[3.0, 0, 4.0], [-3.0, 0, 4.0]]), actor, motion))
    other_side = keeps_line_of_action(before, screen_motion(np.array([[3.0, 0, -4.0], [0.0, 0, -5.0]]), actor, motion))
    assert same_side.all() and not other_side.any()


def test_shot_durations_are_log_normal():
    settings = DirectorSettings(min_shot_s=0.0)
    rng = np.random.default_rng(0)
    logs = np.log([draw_shot_duration_s(rng, settings) for _ in range(2000)])
    assert stats.kstest(logs, "norm", args=(np.log(settings.shot_duration_median_s), settings.shot_duration_sigma)).pvalue > 0.01


def _corridor_feet(speed=1.4, seconds=20.0, fps=30.0) -> list[tuple[float, np.ndarray]]:
    """(time s, feet (3,) m) of an actor walking down the corridor, again and again."""
    return [(k / fps, np.array([2.0 + (speed * k / fps) % 26.0, 0.0, 2.0])) for k in range(int(seconds * fps))]


def _walk_corridor(director, scene):
    return [director.step(t, feet, np.array([1.0, 0, 0]), scene) for t, feet in _corridor_feet()]


@pytest.mark.parametrize("movement", list(Movement))
def test_director_keeps_the_actor_visible_and_cuts_by_the_rules(corridor_artifact, movement):
    scene = RayScene([corridor()])
    settings = DirectorSettings(shot_duration_median_s=1.5)
    director = GraphDirector(corridor_artifact, settings, np.random.default_rng(1), DirectorStyle(ShotSize.LONG, movement))
    shots = _walk_corridor(director, scene)
    lens, body = Lens(vertical_fov_deg=settings.vertical_fov_deg), ActorBody.of_height(corridor_artifact.agent_height_m)
    views = [
        frame_view(shot_pose(s.position_world, s.look_at_world, lens), lens, feet, body, ShotSize.LONG, scene)
        for s, (_, feet) in zip(shots, _corridor_feet())
    ]
    assert visible_share(views) >= 0.9, "the actor inside the frame and unoccluded (evaluation/tracks/measure.py)"
    cuts = [i for i, s in enumerate(shots) if s.cut]
    assert cuts[0] == 0
    if movement == Movement.DYNAMIC_NO_CUTS:
        assert cuts == [0]
    else:
        assert len(cuts) >= 3, "20 s of 1.5 s median shots must cut"
    for i in cuts[1:]:
        prev, new = shots[i - 1], shots[i]
        actor = new.look_at_world
        assert cut_angle_deg(prev.position_world, new.position_world[None], actor)[0] >= settings.min_cut_angle_deg
        before = screen_motion(prev.position_world[None], actor, np.array([1.0, 0, 0]))[0]
        assert keeps_line_of_action(before, screen_motion(new.position_world[None], actor, np.array([1.0, 0, 0])))[0]
    if movement == Movement.STATIC:
        moving = [
            i
            for i in range(1, len(shots))
            if not shots[i].cut and not np.allclose(shots[i].position_world, shots[i - 1].position_world)
        ]
        assert moving == []
    assert all(s.shot_id == sum(1 for c in cuts if c <= i) - 1 for i, s in enumerate(shots))


def test_style_switches_live(corridor_artifact):
    director = GraphDirector(corridor_artifact, DirectorSettings(), np.random.default_rng(0))
    near = director.optimal_distance_m()
    director.set_style(DirectorStyle(ShotSize.EXTREME_LONG, Movement.STATIC))
    assert director.optimal_distance_m() > 2.5 * near and director.style.movement == Movement.STATIC


def test_each_frame_reports_the_scores_of_the_target_it_chose(corridor_artifact):
    """Moves carry the target moving strategy's four sub-scores, cuts after the first the two
    continuity ones too, and each total is their weighted mean (Section 5.2-5.3)."""
    s = DirectorSettings(shot_duration_median_s=1.5)
    director = GraphDirector(corridor_artifact, s, np.random.default_rng(1))
    shots = _walk_corridor(director, RayScene([corridor()]))
    move_keys = {"shot_size", "direct_visibility", "indirect_visibility", "graph_distance", "total"}
    weights = {
        "shot_size": s.weight_shot_size,
        "direct_visibility": s.weight_direct_visibility,
        "indirect_visibility": s.weight_indirect_visibility,
        "graph_distance": s.weight_distance,
        "thirty_degree": s.weight_thirty_degree,
        "line_of_action": s.weight_line_of_action,
    }
    assert set(shots[0].scores) == {"shot_size", "direct_visibility", "indirect_visibility", "total"}
    later_cuts = [shot.scores for shot in shots[1:] if shot.cut]
    moves = [shot.scores for shot in shots if not shot.cut and shot.scores]
    assert later_cuts and moves
    assert all(
        set(c) == {"shot_size", "direct_visibility", "indirect_visibility", "thirty_degree", "line_of_action", "total"}
        for c in later_cuts
    )
    assert all(set(m) == move_keys for m in moves)
    for scores in [shots[0].scores, *later_cuts, *moves]:
        parts = {k: v for k, v in scores.items() if k != "total"}
        assert all(0.0 <= v <= 1.0 for v in parts.values())
        mean = sum(weights[k] * v for k, v in parts.items()) / sum(weights[k] for k in parts)
        assert scores["total"] == pytest.approx(mean, abs=1e-3)


@pytest.mark.parametrize("size", list(ShotSize))
def test_cuts_that_can_wait_go_only_to_places_that_frame_solidly(corridor_artifact, size):
    """A cut for shot duration or framing lands where the shot size holds with room to spare
    (`framing_cut_margin` of the framing tolerance) and its framed extent fits (a static camera
    that crops the actor may also cut to where the extent merely fits); a cut to a place at the
    tolerance's edge, or to one too near, was violated again a moment later and cut again."""
    s = DirectorSettings(shot_duration_median_s=1.5)
    director = GraphDirector(corridor_artifact, s, np.random.default_rng(1), DirectorStyle(size, Movement.DYNAMIC_WITH_CUTS))
    shots = _walk_corridor(director, RayScene([corridor()]))
    height, radius = corridor_artifact.agent_height_m, s.actor_radius_fraction * corridor_artifact.agent_height_m
    feet = [f for _, f in _corridor_feet()]

    def fits(camera, k):
        return fit_ratio(camera[None], framed_ends_world(feet[k], height, size), radius, s.vertical_fov_deg, 0.0)[0] <= 1.0

    waited = [
        k for k in range(1, len(shots)) if shots[k].cut and shots[k].cut_reason in (CutReason.SHOT_DURATION, CutReason.FRAMING)
    ]
    assert len(waited) >= 3, "20 s of 1.5 s median shots must cut"
    for k in waited:
        camera = shots[k].position_world
        look_at = feet[k] + np.array([0.0, s.look_at_fraction * height, 0.0])
        log_ratio = abs(np.log(np.linalg.norm(camera - look_at) / director.optimal_distance_m()))
        assert fits(camera, k), shots[k].cut_reason
        assert log_ratio <= s.framing_violation_log * s.framing_cut_margin + 1e-9, shots[k].cut_reason
