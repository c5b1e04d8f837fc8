"""MATCH sessions on a real server, over both transports: the delay's buffering and delayed
answers, the shot and candidates, TakeShot held until released, each kind of bad match input
(with a healthy session beside them that must not notice), recording and replay of a take."""

from __future__ import annotations

import math

import grpc
import pytest

from camdirector.v1 import director_pb2 as pb
from camdirector.worker.replay import replay
from tests.service.test_bad_input import canary, expect  # noqa: F401  (canary is a fixture)
from tests.service.wire_client import capsule_target

RATE_HZ = 30.0
PLAYERS = ("a0", "a1", "b0", "b1")


def match_request(delay_s: float, players=PLAYERS, record: bool = False, **style) -> pb.CreateSessionRequest:
    targets = []
    for i, player in enumerate(players):
        target = capsule_target(player, position=(2.0 * i, 0.9, 0.0), aim=(0.0, 0.6, 0.0))
        target.team = 0 if player.startswith("a") else 1
        targets.append(target)
    return pb.CreateSessionRequest(
        targets=targets, delay_s=delay_s, seed=3, record=record, style=pb.Style(rig=pb.RIG_MATCH, **style)
    )


def frames(session_id: str, count: int, start: int = 0, kill_at: dict[int, tuple[str, str]] | None = None):
    """Two pairs of opponents circling each other; `kill_at`: frame -> (attacker, victim)."""
    for k in range(start, start + count):
        t = k / RATE_HZ
        update = pb.FrameUpdate(session_id=session_id, frame=k + 1, time_s=t)
        for i, player in enumerate(PLAYERS):
            centre = (0.0, 0.0) if i % 2 == 0 else (8.0, 0.0)
            angle = 0.4 * t + (math.pi if player.startswith("b") else 0.0)
            x, z = centre[0] + 2.5 * math.cos(angle), centre[1] + 2.5 * math.sin(angle)
            yaw = math.atan2(centre[0] - x, centre[1] - z)  # facing the middle: the opponent
            update.states.add(
                id=player,
                transform=pb.Transform(
                    position=pb.Vec3(x=x, y=0.9, z=z), rotation=pb.Quat(y=math.sin(yaw / 2), w=math.cos(yaw / 2))
                ),
            )
        if kill_at and k in kill_at:
            attacker, victim = kill_at[k]
            update.events.add(kind=pb.EVENT_KILL, actor_id=attacker, other_actor_id=victim)
        yield update


def test_delay_buffers_then_answers_for_the_moment_delay_earlier(raw):
    session_id = raw.call("CreateSession", match_request(delay_s=2.0)).session_id
    replies = raw.stream(list(frames(session_id, 150, kill_at={100: ("a0", "b0")})))
    buffering = [u for u in replies if u.buffering]
    assert buffering and all(not u.HasField("pose") for u in buffering)
    answered = [u for u in replies if not u.buffering]
    assert len(buffering) + len(answered) == 150
    assert all(u.HasField("pose") and u.shot.subject_ids and u.shot.reason for u in answered)
    # The reply to the frame of game time t is the program at t - 2 s.
    last_sent_time_s = 149 / RATE_HZ
    assert answered[-1].time_s == pytest.approx(last_sent_time_s - 2.0, abs=1.0 / RATE_HZ + 1e-9)
    assert answered[0].cut and answered[0].candidates
    assert all(c.shot.subject_ids or c.shot.kind == pb.SHOT_OVERVIEW for u in answered for c in u.candidates)
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))


def test_a_take_is_held_until_released(raw):
    session_id = raw.call("CreateSession", match_request(delay_s=0.0)).session_id
    raw.stream(list(frames(session_id, 30)))
    taken = raw.call("TakeShot", pb.TakeShotRequest(session_id=session_id, subject_ids=["a1", "b1"]))
    assert list(taken.shot.subject_ids) == ["a1", "b1"] and taken.shot.kind == pb.SHOT_DUEL
    held = raw.stream(list(frames(session_id, 300, start=30)))  # 10 s: past the longest shot
    assert all(list(u.shot.subject_ids) == ["a1", "b1"] for u in held[1:])
    released = raw.call("TakeShot", pb.TakeShotRequest(session_id=session_id, release=True))
    assert not released.shot.subject_ids
    raw.stream(list(frames(session_id, 30, start=330)))
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))


def test_bad_match_input_is_refused_and_the_session_streams_on(raw, canary):  # noqa: F811
    invalid, missing = grpc.StatusCode.INVALID_ARGUMENT, grpc.StatusCode.NOT_FOUND
    expect(invalid, raw.call, "CreateSession", match_request(delay_s=300.5), contains="delay_s")
    expect(invalid, raw.call, "CreateSession", match_request(0.0, players=[f"a{i}" for i in range(65)]), contains="2 to 64")
    session_id = raw.call("CreateSession", match_request(delay_s=1.0)).session_id
    raw.stream(list(frames(session_id, 10)))
    bad_events = [
        (pb.GameEvent(kind=pb.EVENT_KILL, actor_id="a0", other_actor_id="nobody"), missing, "nobody"),
        (pb.GameEvent(kind=pb.EVENT_DAMAGE, actor_id="a0", priority=16), invalid, "priority"),
        (pb.GameEvent(kind=pb.EVENT_CUSTOM, time_s=100.0), invalid, "plus the delay"),
    ]
    for event, code, contains in bad_events:
        update = next(frames(session_id, 1, start=10))
        update.events.append(event)
        expect(code, raw.call, "Frame", update, contains=contains)
    expect(
        missing, raw.call, "TakeShot", pb.TakeShotRequest(session_id="no-such", subject_ids=["a0"]), contains="unknown session"
    )
    expect(missing, raw.call, "TakeShot", pb.TakeShotRequest(session_id=session_id, subject_ids=["zz"]), contains="zz")
    expect(invalid, raw.call, "TakeShot", pb.TakeShotRequest(session_id=session_id, subject_ids=["a0", "a0"]), contains="twice")
    toric = raw.call("CreateSession", pb.CreateSessionRequest(targets=[capsule_target()])).session_id
    expect(
        grpc.StatusCode.FAILED_PRECONDITION,
        raw.call,
        "TakeShot",
        pb.TakeShotRequest(session_id=toric, subject_ids=["hero"]),
        contains="RIG_MATCH",
    )
    # Nothing was lost: the match session answers its next frames in order.
    after = raw.stream(list(frames(session_id, 40, start=10)))
    assert [u.frame for u in after if not u.buffering][-1] <= 50 and not any(u.stale for u in after)
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=toric))


def test_a_recorded_match_with_a_take_replays_bit_for_bit(raw, server):
    response = raw.call("CreateSession", match_request(delay_s=1.0, record=True))
    session_id = response.session_id
    raw.stream(list(frames(session_id, 60, kill_at={40: ("b1", "a1")})))
    raw.call("TakeShot", pb.TakeShotRequest(session_id=session_id, subject_ids=["a0"]))
    raw.stream(list(frames(session_id, 60, start=60)))
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    report = replay(server.data_dir / "recordings" / response.recording_path)
    assert report.frames == 120 and report.identical == 120, report
