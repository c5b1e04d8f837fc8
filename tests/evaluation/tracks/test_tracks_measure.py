"""The frame-aware measure of the TRACKS rig on hand-placed cameras, and the routes through a level's
tightest corridor and its most open place on a hand-built level of two rooms and a corridor."""

from __future__ import annotations

import numpy as np
import pytest

from camdirector.evaluation.tracks.measure import ActorBody, frame_view, shot_pose
from camdirector.evaluation.tracks.route import NavmeshPaths, corridor_and_open_routes, there_and_back, walkable
from camdirector.geometry.camera import Lens
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.style import ShotSize
from camdirector.precompute.tracks.pipeline import precompute_level
from camdirector.precompute.tracks.track_settings import TrackSettings
from tests.precompute.tracks.tiny_levels import boxes, two_rooms

HEIGHT_M = 1.8
FEET = np.zeros(3)
LOOK_AT = np.array([0.0, 0.6 * HEIGHT_M, 0.0])  # where the director looks up the actor (look_at_fraction)


def floor() -> TriMesh:
    return boxes(((-10, -0.2, -10), (10, 0, 10)))


def view(camera_world, look_at_world=LOOK_AT, shot_size=ShotSize.LONG, level=None):
    lens = Lens()
    return frame_view(
        shot_pose(np.asarray(camera_world, float), look_at_world, lens),
        lens,
        FEET,
        ActorBody.of_height(HEIGHT_M),
        shot_size,
        RayScene([level or floor()]),
    )


def test_a_camera_too_close_has_the_actor_in_sight_but_not_in_frame():
    """1 m away at eye height, looking at 0.6 of the height: the feet are under the frame's bottom
    edge (about 35 deg below its centre, the half field of view is 25 deg), nothing hides them."""
    close = view([0.0, 1.7, 1.0])
    assert close.line_of_sight == 1.0
    assert not close.framed_in_frame
    assert close.visible < 1.0


def test_a_camera_at_a_long_shot_distance_has_the_actor_in_sight_and_in_frame():
    far = view([0.0, 1.7, 6.0])
    assert far.line_of_sight == 1.0 and far.visible == 1.0 and far.framed_in_frame


def test_the_framed_extent_is_the_shot_sizes():
    """Aimed at the upper body from 1.6 m: the waist up is in frame (a medium shot's extent), the
    feet are not (a long shot's)."""
    camera, aim = [0.0, 1.4, 1.6], np.array([0.0, 1.35, 0.0])
    assert view(camera, aim, ShotSize.MEDIUM).framed_in_frame
    assert not view(camera, aim, ShotSize.LONG).framed_in_frame
    body = ActorBody.of_height(HEIGHT_M)
    waist_up = body.framed(ShotSize.MEDIUM)
    assert body.points_local[waist_up, 1].min() >= 0.5 * HEIGHT_M - 1e-9 and body.framed(ShotSize.LONG).all()
    assert body.points_local[:, 1].min() == pytest.approx(0.0) and body.points_local[:, 1].max() == pytest.approx(HEIGHT_M)


def test_a_wall_between_hides_the_actor_it_frames():
    wall = boxes(((-10, -0.2, -10), (10, 0, 10)), ((-3, 0, 2.9), (3, 3, 3.0)))
    hidden = view([0.0, 1.7, 6.0], level=wall)
    assert hidden.framed_in_frame and hidden.line_of_sight == 0.0 and hidden.visible == 0.0


@pytest.fixture(scope="module")
def rooms():
    return precompute_level(two_rooms(), TrackSettings(), np.random.default_rng(0))


@pytest.fixture(scope="module")
def rooms_routes(rooms):
    paths = NavmeshPaths(TriMesh(rooms.navmesh_vertices, rooms.navmesh_faces), rooms.settings)
    scene = RayScene([TriMesh(rooms.level_vertices, rooms.level_faces)])
    return corridor_and_open_routes(paths, rooms.skeleton_segments, scene, rooms.agent_height_m, 20.0)


def test_places_are_where_an_actor_can_stand(rooms):
    """On the navmesh with head room: a room's middle and the corridor are; a point beside the
    level is not, nor one under a beam 1 m up."""
    navmesh = RayScene([TriMesh(rooms.navmesh_vertices, rooms.navmesh_faces)])
    beam = boxes(((5.0, 1.0, 0.0), (7.0, 1.2, 12.0)))
    scene = RayScene([TriMesh(rooms.level_vertices, rooms.level_faces), beam])
    points = np.array([[3.0, 0.0, 6.0], [16.0, 0.0, 6.0], [-5.0, 0.0, 6.0], [6.0, 0.0, 6.0]])
    assert walkable(points, navmesh, scene, rooms.agent_height_m).tolist() == [True, True, False, False]


def _length_m(polyline: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(polyline, axis=0), axis=1).sum())


def test_the_tightest_route_runs_through_the_corridor_from_room_to_room(rooms_routes):
    tight = rooms_routes["tightest"]
    x, _, z = tight.place_world
    assert 12.0 < x < 20.0 and 4.8 < z < 7.2, tight.place_world
    assert tight.half_width_m == pytest.approx(1.2, abs=0.02)  # the corridor is 2.4 m wide
    ends_x = sorted(tight.polyline_world[[0, -1], 0])
    assert ends_x[0] < 12.0 and ends_x[1] > 20.0, "it runs through, from one room to the other"
    assert np.linalg.norm(tight.polyline_world - tight.place_world, axis=1).min() == pytest.approx(0.0)
    assert 15.0 <= _length_m(tight.polyline_world) <= 20.5


def test_the_open_route_runs_through_a_room(rooms_routes):
    wide = rooms_routes["open"]
    x, _, z = wide.place_world
    assert (x < 12.0 or x > 20.0) and 0.0 < z < 12.0, wide.place_world
    assert wide.half_width_m == pytest.approx(6.0, abs=0.05)  # the rooms are 12 m across
    assert np.linalg.norm(wide.polyline_world - wide.place_world, axis=1).min() == pytest.approx(0.0)
    assert 15.0 <= _length_m(wide.polyline_world) <= 20.5


def test_a_place_route_is_walked_there_and_back(rooms_routes):
    polyline = rooms_routes["tightest"].polyline_world
    route = there_and_back(polyline)
    np.testing.assert_allclose(route.position_world[0], polyline[0])
    far = int(np.argmax(np.linalg.norm(route.position_world - polyline[0], axis=1)))
    np.testing.assert_allclose(route.position_world[far], polyline[-1], atol=1.4 / 30.0)
    assert np.linalg.norm(route.position_world[-1] - polyline[0]) < 1.4 / 30.0
    assert len(route.time_s) == pytest.approx(2.0 * _length_m(polyline) / 1.4 * 30.0, abs=2)
