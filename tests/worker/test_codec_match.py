"""The codec's checks of a MATCH session's input: players, teams, delay, events, style fields."""

from __future__ import annotations

import grpc
import pytest

from camdirector.errors import DirectorError
from camdirector.pipeline.inputs import EventKind
from camdirector.pipeline.style import Rig
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.codec import MAX_PLAYERS, frame_from_msg, scene_from_request, shown_style, style_from_msg
from tests.service.wire_client import capsule_target

SETTINGS = ServerSettings()
PLAYERS = frozenset({"p0", "p1", "p2"})


def match_request(players: int = 3, delay_s: float = 10.0, **style) -> pb.CreateSessionRequest:
    targets = [capsule_target(f"p{i}", position=(3.0 * i, 0.9, 0.0)) for i in range(players)]
    for i, target in enumerate(targets):
        target.team = i % 2
    return pb.CreateSessionRequest(targets=targets, delay_s=delay_s, style=pb.Style(rig=pb.RIG_MATCH, **style))


def refused(code: grpc.StatusCode, fn, *args, contains: str = "", **kwargs) -> None:
    with pytest.raises(DirectorError) as info:
        fn(*args, **kwargs)
    assert info.value.code == code, info.value.message
    assert contains in info.value.message


def frame(*events: pb.GameEvent, time_s: float = 5.0) -> pb.FrameUpdate:
    return pb.FrameUpdate(session_id="s", frame=1, time_s=time_s, events=list(events))


def test_a_match_scene_keeps_players_teams_delay_and_director():
    scene = scene_from_request(match_request(4, delay_s=30.0, match_director=pb.MATCH_DIRECTOR_HLTV, min_shot_s=3.0), SETTINGS)
    assert scene.style.rig == Rig.MATCH
    assert scene.style.match_director == "hltv"
    assert scene.style.min_shot_s == 3.0 and scene.style.max_shot_s == 8.0
    assert [t.team for t in scene.targets] == [0, 1, 0, 1]
    assert scene.delay_s == 30.0 and scene.level is None


def test_the_director_name_wins_over_the_enum_and_an_unknown_one_is_refused_with_the_registered_names():
    lens = scene_from_request(match_request(), SETTINGS).lens
    named = pb.Style(rig=pb.RIG_MATCH, match_director=pb.MATCH_DIRECTOR_HLTV, match_director_name="autotrack")
    assert style_from_msg(named, lens).match_director == "autotrack"
    assert style_from_msg(pb.Style(rig=pb.RIG_MATCH), lens).match_director == "planned"
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        style_from_msg,
        pb.Style(rig=pb.RIG_MATCH, match_director_name="nobody"),
        lens,
        contains="'nobody' is not a registered match director; the registered ones are planned, hltv, autotrack",
    )
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        style_from_msg,
        pb.Style(rig=pb.RIG_MATCH, match_director=99),
        lens,
        contains="not a known match_director",
    )


def test_the_style_shown_back_carries_the_resolved_director_name():
    lens = scene_from_request(match_request(), SETTINGS).lens
    sent = pb.Style(rig=pb.RIG_MATCH, match_director=pb.MATCH_DIRECTOR_HLTV)
    shown = shown_style(sent, style_from_msg(sent, lens))
    assert shown.match_director_name == "hltv" and shown.match_director == pb.MATCH_DIRECTOR_HLTV
    assert not sent.match_director_name  # the request itself is left as it came
    toric = pb.Style()
    assert shown_style(toric, style_from_msg(toric, lens)) is toric


def test_player_counts_and_delay_out_of_range_are_refused():
    refused(grpc.StatusCode.INVALID_ARGUMENT, scene_from_request, match_request(1), SETTINGS, contains="2 to 64")
    refused(grpc.StatusCode.INVALID_ARGUMENT, scene_from_request, match_request(MAX_PLAYERS + 1), SETTINGS, contains="2 to 64")
    refused(grpc.StatusCode.INVALID_ARGUMENT, scene_from_request, match_request(delay_s=300.5), SETTINGS, contains="delay_s")
    refused(
        grpc.StatusCode.INVALID_ARGUMENT, scene_from_request, match_request(delay_s=float("nan")), SETTINGS, contains="delay_s"
    )
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        scene_from_request,
        match_request(min_shot_s=5.0, max_shot_s=4.0),
        SETTINGS,
        contains="max_shot_s",
    )


