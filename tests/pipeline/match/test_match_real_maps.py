"""What real maps asked of our director (issue 29): no fight through a wall, a player on the move
rather than an overview of walls (and an overview of nobody on air worth only what it shows,
issue 41), and a camera that a wall comes between it and its subject pulled in front of the wall
(and back out no faster than pull_regrow_m_s)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from camdirector.geometry.camera import CameraPose, level_look_rotation
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.match.frame import ShotKind
from camdirector.pipeline.match.interest import fight_matrix
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import Place, ToricCamera
from camdirector.pipeline.style import Rig, Style
from tests.pipeline.match.scenes import EYE_M, LENS, BareRig, Match, facing, run_session, yaw_quat
from tests.pipeline.match.test_match_places import block


def moment_of(places: dict[str, tuple[float, float]], faces: dict[str, tuple[float, float]]) -> Moment:
    """Players standing at (x, z), facing the given points, all alive."""
    ids = list(places)
    yaws = [facing(places[p], faces[p]) for p in ids]
    transforms = [RigidTransform(np.array([places[p][0], 0.0, places[p][1]]), yaw_quat(y)) for p, y in zip(ids, yaws)]
    feet = np.array([t.position_world for t in transforms])
    forward = np.array([[np.sin(y), 0.0, np.cos(y)] for y in yaws])
    return Moment(0, 0.0, transforms, feet + [0.0, EYE_M, 0.0], feet, forward, np.ones(len(ids), dtype=bool))


FACE_OFF = moment_of({"a": (0.0, 0.0), "b": (0.0, 8.0)}, {"a": (0.0, 8.0), "b": (0.0, 0.0)})


@pytest.mark.parametrize(
    "wall, fight",
    [(None, True), (block((0.0, 1.5, 4.0), (6.0, 3.0, 0.2)), False), (block((5.0, 1.5, 4.0), (2.0, 3.0, 0.2)), True)],
)
def test_opponents_face_to_face_fight_only_when_no_wall_stands_between_them(wall, fight):
    scene = RayScene([wall]) if wall is not None else RayScene([block((50.0, 0.0, 50.0), (1.0, 1.0, 1.0))])
    scores = fight_matrix(FACE_OFF, np.array([0, 1]), MatchSettings(), scene)
    assert (scores[0, 1] > 0.5) == fight and scores[0, 1] == scores[1, 0]
    assert (fight_matrix(FACE_OFF, np.array([0, 1]), MatchSettings()) > 0.5)[0, 1]  # no scene: in sight


def test_players_apart_behind_walls_are_followed_on_the_move_not_shown_in_an_overview():
    # two opponents 10 m apart, a wall between them the whole time, walking toward it
    def script(t: float):
        return {"a": ((-5.0, 0.2 * t), facing((-5, 0), (5, 0))), "b": ((5.0, -0.2 * t), facing((5, 0), (-5, 0)))}

    wall = block((0.0, 2.0, 0.0), (0.3, 4.0, 40.0))
    match = Match({"a": 1, "b": 2}, script, walls=[wall], style=Style(rig=Rig.MATCH))
    _, states = run_session(match, 6.0)
    kinds = {s.match.shot.kind for s in states[1:]}
    assert kinds == {ShotKind.FOLLOW}, kinds
    assert all("on the move" in s.match.shot.reason for s in states[1:])


def test_players_beyond_fighting_range_are_followed_nearest_an_opponent_first():
    """No fight anywhere (a duel's players 60-90 m apart): a player, not an overview of nobody;
    the one nearer an opponent first."""

    def script(t: float):
        return {"a": ((0.0, 0.0), 0.0), "b": ((0.0, 60.0), 0.0), "c": ((0.0, -30.0), 0.0)}

    match = Match({"a": 1, "b": 2, "c": 1}, script, style=Style(rig=Rig.MATCH))
    _, states = run_session(match, 3.0)
    assert {s.match.shot.kind for s in states} == {ShotKind.FOLLOW}
    assert states[0].match.shot.subject_ids in (("a",), ("b",))  # 60 m from an opponent; c is 90 m from b
    assert all("on the move" in s.match.shot.reason for s in states)


def looking(from_world: tuple[float, float, float], at_world: tuple[float, float, float]) -> CameraPose:
    position = np.array(from_world, dtype=float)
    return CameraPose(position, level_look_rotation(position, at_world, (0.0, 0.0), LENS), LENS.vertical_fov_deg)


def test_an_overview_of_nobody_on_air_is_worth_the_share_of_its_best_shown_living_player():
    """What the planner scales an overview of nobody's interest by (planned.py `_overview_shows`):
    the best-shown living player's share framed and seen; a wall, a look away or death shows
    nobody."""

    def script(t: float):
        return {"a": ((0.0, 0.0), 0.0), "b": ((0.0, 30.0), 0.0)}

    wall = block((0.0, 1.5, 6.0), (40.0, 12.0, 0.2))  # across the level between a (z 0) and z 12
    director = BareRig(Match({"a": 1, "b": 2}, script, walls=[wall]), MatchSettings()).rig.director
    moment = moment_of({"a": (0.0, 0.0), "b": (0.0, 30.0)}, {"a": (0.0, 30.0), "b": (0.0, 0.0)})
    assert director._overview_shows(moment, looking((0.0, 6.0, -10.0), (0.0, 1.0, 0.0))) == 1.0  # a, whole
    assert director._overview_shows(moment, looking((0.0, 6.0, -10.0), (0.0, 1.0, -30.0))) == 0.0  # looking away
    assert director._overview_shows(moment, looking((0.0, 3.0, 14.0), (0.0, 1.0, 0.0))) == 0.0  # a behind the wall
    b_dead = dataclasses.replace(moment, alive=np.array([True, False]))
    assert director._overview_shows(b_dead, looking((0.0, 3.0, 24.0), (0.0, 1.0, 30.0))) == 0.0  # only b, dead, framed
    nobody = dataclasses.replace(moment, alive=np.zeros(2, dtype=bool))
    assert director._overview_shows(nobody, looking((0.0, 6.0, -10.0), (0.0, 1.0, -30.0))) == 1.0  # nobody to show


def pulled_camera(wall_z: float) -> tuple[ToricCamera, Moment, RayScene]:
    """A FOLLOW camera on a, 4.3 m from its aim point up and behind it (z = -3.1), and a wall wall_z
    m behind a (across the line from a to the camera)."""
    moment = moment_of({"a": (0.0, 0.0), "b": (0.0, 30.0)}, {"a": (0.0, 30.0), "b": (0.0, 0.0)})
    camera = ToricCamera(ShotKind.FOLLOW, 0, None, Style(rig=Rig.MATCH), LENS, Place(0.05, 0.5, 1.0))
    camera.gaze_room_m = 10.0
    scene = RayScene([block((0.0, 1.5, wall_z), (40.0, 12.0, 0.2))])
    return camera, moment, scene


def never_near(positions_world: np.ndarray) -> np.ndarray:
    """A readable clearance (shot_builder.py readable_clearance) that no place comes under."""
    return np.ones(len(positions_world))


def test_a_wall_between_the_camera_and_its_subject_pulls_it_in_front_and_it_goes_back_slowly():
    camera, moment, scene = pulled_camera(-2.5)  # the wall's near face at z = -2.4
    free = camera.pose(moment)
    a = moment.aims_world[0]
    assert free.position_world[2] < -2.6, "the place stands behind the wall"
    assert scene.occluded(free.position_world[None], a[None])[0]
    pulled, was = camera.pulled_in(moment, free, True, scene, 0.0, 0.3, 2.0, never_near)
    assert was and not scene.occluded(pulled.position_world[None], a[None])[0]
    reach = np.linalg.norm(pulled.position_world - a)
    assert pulled.position_world[2] > -2.4 and camera.reach_m == pytest.approx(reach)
    # the wall gone, the camera goes back out at 2 m/s, not at once
    open_scene = RayScene([block((50.0, 0.0, 50.0), (1.0, 1.0, 1.0))])
    later, was = camera.pulled_in(moment, free, False, open_scene, 0.1, 0.3, 2.0, never_near)
    assert was and np.linalg.norm(later.position_world - a) == pytest.approx(reach + 0.2)
    back, was = camera.pulled_in(moment, free, False, open_scene, 100.0, 0.3, 2.0, never_near)
    assert not was and np.allclose(back.position_world, free.position_world) and camera.reach_m is None
    # a camera that sees its subject well stays where it is, wall or no wall
    assert camera.pulled_in(moment, free, False, scene, 0.1, 0.3, 2.0, never_near) == (free, False)
