"""The bot match simulator (evaluation/match/sim.py) and the match file (match_file.py) on a tiny
hand-built arena, and `camdirector match-sim` on the shared nav_test level."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from camdirector.evaluation.match.match_file import MatchEvent, MatchRecording, load_match, save_match
from camdirector.evaluation.match.sim import NavGround, SimSettings, simulate_match
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import UP_WORLD, quat_to_matrix
from camdirector.precompute.tracks.pipeline import precompute_level
from camdirector.precompute.tracks.track_settings import TrackSettings
from tests.precompute.tracks.tiny_levels import boxes
from tests.service.tracks_sessions import ROOT, cli_add_level

SECONDS = 60.0


def arena() -> TriMesh:
    """A walled 40 x 14 m floor (top at y=0) with two 3 m high blocks that break the line of sight."""
    return boxes(
        ((0, -0.2, 0), (40, 0, 14)),
        ((0, 0, -0.1), (40, 3, 0)),
        ((0, 0, 14), (40, 3, 14.1)),
        ((-0.1, 0, 0), (0, 3, 14)),
        ((40, 0, 0), (40.1, 3, 14)),
        ((12, 0, 3), (14, 3, 8)),
        ((26, 0, 6), (28, 3, 11)),
    )


@pytest.fixture(scope="module")
def artifact():
    return precompute_level(arena(), TrackSettings(), np.random.default_rng(0))


@pytest.fixture(scope="module")
def match(artifact) -> MatchRecording:
    return simulate_match(artifact, "arena", 6, SECONDS, np.random.default_rng(7), 7)


def _frame_of(match: MatchRecording, event: MatchEvent) -> int:
    return int(np.searchsorted(match.time_s, event.time_s))


def test_same_seed_same_match_bit_for_bit(artifact, match):
    again = simulate_match(artifact, "arena", 6, SECONDS, np.random.default_rng(7), 7)
    for name in ("time_s", "positions_world", "rotations_xyzw", "alive"):
        assert np.array_equal(getattr(again, name), getattr(match, name)), name
    assert [e.as_json() for e in again.events] == [e.as_json() for e in match.events]
    other = simulate_match(artifact, "arena", 6, 10.0, np.random.default_rng(8), 8)
    assert not np.array_equal(other.positions_world, match.positions_world[: len(other.time_s)])


def test_bots_meet_fight_and_take_objectives(match):
    kinds = [e.kind for e in match.events]
    assert kinds.count("kill") >= 3, kinds
    assert "damage" in kinds and "objective" in kinds
    distance_m = np.linalg.norm(np.diff(match.positions_world, axis=0), axis=2)
    assert (distance_m.sum(axis=0) > 50.0).all(), "every bot walks"


def test_feet_stay_on_the_navmesh_and_speed_is_bounded(artifact, match):
    agent = artifact.settings
    ground = NavGround(
        TriMesh(artifact.navmesh_vertices, artifact.navmesh_faces), agent.agent_max_climb_m, 0.5 * agent.navmesh_cell_m, 0.3, 32
    )
    feet = match.positions_world[match.alive]
    triangle, height = ground.surface(feet)
    on = triangle >= 0
    np.testing.assert_allclose(height[on], feet[on, 1], atol=1e-6)
    # the rest may cut a notch of the navmesh's jagged outline between two checks of a shortcut
    # (SimSettings.path_check_step_m), but never by more than 10 cm (the navmesh is eroded 60 cm from walls)
    angle = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    ring = 0.1 * np.stack([np.cos(angle), np.zeros_like(angle), np.sin(angle)], axis=1)
    near = ground.surface((feet[~on][:, None] + ring).reshape(-1, 3))[0].reshape(-1, len(ring)) >= 0
    assert near.any(axis=1).all(), "an alive bot stands more than 10 cm off the navmesh's largest region"
    assert on.mean() > 0.99
    both = match.alive[1:] & match.alive[:-1]
    speed_m_s = np.linalg.norm(np.diff(match.positions_world, axis=0), axis=2)[both] * match.rate_hz
    assert speed_m_s.max() <= SimSettings().run_speed_m_s * (1 + 1e-6)


def test_facing_is_a_yaw_about_up(match):
    q = match.rotations_xyzw.reshape(-1, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0)
    rotation = quat_to_matrix(q)  # (n, 3, 3): columns are local +X, +Y, +Z in the world
    np.testing.assert_allclose(rotation[:, :, 1], np.broadcast_to(UP_WORLD, (len(q), 3)), atol=1e-12)
    assert np.ptp(rotation[:, 0, 2]) > 1.5 and np.ptp(rotation[:, 2, 2]) > 1.5, "bots face every way"


def test_kills_only_in_line_of_sight_within_range(artifact, match):
    settings = SimSettings()
    scene = RayScene([TriMesh(artifact.level_vertices, artifact.level_faces)])
    index = match.player_index()
    kills = [e for e in match.events if e.kind == "kill"]
    assert kills
    for kill in kills:
        f, a, v = _frame_of(match, kill), index[kill.actor_id], index[kill.other_actor_id]
        assert match.players[a].team != match.players[v].team
        height = match.players[a].height_m
        eye = match.positions_world[f, a] + settings.eye_height_fraction * height * UP_WORLD
        chest = match.positions_world[f, v] + settings.chest_height_fraction * height * UP_WORLD
        assert np.linalg.norm(chest - eye) <= settings.view_range_m
        assert not scene.occluded(eye, chest[None])[0], f"kill at {kill.time_s} s through a wall"
        np.testing.assert_array_equal(kill.position_world, match.positions_world[f, v])


def test_the_dead_neither_move_nor_shoot_and_wait_to_respawn(match):
    settings = SimSettings()
    index = match.player_index()
    for event in match.events:
        if event.kind in ("kill", "damage"):
            f = _frame_of(match, event)
            assert match.alive[f - 1, index[event.actor_id]], f"{event.actor_id} shot while dead"
            assert match.alive[f - 1, index[event.other_actor_id]]
            if event.kind == "kill":  # (a damaged one may die to another shot of the same tick)
                assert not match.alive[f, index[event.other_actor_id]]
    dead = ~match.alive[1:] & ~match.alive[:-1]
    assert dead.any()
    moved = np.linalg.norm(np.diff(match.positions_world, axis=0), axis=2)[dead]
    turned = np.abs(np.diff(match.rotations_xyzw, axis=0)).sum(axis=2)[dead]
    assert (moved == 0).all() and (turned == 0).all()
    for p in range(len(match.players)):
        changes = np.flatnonzero(np.diff(match.alive[:, p].astype(int)))
        deaths = [c + 1 for c in changes if not match.alive[c + 1, p]]
        for d in deaths:
            back = np.flatnonzero(match.alive[d:, p])
            if len(back):
                assert back[0] / match.rate_hz >= settings.respawn_s - 1e-9


def test_events_are_ordered_and_grouped_on_their_frames(match):
    times = [e.time_s for e in match.events]
    assert times == sorted(times)
    per_frame = match.events_per_frame()
    assert len(per_frame) == len(match.time_s) and sum(map(len, per_frame)) == len(match.events)
    for f, events in enumerate(per_frame):
        for e in events:
            assert match.time_s[f] >= e.time_s and (f == 0 or match.time_s[f - 1] < e.time_s)
    damage = [(e.actor_id, e.other_actor_id, e.time_s) for e in match.events if e.kind == "damage"]
    for pair in {d[:2] for d in damage}:
        gaps = np.diff([t for a, v, t in damage if (a, v) == pair])
        assert (gaps >= SimSettings().damage_event_interval_s - 1e-9).all(), "damage events are throttled"


def test_file_round_trips_and_refuses_bad_shapes(match, tmp_path):
    save_match(match, tmp_path / "m.npz")
    back = load_match(tmp_path / "m.npz")
    assert (back.level, back.seed, back.rate_hz, back.players) == (match.level, match.seed, match.rate_hz, match.players)
    for name in ("time_s", "positions_world", "rotations_xyzw", "alive"):
        assert (
            np.array_equal(getattr(back, name), getattr(match, name)) and getattr(back, name).dtype == getattr(match, name).dtype
        )
    assert [e.as_json() for e in back.events] == [e.as_json() for e in match.events]
    with pytest.raises(ValueError, match=r"positions_world must be \(F, P, 3\)"):
        dataclasses.replace(match, positions_world=match.positions_world[:, :-1])
    with pytest.raises(ValueError, match="outside the frames' times"):
        dataclasses.replace(match, events=[dataclasses.replace(match.events[0], time_s=match.time_s[-1] + 1.0)])
    np.savez(tmp_path / "other.npz", time_s=match.time_s)
    with pytest.raises(ValueError, match="not a match file"):
        load_match(tmp_path / "other.npz")


def test_settings_and_arguments_are_checked_once(artifact):
    with pytest.raises(ValueError, match="hit_chance"):
        SimSettings(hit_chance=1.5)
    with pytest.raises(ValueError, match="fire_rate_hz"):
        SimSettings(fire_rate_hz=20.0)
    with pytest.raises(ValueError, match="players must be 2 to 64"):
        simulate_match(artifact, "arena", 65, 1.0, np.random.default_rng(0), 0)


@pytest.mark.shared_data
def test_cli_on_nav_test(shared_data, tmp_path):
    cli_add_level(tmp_path / "data", "nav_test", shared_data / "levels" / "recast" / "nav_test.obj")
    out = tmp_path / "m.npz"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "camdirector.__main__",
            "match-sim",
            "--level",
            "nav_test",
            "--players",
            "10",
            "--minutes",
            "1",
            "--seed",
            "1",
            "--out",
            str(out),
            "--data-dir",
            str(tmp_path / "data"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    match = load_match(out)
    assert summary["frames"] == len(match.time_s) == 3600 and len(match.players) == 10
    assert [p.team for p in match.players].count(0) == 5
    assert summary["events"]["kill"] == sum(e.kind == "kill" for e in match.events) >= 5
    unknown = subprocess.run(
        [
            sys.executable,
            "-m",
            "camdirector.__main__",
            "match-sim",
            "--level",
            "nope",
            "--out",
            str(out),
            "--data-dir",
            str(tmp_path / "data"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert unknown.returncode == 2 and "no level named 'nope'" in unknown.stderr
