"""Match files (evaluation/match/match_file.py): cutting a match short keeps every per-frame array,
the stats and the aim included, and only the events up to the cut; saved and loaded, it is the
same. Bodies stand: a rotation is a turn about world up, the view's pitch is the aim; a file of the
older kind (the view as the body) reads as such; a file that is no match is refused plainly."""

from __future__ import annotations

import dataclasses
import gzip

import numpy as np
import pytest

from camdirector.evaluation.match.match_file import load_match, save_match
from camdirector.geometry import quake_frame
from camdirector.geometry.transforms import quat_rotate
from tests.evaluation.match.test_measure import duel


def with_stats():
    match = duel()
    stats = np.zeros((len(match.time_s), 2, 4), dtype=np.int32)
    stats[:, :, 0] = np.arange(len(match.time_s))[:, None]  # health: the frame number, to see the cut
    return dataclasses.replace(match, stats=stats)


def test_until_cuts_every_per_frame_array_and_the_events_alike():
    match = with_stats()
    before = match.until(1.5)  # the kill is at 2 s
    assert len(before.time_s) == 16 and before.time_s[-1] == 1.5
    assert before.positions_world.shape[0] == before.rotations_xyzw.shape[0] == before.alive.shape[0] == 16
    assert before.stats[:, 0, 0].tolist() == list(range(16)) and before.events == []
    assert len(match.until(2.0).events) == 1
    assert len(match.until(-5.0).time_s) == 1  # at least the first frame


def test_a_cut_match_with_stats_and_names_survives_a_save(tmp_path):
    match = with_stats().until(2.5)
    save_match(match, tmp_path / "m.npz")
    loaded = load_match(tmp_path / "m.npz")
    np.testing.assert_array_equal(loaded.stats, match.stats)
    np.testing.assert_array_equal(loaded.positions_world, match.positions_world)
    assert loaded.players == match.players and len(loaded.events) == 1


def assert_stands_and_aims(match, frame: int, player: int, pitch_deg: float, yaw_deg: float) -> None:
    """The player's body stands upright (its local +Y world up, within 1e-9) facing the view's yaw,
    and its aim looks along the view: pitch (positive looks down) and yaw as Quake and Source count
    them, yaw about Z up from +X, which is world +X turning toward world -Z (geometry/quake_frame.py)."""
    p, y = np.radians(pitch_deg), np.radians(yaw_deg)
    body = match.rotations_xyzw[frame, player]
    np.testing.assert_allclose(quat_rotate(body, [0.0, 1.0, 0.0]), [0.0, 1.0, 0.0], rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(quat_rotate(body, [0.0, 0.0, 1.0]), [np.cos(y), 0.0, -np.sin(y)], rtol=0.0, atol=1e-9)
    aim = match.aim_rotations_xyzw()[frame, player]
    forward = [np.cos(p) * np.cos(y), -np.sin(p), -np.cos(p) * np.sin(y)]
    np.testing.assert_allclose(quat_rotate(aim, [0.0, 0.0, 1.0]), forward, rtol=0.0, atol=1e-9)


def save_views(path) -> np.ndarray:
    """Writes the duel as a file imported before bodies stood: its rotations the players' views,
    a (pitch 60, yaw 30) deg, b (-45, -120), no aim. Returns those rotations (F, 2, 4)."""
    match = duel()
    views = match.rotations_xyzw.copy()
    views[:, 0] = quake_frame.view_rotation(60.0, 30.0)
    views[:, 1] = quake_frame.view_rotation(-45.0, -120.0)
    save_match(match, path)
    with np.load(path) as data:
        arrays = dict(data)
    np.savez_compressed(path, **{**arrays, "rotations_xyzw": views})
    return views


def test_a_body_that_leans_is_refused():
    match = duel()
    leaning = match.rotations_xyzw.copy()
    leaning[:, 0] = quake_frame.view_rotation(60.0, 0.0)  # looking down, the whole body pitched
    with pytest.raises(ValueError, match="upright"):
        dataclasses.replace(match, rotations_xyzw=leaning)


def test_a_file_written_with_the_view_as_the_body_loads_upright_with_the_pitch_as_its_aim(tmp_path):
    """Match files imported before bodies stood hold the view's rotation (pitch and yaw) as the body's:
    read, the body keeps the yaw and the aim the pitch, so no reader ever sees a body lying down."""
    views = save_views(tmp_path / "old.npz")
    loaded = load_match(tmp_path / "old.npz")
    assert_stands_and_aims(loaded, 5, 0, 60.0, 30.0)
    assert_stands_and_aims(loaded, 5, 1, -45.0, -120.0)
    np.testing.assert_allclose(loaded.aim_rotations_xyzw(), views, atol=1e-12)


def test_the_aim_survives_a_save_and_a_cut(tmp_path):
    match = duel()
    pitch = np.zeros((len(match.time_s), 2))
    pitch[:, 0] = np.linspace(-30.0, 60.0, len(match.time_s))
    match = dataclasses.replace(match, aim_pitch_deg=pitch)
    save_match(match.until(2.5), tmp_path / "m.npz")
    loaded = load_match(tmp_path / "m.npz")
    np.testing.assert_array_equal(loaded.aim_pitch_deg, pitch[:26])
    np.testing.assert_array_equal(loaded.rotations_xyzw, match.rotations_xyzw[:26])
    save_match(duel(), tmp_path / "plain.npz")  # no aim: the simulator's bots look where they face
    assert load_match(tmp_path / "plain.npz").aim_pitch_deg is None


def test_a_file_that_is_not_a_match_is_refused_in_one_line_naming_it(tmp_path):
    demo = tmp_path / "duel.mvd.gz"
    demo.write_bytes(gzip.compress(b"\x00\x06" + bytes(64)))
    with pytest.raises(ValueError) as refused:
        load_match(demo)
    message = str(refused.value)
    assert message.startswith(f"{demo}: not a match file") and ".npz" in message and "\n" not in message
    assert "pickle" not in message
