"""Match files (evaluation/match/match_file.py): cutting a match short keeps every per-frame array,
the stats included, and only the events up to the cut; saved and loaded, it is the same."""

from __future__ import annotations

import dataclasses

import numpy as np

from camdirector.evaluation.match.match_file import load_match, save_match
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
