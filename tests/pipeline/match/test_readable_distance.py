"""Issue 41's readable distance (shot_builder.py readable_clearance): a program camera keeps far
enough from its framed subjects that the widest lens shows them under the framing band's top. A
camera pulled in front of a wall stops there (shots.py pulled_in), one whose place has come nearer
steps back along its line (stepped_back), and a DUEL's place is chosen no nearer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from camdirector.geometry.camera import CameraPose, Lens, level_look_rotation, project_to_screen
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shot_builder import readable_clearance
from camdirector.pipeline.match.shots import Place, ToricCamera
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.pipeline.style import Rig, Style
from tests.pipeline.match.scenes import LENS, BareRig, Match, facing, player_mesh
from tests.pipeline.match.test_match_places import block
from tests.pipeline.match.test_match_real_maps import moment_of, pulled_camera

SETTINGS = MatchSettings(first_person=False)  # the Toric camera's distances (not a player's eyes: first_person.py)
OPEN = RayScene([block((50.0, 0.0, 50.0), (1.0, 1.0, 1.0))])  # nothing near the players


def clearance_of(scene: RayScene, moment, subjects=(0,)):
    visibility = SubjectVisibility(scene, [player_mesh(), player_mesh()], 16, np.random.default_rng(0))
    return readable_clearance(visibility, LENS, SETTINGS, subjects, moment)


def screen_height(pose: CameraPose, points_world: np.ndarray) -> float:
    """The points' extent on the screen's vertical axis, share of the frame's height."""
    y = project_to_screen(pose, Lens(pose.vertical_fov_deg, LENS.aspect), points_world)[:, 1]
    return float((y.max() - y.min()) / 2.0)


@pytest.mark.parametrize("camera_y", [0.9, 0.0, 2.5])
def test_from_the_readable_distance_the_widest_lens_shows_a_body_under_the_bands_top(camera_y):
    moment = moment_of({"a": (0.0, 0.0), "b": (0.0, 30.0)}, {"a": (1.0, 0.0), "b": (1.0, 30.0)})
    clearance = clearance_of(OPEN, moment)
    # along +x from a's axis at a height, the first point where clearance reaches 0
    xs = np.linspace(0.0, 5.0, 5001)
    x = xs[np.argmax(clearance(np.stack([xs, np.full_like(xs, camera_y), np.zeros_like(xs)], axis=1)) >= 0.0)]
    camera = np.array([x, camera_y, 0.0])
    corners = moment.transforms[0].apply(player_mesh().vertices)  # (8, 3) the box
    centre = corners.mean(axis=0)
    pose = CameraPose(camera, level_look_rotation(camera, centre, (0.0, 0.0), LENS), SETTINGS.widen_max_fov_deg)
    assert screen_height(pose, corners) <= SETTINGS.shown_height_max + 0.01
    # a little nearer, level with its middle, it is over the band's top
    if camera_y == 0.9:
        nearer = CameraPose(camera - [0.3, 0.0, 0.0], pose.rotation_xyzw, SETTINGS.widen_max_fov_deg)
        assert screen_height(nearer, corners) > SETTINGS.shown_height_max


def test_a_camera_pulled_in_toward_a_subject_near_a_wall_stops_at_the_readable_distance():
    camera, moment, scene = pulled_camera(-0.5)  # a wall 0.5 m behind a, between it and the camera 4.3 m off
    free = camera.pose(moment)
    a = moment.aims_world[0]
    clearance = clearance_of(scene, moment)
    assert clearance(free.position_world[None])[0] > 0.0
    pulled, was = camera.pulled_in(moment, free, True, scene, 0.0, 0.3, 2.0, clearance)
    assert was
    assert 0.0 <= clearance(pulled.position_world[None])[0] < 0.01  # not in front of the wall, 0.3 m from a's axis
    along = (pulled.position_world - a) / np.linalg.norm(pulled.position_world - a)
    assert np.allclose(along, (free.position_world - a) / np.linalg.norm(free.position_world - a))
    # a wall far enough: in front of it as before
    camera, moment, scene = pulled_camera(-2.5)
    free = camera.pose(moment)
    pulled, was = camera.pulled_in(moment, free, True, scene, 0.0, 0.3, 2.0, clearance_of(scene, moment))
    assert was and not scene.occluded(pulled.position_world[None], moment.aims_world[0][None])[0]


