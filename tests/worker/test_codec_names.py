"""The codec's checks of the targets' display names and team names: kept as sent, limited in
length, one line, team names for a MATCH session only."""

from __future__ import annotations

import grpc

from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.codec import MAX_NAME_CHARS, scene_from_request
from tests.service.wire_client import capsule_target
from tests.worker.test_codec_match import match_request, refused

SETTINGS = ServerSettings()


def named_request(display_name: str, team_name: str = "red") -> pb.CreateSessionRequest:
    request = match_request(2)
    request.targets[0].display_name = display_name
    request.targets[0].team_name = team_name
    return request


def test_names_reach_the_pipeline_as_sent_and_an_unnamed_player_has_empty_ones():
    name = "<b>x</b> \u00e9\u00e8 " + "\u4e2d" * (MAX_NAME_CHARS - 12)  # exactly the limit, in code points
    assert len(name) == MAX_NAME_CHARS
    scene = scene_from_request(named_request(name, "Team \u00c5"), SETTINGS)
    assert (scene.targets[0].display_name, scene.targets[0].team_name) == (name, "Team \u00c5")
    assert (scene.targets[1].display_name, scene.targets[1].team_name) == ("", "")


def test_a_name_over_the_limit_or_with_a_control_character_is_refused_naming_the_field():
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        scene_from_request,
        named_request("x" * (MAX_NAME_CHARS + 1)),
        SETTINGS,
        contains=f"targets[0].display_name has 65 characters; at most {MAX_NAME_CHARS} are allowed",
    )
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        scene_from_request,
        named_request("ok", "y" * (MAX_NAME_CHARS + 1)),
        SETTINGS,
        contains="targets[0].team_name has 65 characters",
    )
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        scene_from_request,
        named_request("two\nlines"),
        SETTINGS,
        contains="targets[0].display_name holds the control character U+000A",
    )


def test_a_display_name_is_any_rigs_but_a_team_name_only_a_matchs():
    hero = capsule_target("hero")
    hero.display_name = "Hero"
    scene = scene_from_request(pb.CreateSessionRequest(targets=[hero]), SETTINGS)
    assert scene.targets[0].display_name == "Hero"
    hero.team_name = "red"
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        scene_from_request,
        pb.CreateSessionRequest(targets=[hero]),
        SETTINGS,
        contains="targets[].team_name are for a RIG_MATCH session",
    )
