"""The places test (geometry/inside.py): a hand-built room and a real Quake map."""

from __future__ import annotations

import gzip
import pickle
from pathlib import Path

import numpy as np

from camdirector.geometry.bsp import bsp_entities, from_bsp
from camdirector.geometry.inside import LevelInterior, Place, open_above, sphere_directions
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.quake_frame import points_to_world

MAPS = Path(__file__).resolve().parents[1] / "data" / "real_maps"


def room_with_slab() -> TriMesh:
    """A 10 x 4 x 10 m room (its faces turned inward, as a level's face its playable space) centred
    on (0, 2, 0), with a 1 m thick wall slab across x = 2 (its faces outward, into the room)."""
    room = box((10.0, 4.0, 10.0))
    slab = box((1.0, 4.0, 10.0))
    return TriMesh(
        np.concatenate([room.vertices + [0.0, 2.0, 0.0], slab.vertices + [2.0, 2.0, 0.0]]),
        np.concatenate([room.faces[:, ::-1], slab.faces + len(room.vertices)]).astype(np.int32),
    )


def test_a_box_room_has_its_centre_inside_its_wall_slab_solid_and_the_world_around_it_outside():
    interior = LevelInterior(room_with_slab())
    points = np.array(
        [
            [0.0, 2.0, 0.0],  # the room's centre
            [-4.8, 0.2, 4.8],  # a corner of the room, near the floor
            [2.0, 2.0, 0.0],  # inside the slab
            [2.4, 3.9, -4.9],  # inside the slab, at a corner of the room
            [0.0, 6.0, 0.0],  # above the room
            [20.0, 2.0, 0.0],  # beside it
        ]
    )
    assert interior.places(points).tolist() == [
        Place.INSIDE,
        Place.INSIDE,
        Place.SOLID,
        Place.SOLID,
        Place.OUTSIDE,
        Place.OUTSIDE,
    ]
    assert interior.bad(points).tolist() == [False, False, True, True, True, True]


def test_a_point_in_the_void_between_two_rooms_is_solid():
    # two rooms side by side, 2 m of void between their walls (a Quake map has no faces there)
    room = box((4.0, 3.0, 4.0))
    vertices = np.concatenate([room.vertices + [-3.0, 1.5, 0.0], room.vertices + [3.0, 1.5, 0.0]])
    faces = np.concatenate([room.faces[:, ::-1], room.faces[:, ::-1] + len(room.vertices)]).astype(np.int32)
    interior = LevelInterior(TriMesh(vertices, faces))
    assert interior.places([[0.0, 1.5, 0.0], [-3.0, 1.5, 0.0], [3.0, 1.5, 0.0]]).tolist() == [
        Place.SOLID,
        Place.INSIDE,
        Place.INSIDE,
    ]


def test_an_open_level_reads_inside_above_its_floor_though_most_rays_escape():
    # a floor with a low wall, open at the top and the sides (as Recast's terrains are)
    floor, wall = box((20.0, 0.2, 20.0)), box((0.5, 3.0, 20.0))
    mesh = TriMesh(
        np.concatenate([floor.vertices + [0.0, -0.1, 0.0], wall.vertices + [5.0, 1.5, 0.0]]),
        np.concatenate([floor.faces, wall.faces + len(floor.vertices)]).astype(np.int32),
    )
    interior = LevelInterior(mesh)
    assert interior.places([[0.0, 2.0, 0.0], [0.0, -0.1, 0.0], [5.0, 1.0, 0.0]]).tolist() == [
        Place.INSIDE,
        Place.SOLID,  # in the floor
        Place.SOLID,  # in the wall
    ]


def terrain() -> TriMesh:
    """An outdoor terrain: a 40 x 40 m ground with a 6 m hill (a pyramid), every face turned up,
    nothing above it (Recast's undulating is such a level)."""
    vertices = np.array(
        [[-20.0, 0.0, -20.0], [20.0, 0.0, -20.0], [20.0, 0.0, 20.0], [-20.0, 0.0, 20.0], [0.0, 6.0, 0.0]], dtype=np.float64
    )
    faces = np.array([[0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]], dtype=np.int32)  # counter-clockwise seen from above
    return TriMesh(vertices, faces)


