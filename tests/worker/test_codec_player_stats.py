"""The codec's checks of a MATCH frame's player_stats, and the AUTOTRACK director on the wire."""

from __future__ import annotations

import grpc

from camdirector.pipeline.inputs import PlayerStats
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.codec import frame_from_msg, scene_from_request
from tests.worker.test_codec_match import PLAYERS, SETTINGS, match_request, refused


def frame(*stats: pb.PlayerStats) -> pb.FrameUpdate:
    return pb.FrameUpdate(session_id="s", frame=1, time_s=5.0, player_stats=list(stats))


def test_player_stats_become_domain_stats():
    update = frame_from_msg(
        frame(
            pb.PlayerStats(id="p0", health=-20, armor=150, items=2**32 - 1, frags=-3),
            pb.PlayerStats(id="p2", health=100, items=32 | 32768),
        ),
        set(PLAYERS),
        set(),
        player_ids=PLAYERS,
    )
    assert update.player_stats == [PlayerStats("p0", -20, 150, 2**32 - 1, -3), PlayerStats("p2", 100, 0, 32 | 32768, 0)]
    assert frame_from_msg(frame(), set(PLAYERS), set(), player_ids=PLAYERS).player_stats == []


def test_stats_of_an_unknown_or_repeated_player_are_refused():
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        frame_from_msg,
        frame(pb.PlayerStats(id="p9", health=100)),
        set(PLAYERS),
        set(),
        player_ids=PLAYERS,
        contains="player_stats[0].id 'p9' is not a player",
    )
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        frame_from_msg,
        frame(pb.PlayerStats(id="p1"), pb.PlayerStats(id="p1", frags=1)),
        set(PLAYERS),
        set(),
        player_ids=PLAYERS,
        contains="player_stats[1].id 'p1' is sent twice",
    )


def test_stats_outside_a_match_session_are_refused():
    refused(
        grpc.StatusCode.INVALID_ARGUMENT,
        frame_from_msg,
        frame(pb.PlayerStats(id="hero", health=100)),
        {"hero"},
        set(),
        contains="player_stats are for a RIG_MATCH session",
    )


def test_the_autotrack_director_is_chosen_by_style():
    scene = scene_from_request(match_request(4, delay_s=0.0, match_director=pb.MATCH_DIRECTOR_AUTOTRACK), SETTINGS)
    assert scene.style.match_director == "autotrack"
