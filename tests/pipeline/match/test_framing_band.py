"""Issue 41's framing band and candidate check in the shot builder (shot_builder.py): a FOLLOW
frames its player as a long shot, no place puts a subject taller than the band's top, and a
candidate whose camera shows none of its subjects is not offered (when its shot is chosen, and
on each frame it would be offered: rig.py `_offerable`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from camdirector.geometry.camera import in_frame
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.settings import MatchSettings
from tests.pipeline.match.scenes import LENS, BareRig, Match, facing, melee, player_mesh, run_session
from tests.pipeline.match.test_match_places import block

BODY_M = 1.8  # scenes.py's box players


def apart(t: float):
    """a and b 30 m apart along +z, facing +x: no fight, each one alone."""
    return {"a": ((0.0, 0.0), facing((0, 0), (1, 0))), "b": ((0.0, 30.0), facing((0, 30), (1, 30)))}


def rig_of(walls=(), settings: MatchSettings = MatchSettings()) -> BareRig:
    rig = BareRig(Match({"a": 1, "b": 2}, apart, walls=list(walls)), settings)
    rig.run(0.5)
    return rig


def height_share(rig: BareRig, distance_m: float) -> float:
    """The share of the frame's height a scenes.py player fills at distance_m, level."""
    return BODY_M / (2.0 * distance_m * rig.rig.lens.tan_half_fov_y)


def test_a_follow_at_the_styles_place_is_a_long_shot():
    rig = rig_of()
    builder, moment = rig.rig.builder, rig.rig.buffer.moments[-1]
    camera = builder.cameras(ShotKind.FOLLOW, (0,), moment, default=True)[0][0]
    distance_m = float(np.linalg.norm(camera.positions(moment, [camera.place])[0] - moment.aims_world[0]))
    assert height_share(rig, distance_m) == pytest.approx(MatchSettings().follow_shown_height, rel=0.1)


@pytest.mark.parametrize("top", [0.3, 0.5])
def test_no_place_puts_a_subject_taller_than_the_bands_top(top):
    # a corridor 2 m wide along a's facing: the places beside it are behind its walls, the ones
    # over a's shoulder close to it see it best
    walls = [block((2.0, 1.5, z), (30.0, 3.0, 0.2)) for z in (-1.0, 1.0)]
    # the Toric place (a FOLLOW through a's eyes has no place: first_person.py)
    sizes = {"follow_shown_height": min(top, 0.35), "zoom_shown_height": min(top, 0.35)}  # under the band's top
    settings = MatchSettings(shown_height_max=top, first_person=False, **sizes)
    rig = rig_of(walls, settings)
    builder, moment = rig.rig.builder, rig.rig.buffer.moments[-1]
    shot, score = builder.build(ShotChoice(("a",), ShotKind.FOLLOW, "test"), (0,), moment, [moment], None, None, 0.0)
    assert shot is not None and score >= 0.0
    pose = shot.camera.pose(moment)
    distance_m = float(np.linalg.norm(pose.position_world - moment.aims_world[0]))
    assert height_share(rig, distance_m) <= top + 1e-6


def test_a_candidate_behind_a_wall_is_not_offered_and_one_in_the_open_is():
    rig = rig_of()
    builder, moment = rig.rig.builder, rig.rig.buffer.moments[-1]
    camera = builder.candidate_camera(ShotKind.FOLLOW, (0,), moment)
    assert camera is not None
    # a wall around a's camera hides a from it
    centre = camera.positions(moment, [camera.place])[0]
    walled = rig_of(_box_around(centre))
    assert walled.rig.builder.candidate_camera(ShotKind.FOLLOW, (0,), walled.rig.buffer.moments[-1]) is None


def _box_around(centre: np.ndarray) -> list:
    """Six slabs closing a 1 m cube around centre."""
    slabs = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            offset = np.zeros(3)
            offset[axis] = 0.5 * sign
            size = np.full(3, 1.1)
            size[axis] = 0.05
            slabs.append(block(centre + offset, tuple(size)))
    return slabs


def test_settings_refuse_a_follow_height_over_the_bands_top():
    with pytest.raises(ValueError):
        dataclasses.replace(MatchSettings(), follow_shown_height=0.6, shown_height_max=0.5)


def _offered(match: Match, duration_s: float, ahead: bool) -> list:
    """The answered frames past the delay, streamed through a real Session; with `ahead`, the
    rig's idle work done between frames (camera_ahead.py: the candidates' poses worked out there)."""
    return [s for s in run_session(match, duration_s, idle=ahead)[1] if s.match is not None and not s.match.buffering]


def _shown_shares(candidate, columns: list[int], walls: RayScene) -> np.ndarray:
    """(len(columns),) the share of each player's box points (its corners drawn 10% in, and five
    points up its middle) inside the candidate's frame and not behind a wall: this test's own
    judge of what its monitor shows."""
    mesh = player_mesh()
    middle = np.array([[0.0, y, 0.0] for y in (0.2, 0.6, 0.9, 1.2, 1.6)])
    local = np.vstack([0.9 * mesh.vertices + 0.1 * mesh.vertices.mean(axis=0), middle])
    shares = []
    for column in columns:
        points = candidate.transforms[column].apply(local)
        inside = in_frame(candidate.pose, LENS, points)
        hidden = walls.occluded(np.repeat(candidate.pose.position_world[None], len(points), axis=0), points)
        shares.append(float((inside & ~hidden).mean()))
    return np.array(shares)


@pytest.mark.parametrize("seed", [2, 5])  # melees where the code before offered such poses (6 and 1 of 543)
def test_a_candidate_is_offered_only_on_frames_its_pose_shows_half_its_subjects(seed):
    """Issue 41: candidates are offered only when their camera shows their subjects at the moment
    offered. Their shot is chosen and its place checked at a plan's tick; between ticks the
    players run on past the pillars, and a pose that lost them is not offered on those frames.
    The same candidates whether their poses were worked out in idle moments or on the frame."""
    match = melee(seed=seed, duration_s=16.0, delay_s=10.0)
    ids, walls = list(match.teams), RayScene(match.walls)
    states = _offered(match, 16.0, ahead=True)
    offered = [(s, c) for s in states for c in s.match.candidates if c.shot.subject_ids]
    assert len(offered) > 300
    for state, candidate in offered:
        columns = [ids.index(p) for p in candidate.shot.subject_ids]
        shares = _shown_shares(candidate, columns, walls)
        # the rig's sample points are not these: a margin of a quarter of a body's points
        assert 2 * int((shares >= 0.25).sum()) >= len(columns), (state.time_s, candidate.shot, shares)
    on_the_frame = _offered(match, 16.0, ahead=False)
    assert [[(c.shot, c.pose.position_world.tolist()) for c in s.match.candidates] for s in on_the_frame] == [
        [(c.shot, c.pose.position_world.tolist()) for c in s.match.candidates] for s in states
    ]
