"""An AUTOTRACK MATCH session on a real server over gRPC, fed by the Python SDK: player stats
streamed with the frames pick the tracked player; bad stats are refused and the session goes on."""

from __future__ import annotations

import asyncio

import grpc
import numpy as np
import pytest

import camdirector_client as cd
from tests.service.test_match_sessions import PLAYERS, match_request

RATE_HZ = 30.0
START = 4096 | 1  # IT_AXE | IT_SHOTGUN
RL, LG, RED_ARMOR, QUAD = 32, 64, 32768, 4194304


def packed(t: float):
    """The four players standing 2 m apart, facing +Z, stepping slowly along x."""
    positions = np.array([[2.0 * i + 0.1 * t, 0.9, 0.0] for i in range(len(PLAYERS))])
    return cd.pack_states(list(PLAYERS), positions, np.tile([0.0, 0.0, 0.0, 1.0], (len(PLAYERS), 1)))


def test_stats_streamed_to_an_autotrack_session_pick_the_tracked_player(server):
    with cd.connect(server.url("grpc")) as client:
        with client.create_session(match_request(delay_s=0.0, match_director=cd.pb.MATCH_DIRECTOR_AUTOTRACK)) as session:
            first = [cd.pb.PlayerStats(id=p, health=100, items=START) for p in PLAYERS]
            first[2] = cd.pb.PlayerStats(id="b0", health=100, armor=200, items=START | RL | RED_ARMOR)

            def updates():
                for k in range(60):
                    t = k / RATE_HZ
                    stats = (
                        first if k == 0 else [{"id": "a1", "health": 100, "items": START | LG | QUAD}] if k == 30 else None
                    )  # a1 takes the quad at 1 s: a switch moment (b0 has none)
                    yield session.frame_update(k + 1, t, packed=packed(t), player_stats=stats)

            replies = list(session.stream(updates()))
            assert all(r.HasField("pose") for r in replies)
            tracked = [tuple(r.shot.subject_ids) for r in replies]
            assert set(tracked[:30]) == {("b0",)}  # RL and red armor: 200 * 3 + 50 * 8
            switch = tracked.index(("a1",))  # quad and LG: 50 * 8 + 900
            assert 30 <= switch <= 30 + 0.6 * RATE_HZ and set(tracked[switch:]) == {("a1",)}
            assert replies[switch].cut and replies[switch].shot.kind == cd.pb.SHOT_FOLLOW
            assert "autotrack (2on2" in replies[switch].shot.reason

            with pytest.raises(cd.DirectorError) as err:
                session.frame(61, 2.0, packed=packed(2.0), player_stats=[{"id": "ghost", "frags": 1}])
            assert err.value.code == grpc.StatusCode.INVALID_ARGUMENT and "ghost" in err.value.message
            assert session.frame(61, 2.0, packed=packed(2.0)).shot.subject_ids == ["a1"]


def test_async_frames_carry_player_stats(server):
    async def main():
        async with cd.connect_async(server.url("grpc")) as client:
            request = match_request(delay_s=0.0, match_director=cd.pb.MATCH_DIRECTOR_AUTOTRACK)
            async with client.create_session(request) as session:
                stats = [cd.pb.PlayerStats(id="a1", health=100, items=START | RL)]
                return await session.frame(1, 0.0, packed=packed(0.0), player_stats=stats)

    assert list(asyncio.run(main()).shot.subject_ids) == ["a1"]
