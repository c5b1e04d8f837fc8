"""eval-match's count of cameras outside the level or inside solid, of the program's moves
through walls (measure.py `places_count`, `sweeps_through_walls`), on a room with a wall slab,
and of its jumps that no cut flags (`jumps_without_cut`)."""

from __future__ import annotations

import numpy as np

from camdirector.evaluation.match.measure import (
    JUMP_SPEED_M_S,
    Program,
    jumps_without_cut,
    places_count,
    sweeps_through_walls,
)
from camdirector.geometry.inside import LevelInterior
from tests.geometry.test_inside import room_with_slab


def program_at(positions: list[list[float]], cuts: list[bool]) -> Program:
    n = len(positions)
    return Program(
        index=np.arange(n),
        time_s=np.arange(n) / 30.0,
        position=np.array(positions, dtype=np.float64),
        rotation=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
        vertical_fov_deg=np.full(n, 50.0),
        cut=np.array(cuts),
        shot_id=np.cumsum(cuts),
        subjects=[()] * n,
        overview=np.zeros(n, dtype=bool),
        shown_index=np.arange(n),
        replay=np.zeros(n, dtype=bool),
    )


def test_places_count_tells_outside_from_solid():
    interior = LevelInterior(room_with_slab())
    points = np.array([[0.0, 2.0, 0.0], [2.0, 2.0, 0.0], [0.0, 9.0, 0.0], [30.0, 2.0, 0.0], [-3.0, 1.0, 3.0]])
    assert places_count(interior, points) == {"outside": 2, "solid": 1, "poses": 5}
    assert places_count(interior, np.zeros((0, 3))) == {"outside": 0, "solid": 0, "poses": 0}


def test_a_move_through_the_slab_is_a_sweep_unless_it_is_a_cut():
    interior = LevelInterior(room_with_slab())
    # in the room, a move within it, across the slab (a sweep), held still, back across at a cut
    positions = [[0.0, 2.0, 0.0], [1.0, 2.0, 0.0], [3.5, 2.0, 0.0], [3.5, 2.0, 0.0], [0.0, 2.0, 1.0]]
    assert sweeps_through_walls(interior, program_at(positions, [True, False, False, False, False])) == 2
    assert sweeps_through_walls(interior, program_at(positions, [True, False, True, False, True])) == 0


def test_a_move_faster_than_a_camera_moves_is_a_jump_unless_it_is_a_cut():
    # at 30 Hz: 1 m a frame (30 m/s, a fast follow), then 3 m (90 m/s: a jump), held, 20 m back at a cut
    # (uncut in the second program: a jump too)
    step_m = JUMP_SPEED_M_S / 30.0
    far_x = 1.0 + 1.5 * step_m
    positions = [[0.0, 2.0, 0.0], [1.0, 2.0, 0.0], [far_x, 2.0, 0.0], [far_x, 2.0, 0.0], [-19.0, 2.0, 0.0]]
    assert jumps_without_cut(program_at(positions, [True, False, False, False, True])) == 1
    assert jumps_without_cut(program_at(positions, [True, False, True, False, False])) == 1
    assert jumps_without_cut(program_at(positions[:2], [True, False])) == 0
