"""What a monitor shows (render/snapshots.py): the snapshot taken of a session for each kind of
view, and the placeholders that say why there is no picture."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from camdirector.infra.channels import ViewQuery
from camdirector.pipeline.match.frame import ReplayedMoment
from camdirector.render.snapshots import TARGET_RGB, TEAM_RGB, render_job, rigid_matrices, scene_geometry
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.table import SessionTable
from tests.service.test_match_sessions import frames as match_frames
from tests.service.test_match_sessions import match_request
from tests.service.wire_client import two_target_request, walk


@pytest.fixture
def table():
    t = SessionTable(ServerSettings(checkpoint_store="off"))
    yield t
    t.close_all()


def _streamed(table: SessionTable, n: int, **request) -> str:
    table.create("s", two_target_request(seed=2, **request))
    for update in walk("s", n):
        table.frame(update)
    return "s"


def test_a_program_view_is_the_last_pose_with_every_moving_part_where_it_is_now(table):
    session = table.held[_streamed(table, 20)].session
    job = render_job(session, ViewQuery())
    assert job.placeholder is None and job.frame == 20 and job.pose is session.last_state.pose
    assert job.moving_ids == ("object:cart", "target:a", "target:b")
    cart = session.dynamic["cart"][1]
    np.testing.assert_array_equal(job.positions_world[0], cart.position_world)
    np.testing.assert_allclose(rigid_matrices(job)[1], session.target_transforms[0].matrix(), atol=1e-12)
    assert job.size_px == (320, 180) and job.lens.aspect == pytest.approx(16 / 9)
    assert job.lens.vertical_fov_deg == session.last_state.pose.vertical_fov_deg


def test_the_meshes_are_the_world_then_the_moving_parts_in_their_own_frames(table):
    session = table.held[_streamed(table, 1)].session
    parts = scene_geometry(session).parts
    assert [p.part_id for p in parts] == ["static:0", "object:cart", "target:a", "target:b"]
    assert [p.moving for p in parts] == [False, True, True, True]
    np.testing.assert_allclose(parts[0].vertices.mean(axis=0), [1.5, 1.5, 4.0], atol=1e-6)  # the pillar, world frame
    assert parts[2].rgb == TARGET_RGB and scene_geometry(session).has_world


def test_no_pose_yet_a_missing_cut_and_a_candidate_outside_a_match_are_placeholders(table):
    table.create("s", two_target_request(seed=2))
    session = table.held["s"].session
    assert render_job(session, ViewQuery()).placeholder == "no camera yet: no frame answered"
    _ = [table.frame(u) for u in walk("s", 3)]
    assert render_job(session, ViewQuery(shot="cut_after")).placeholder == "no cut yet"
    candidate = render_job(session, ViewQuery(shot="candidate", subjects=("a",)))
    assert candidate.placeholder == "candidate shots are a MATCH session's" and candidate.pose is None


def test_the_cut_views_show_the_two_poses_around_the_last_cut(table):
    session = table.held[_streamed(table, 10)].session
    before_pose, walker_before = session.last_state.pose, session.target_transforms[0]
    assert session.last_cut is None  # the first pose is a cut from nothing: no before picture
    # A new composition cuts to it on the next frame (tests/service/test_director.py).
    table.update_style(
        pb.UpdateStyleRequest(
            session_id="s", style=pb.Style(screen_a=pb.ScreenPoint(x=-0.6, y=0.2), screen_b=pb.ScreenPoint(x=0.6, y=0.2))
        )
    )
    table.frame(next(walk("s", 1, start_frame=11)))
    cut = session.last_cut
    assert cut is not None and cut.frame == 11 and session.last_state.cut
    before, after = render_job(session, ViewQuery(shot="cut_before")), render_job(session, ViewQuery(shot="cut_after"))
    assert (before.frame, after.frame) == (cut.frame - 1, cut.frame)
    assert after.pose is cut.pose_after and before.pose is cut.pose_before is before_pose
    assert not np.allclose(before.pose.position_world, after.pose.position_world)
    # the walking target where each frame had it; the sliding cart as of the cut in both
    walker = before.moving_ids.index("target:a")
    np.testing.assert_array_equal(before.positions_world[walker], walker_before.position_world)
    np.testing.assert_array_equal(after.positions_world[walker], session.target_transforms[0].position_world)
    assert not np.allclose(before.positions_world[walker], after.positions_world[walker])
    np.testing.assert_array_equal(before.positions_world[0], after.positions_world[0])


def test_a_match_candidate_view_is_the_candidates_camera_and_players_show_at_the_program_moment(table):
    table.create("m", match_request(delay_s=1.0))
    session = table.held["m"].session
    updates = list(match_frames("m", 20))
    table.frame(updates[0])
    assert render_job(session, ViewQuery()).placeholder == "buffering: the broadcast delay is still filling, no camera yet"
    for update in updates[1:] + list(match_frames("m", 40, start=20)):
        table.frame(update)
    state = session.last_state
    assert state.pose is not None and state.match.candidates, "the match offers candidates once it answers"
    candidate = state.match.candidates[0]
    job = render_job(session, ViewQuery(shot="candidate", subjects=tuple(reversed(candidate.shot.subject_ids))))
    assert job.pose is candidate.pose and job.frame == state.frame
    # Players are drawn where the program's moment has them, a second behind the newest frame.
    program = session.rig.program_transforms
    latest = session.target_transforms
    rows = [job.moving_ids.index(f"target:{t.id}") for t in session.targets]
    np.testing.assert_array_equal(job.positions_world[rows], [tf.position_world for tf in program])
    assert not np.allclose(job.positions_world[rows], [tf.position_world for tf in latest])
    # a REPLAY candidate's monitor shows its kill's moment: its frame and the players there
    kill_moment = session.rig.buffer.at(state.time_s - 0.5)
    replay = dataclasses.replace(
        candidate, replay_of=ReplayedMoment(kill_moment.frame, kill_moment.time_s), transforms=kill_moment.transforms
    )
    state.match.candidates[0] = replay
    job = render_job(session, ViewQuery(shot="candidate", subjects=candidate.shot.subject_ids))
    assert job.frame == kill_moment.frame and job.frame != state.frame
    np.testing.assert_array_equal(job.positions_world[rows], [tf.position_world for tf in kill_moment.transforms])
    assert not np.allclose(job.positions_world[rows], [tf.position_world for tf in program])
    gone = render_job(session, ViewQuery(shot="candidate", subjects=("a0", "nobody")))
    assert gone.placeholder == "no candidate shot of a0, nobody now"
    assert {p.rgb for p in scene_geometry(session).parts} == {TEAM_RGB[0], TEAM_RGB[1]}