def test_match_fields_outside_a_match_session_are_refused():
    toric = pb.CreateSessionRequest(targets=[capsule_target()], delay_s=5.0)
    refused(grpc.StatusCode.INVALID_ARGUMENT, scene_from_request, toric, SETTINGS, contains="RIG_MATCH")
    for style in (pb.Style(min_shot_s=3.0), pb.Style(match_director_name="hltv")):
        refused(
            grpc.StatusCode.INVALID_ARGUMENT,
            style_from_msg,
            style,
            scene_from_request(pb.CreateSessionRequest(targets=[capsule_target()]), SETTINGS).lens,
            contains="MATCH rig",
        )
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        frame_from_msg,
        frame(pb.GameEvent(kind=pb.EVENT_KILL, actor_id="hero", other_actor_id="hero")),
        {"hero"},
        set(),
        contains="RIG_MATCH",
    )


def test_events_become_domain_events_with_defaults():
    update = frame_from_msg(
        frame(
            pb.GameEvent(kind=pb.EVENT_KILL, actor_id="p0", other_actor_id="p1", label="ak"),
            pb.GameEvent(kind=pb.EVENT_OBJECTIVE, actor_id="p2", priority=9, time_s=4.5, position=pb.Vec3(x=1.0, y=0.0, z=2.0)),
        ),
        set(PLAYERS),
        set(),
        player_ids=PLAYERS,
        delay_s=10.0,
    )
    kill, objective = update.events
    assert (kill.kind, kill.actor_id, kill.other_actor_id, kill.priority, kill.time_s, kill.label) == (
        EventKind.KILL,
        "p0",
        "p1",
        0,
        5.0,
        "ak",
    )
    assert kill.position_world is None
    assert (objective.kind, objective.priority, objective.time_s) == (EventKind.OBJECTIVE, 9, 4.5)
    assert objective.position_world.tolist() == [1.0, 0.0, 2.0]


@pytest.mark.parametrize(
    "event, code, contains",
    [
        (pb.GameEvent(kind=pb.EVENT_KILL, actor_id="p0", other_actor_id="ghost"), grpc.StatusCode.NOT_FOUND, "ghost"),
        (pb.GameEvent(kind=pb.EVENT_DAMAGE, actor_id="nobody"), grpc.StatusCode.NOT_FOUND, "nobody"),
        (pb.GameEvent(kind=pb.EVENT_KILL, actor_id="p0"), grpc.StatusCode.INVALID_ARGUMENT, "victim"),
        (pb.GameEvent(kind=pb.EVENT_CUSTOM, priority=16), grpc.StatusCode.INVALID_ARGUMENT, "priority"),
        (pb.GameEvent(kind=pb.EVENT_CUSTOM, time_s=15.5), grpc.StatusCode.INVALID_ARGUMENT, "plus the delay"),
        (pb.GameEvent(kind=pb.EVENT_CUSTOM, time_s=float("inf")), grpc.StatusCode.INVALID_ARGUMENT, "time_s"),
        (pb.GameEvent(kind=pb.EVENT_KIND_UNSPECIFIED), grpc.StatusCode.INVALID_ARGUMENT, "kind is unset"),
        (pb.GameEvent(kind=99), grpc.StatusCode.INVALID_ARGUMENT, "EventKind"),
        (pb.GameEvent(kind=pb.EVENT_OBJECTIVE, position=pb.Vec3(x=float("nan"))), grpc.StatusCode.INVALID_ARGUMENT, "position"),
    ],
)
def test_each_kind_of_bad_event_is_refused(event, code, contains):
    refused(code, frame_from_msg, frame(event), set(PLAYERS), set(), player_ids=PLAYERS, delay_s=10.0, contains=contains)


def test_an_event_up_to_the_delay_ahead_is_accepted():
    update = frame_from_msg(
        frame(pb.GameEvent(kind=pb.EVENT_CUSTOM, time_s=15.0)), set(PLAYERS), set(), player_ids=PLAYERS, delay_s=10.0
    )
    assert update.events[0].time_s == 15.0