def test_a_level_open_to_the_sky_has_no_top_but_one_with_ceilings_keeps_its_box():
    sky = LevelInterior(terrain())
    assert open_above(terrain()) and not open_above(room_with_slab())
    # above the hill's top: the sky a camera may stand in; below the ground or beside the level: outside
    assert sky.places([[10.0, 9.0, 10.0], [0.0, 8.0, 0.0], [10.0, -1.0, 10.0], [30.0, 2.0, 0.0]]).tolist() == [
        Place.INSIDE,
        Place.INSIDE,
        Place.OUTSIDE,
        Place.OUTSIDE,
    ]
    assert LevelInterior(room_with_slab()).places([[0.0, 6.0, 0.0]]).tolist() == [Place.OUTSIDE]


def test_directions_are_unit_and_spread_over_the_sphere():
    d = sphere_directions(14)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert abs(d.mean(axis=0)).max() < 0.1  # no side favoured
    assert np.abs(d).max() < np.cos(np.radians(20.0))  # none within 20 degrees of an axis


def test_the_interior_is_built_once_per_mesh_and_pickles_as_its_mesh():
    mesh = room_with_slab()
    interior = LevelInterior.of(mesh)
    assert LevelInterior.of(mesh) is interior
    assert LevelInterior.of(room_with_slab()) is not interior
    again = pickle.loads(pickle.dumps(interior))
    points = np.array([[0.0, 2.0, 0.0], [2.0, 2.0, 0.0], [0.0, 9.0, 0.0]])
    assert again.places(points).tolist() == interior.places(points).tolist()


def test_on_dm2_the_spawn_points_are_inside_and_points_below_their_floors_or_above_the_map_are_not():
    data = gzip.decompress((MAPS / "dm2.bsp.gz").read_bytes())
    interior = LevelInterior(from_bsp(data))
    origins = [
        [float(v) for v in e["origin"].split()] for e in bsp_entities(data) if e.get("classname") == "info_player_deathmatch"
    ]
    assert len(origins) >= 4
    chests = points_to_world(origins) + [0.0, 0.3, 0.0]  # a player's origin is 24 units (0.75 m) above its feet
    assert (interior.places(chests) == Place.INSIDE).all()
    below = chests - [0.0, 1.5, 0.0]  # under the floor the player stands on
    assert interior.bad(below).all()
    above = chests.copy()
    above[:, 1] = interior.high[1] + 1.0
    assert (interior.places(above) == Place.OUTSIDE).all()


def test_every_player_of_a_real_duel_is_inside_bravado():
    from camdirector.matches.quakeworld_mvd import import_mvd

    demo = Path(__file__).resolve().parents[1] / "data" / "real_matches" / "duel_holy_vs_dago_bravado_20240426-1659.mvd.gz"
    match = import_mvd(gzip.decompress(demo.read_bytes()), level="bravado")
    interior = LevelInterior(from_bsp(gzip.decompress((MAPS / "bravado.bsp.gz").read_bytes())))
    chests = (match.positions_world[::30] + [0.0, 0.9, 0.0]).reshape(-1, 3)  # every half second, chest high
    assert len(chests) > 2000
    assert (interior.places(chests) == Place.INSIDE).all()


def test_reach_is_the_share_of_a_segment_before_the_level():
    interior = LevelInterior(room_with_slab())
    reach = interior.reach([0.0, 2.0, 0.0], [[1.0, 2.0, 0.0], [3.0, 2.0, 0.0], [-2.0, 2.0, 0.0]])
    assert reach[0] == 1.0 and reach[2] == 1.0  # open room
    assert abs(reach[1] - 0.5) < 1e-5  # the slab's face at x = 1.5
