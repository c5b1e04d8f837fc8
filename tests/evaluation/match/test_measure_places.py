"""eval-match's count of cameras outside the level or inside solid, and of the program's moves
through walls (measure.py `places_count`, `sweeps_through_walls`), on a room with a wall slab."""

from __future__ import annotations

import numpy as np

from camdirector.evaluation.match.measure import Program, places_count, sweeps_through_walls
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