def over_the_shoulder() -> tuple[ToricCamera, object]:
    """A DUEL camera over a's shoulder (the start of the arc), b 6 m ahead of a: 1.4 m behind a's axis."""
    moment = moment_of({"a": (0.0, 0.0), "b": (0.0, 6.0)}, {"a": (0.0, 6.0), "b": (0.0, 0.0)})
    camera = ToricCamera(ShotKind.DUEL, 0, 1, Style(rig=Rig.MATCH), LENS, Place(0.01, math.radians(45.0), 1.0))
    return camera, moment


def test_a_camera_whose_place_comes_too_near_steps_back_along_its_line_to_the_readable_distance():
    camera, moment = over_the_shoulder()
    pose = camera.pose(moment)
    clearance = clearance_of(OPEN, moment, (0, 1))
    assert clearance(pose.position_world[None])[0] < 0.0, "the place stands at a's back"
    back = camera.stepped_back(moment, pose, OPEN, 0.3, clearance)
    assert 0.0 <= clearance(back.position_world[None])[0] < 0.01
    a = moment.aims_world[0]
    along = (back.position_world - a) / np.linalg.norm(back.position_world - a)
    assert np.allclose(along, (pose.position_world - a) / np.linalg.norm(pose.position_world - a))
    # a wall just behind the place: no farther than its margin, nearer than the readable distance
    wall = RayScene([block((0.0, 1.5, pose.position_world[2] - 0.5), (6.0, 12.0, 0.2))])  # its face 0.4 m behind
    walled = camera.stepped_back(moment, pose, wall, 0.3, clearance)
    hit_m = float(wall.first_hit(a, along[None])[0])
    assert np.linalg.norm(walled.position_world - a) <= hit_m - 0.3 + 1e-6
    assert np.linalg.norm(walled.position_world - a) > np.linalg.norm(pose.position_world - a)


def test_a_camera_far_enough_is_not_moved():
    camera, moment = over_the_shoulder()
    camera.place = camera.goal = Place(0.5, math.radians(45.0), 1.0)  # halfway along the arc, beside the pair
    pose = camera.pose(moment)
    assert camera.stepped_back(moment, pose, OPEN, 0.3, clearance_of(OPEN, moment, (0, 1))) is pose


def face_off(t: float):
    """a and b face each other 8 m apart along +z."""
    return {"a": ((0.0, 0.0), facing((0, 0), (0, 8))), "b": ((0.0, 8.0), facing((0, 8), (0, 0)))}


def test_a_duels_place_is_readable_or_steps_back_to_it_before_a_wall():
    # a corridor 3 m wide and 3 m high along the pair, closed 0.6 m behind each: the places that see
    # both best are over a shoulder, under a metre from a player, with no room to step back
    walls = [block((x, 1.5, 4.0), (0.2, 6.0, 12.0)) for x in (-1.5, 1.5)]
    walls += [block((0.0, 1.5, z), (3.2, 6.0, 0.2)) for z in (-0.6, 8.6)]
    walls.append(block((0.0, 3.0, 4.0), (3.2, 0.2, 12.0)))
    rig = BareRig(Match({"a": 1, "b": 2}, face_off, walls=walls), SETTINGS)
    rig.run(0.5)
    builder, moment = rig.rig.builder, rig.rig.buffer.moments[-1]
    shot, _ = builder.build(ShotChoice(("a", "b"), ShotKind.DUEL, "test"), (0, 1), moment, [moment], None, None, 0.0)
    assert shot is not None and isinstance(shot.camera, ToricCamera)
    pose = shot.camera.pose(moment)
    clearance = readable_clearance(builder.visibility, LENS, SETTINGS, (0, 1), moment)
    back = shot.camera.stepped_back(moment, pose, rig.rig.ray_scene, SETTINGS.pull_margin_m, clearance)
    assert clearance(back.position_world[None])[0] >= 0.0
