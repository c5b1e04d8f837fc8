"""The per-hop profile (load_tests/frame_profile.py): its report's shape, hops that add up to no more
than the round trip, and a plugin that is inert unless asked. Tiny runs; no timing is asserted."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from load_tests import frame_profile

ROOT = Path(__file__).resolve().parents[2]
STAGES = {
    "TORIC_FRAMING_ONLY": {"stage:ingest", "stage:framing", "stage:motion", "stage:visibility"},
    "TORIC_ANTICIPATION": {"stage:ingest", "stage:framing", "stage:motion", "stage:visibility"},
    "TRACKS": {"stage:ingest", "stage:cut_check", "stage:target_update", "stage:camera_update"},
    "MATCH": {"stage:ingest", "stage:buffer", "stage:camera", "stage:visibility"},
}


def _profile(tmp_path, rigs: str, frame_path: str = "python", inline_frames: int = 0, edge_frames: int = 0) -> dict:
    out = tmp_path / "out.json"
    args = [
        "--rigs",
        rigs,
        "--frames",
        "12",
        "--warmup",
        "3",
        "--bare-frames",
        "5",
        "--frame-path",
        frame_path,
        "--inline-frames",
        str(inline_frames),
        "--edge-frames",
        str(edge_frames),
        "--json",
        str(out),
    ]
    assert frame_profile.main(args) == 0
    return json.loads(out.read_text())


def _check_configs(result: dict, rigs: list[str]) -> None:
    assert [(c["rig"], c["transport"]) for c in result["configs"]] == [(r, t) for r in rigs for t in ("grpc", "zmq")]
    for config in result["configs"]:
        hops = config["hops"]
        stages = [name for name in hops if name.startswith("stage:")]
        assert STAGES[config["rig"]] <= set(stages)
        # every hop named, the stages where HOPS says "stages", in the order a frame passes them
        assert list(hops) == [n for hop in frame_profile.HOPS for n in (stages if hop == "stages" else [hop])]
        for stats in (*hops.values(), config["round_trip_us"], config["echo_floor_us"]):
            assert {"median_us", "p99_us", "mean_us"} <= set(stats)
        assert config["frames"] == 12 and config["uninstrumented"]["frames"] == 5
        assert config["negative_hop_frames"] == 0
        # frame by frame the hops add up to no more than the round trip (they tile it); their means
        # likewise, give or take each figure's rounding to 0.1 us
        assert config["hops_sum_over_round_trip_max"] <= 1.0
        assert sum(h["mean_us"] for h in hops.values()) <= config["round_trip_us"]["mean_us"] + 0.05 * len(hops)
        assert sum(h["share"] for h in hops.values()) == pytest.approx(1.0, abs=1e-3 * len(hops))
        assert config["request_bytes"] > 0 and config["reply_bytes"] > 0
        assert len(config["load_average"]["before"]) == 3 and {"front", "workers", "client"} <= set(config["cpu_us_per_frame"])


def test_profile_of_toric_frames_over_both_transports(tmp_path):
    result = _profile(tmp_path, "TORIC_FRAMING_ONLY,TORIC_ANTICIPATION")
    assert result["recording"] is True and result["rate_hz"] is None
    _check_configs(result, ["TORIC_FRAMING_ONLY", "TORIC_ANTICIPATION"])
    assert not any("inline" in config or "edge" in config for config in result["configs"])  # 0 frames: not streamed


def test_profile_on_the_compiled_frame_path_stamps_its_wire_and_prices_the_hop_and_the_edge(tmp_path):
    result = _profile(tmp_path, "TORIC_FRAMING_ONLY", "compiled", inline_frames=4, edge_frames=20)
    assert result["frame_path"] == "compiled"
    _check_configs(result, ["TORIC_FRAMING_ONLY"])
    for config in result["configs"]:  # the compiled wire's decode and encode wrapped, not left to "table"
        assert config["hops"]["codec_decode"]["mean_us"] > 0 and config["hops"]["codec_encode"]["mean_us"] > 0
        inline = config["inline"]  # streamed into a server whose front holds the session
        assert inline["frames"] == 4 and inline["round_trip_over_echo_p50"] > 0 and inline["cpu_us_per_frame"]["front"] > 0
        edge = config["edge"]  # streamed into a server whose gRPC port the compiled edge serves
        # more frames than the profiled run's 12: each run streams its own count
        assert edge["frames"] == 20 and edge["round_trip_over_echo_p50"] > 0 and edge["cpu_us_per_frame"]["workers"] > 0


@pytest.mark.shared_data
def test_profile_of_tracks_and_match_frames(shared_data, tmp_path):
    _check_configs(_profile(tmp_path, "TRACKS,MATCH"), ["TRACKS", "MATCH"])


def test_hops_tile_a_frame_and_set_deferred_work_apart():
    client = (1.0, 1.001, 1.009, 1.010)
    front = {"F0": 1.002, "F1": 1.0025, "F2": 1.0075, "F3": 1.008}
    worker = {
        "W0": 1.004,
        "idle": [(1.002, 1.0035)],  # deferred work the frame waited for: 1 ms of it after F1
        "handle_in": 1.0041,
        "worker_decode": 0.0001,
        "table_in": 1.0043,
        "checkpoint_append": 0.0002,
        "session": 0.002,
        "stage_ms": {"ingest": 0.5, "motion": 1.0},
        "table_out": 1.007,
        "handle_out": 1.0071,
        "W_end": 1.0072,
    }
    hops = frame_profile.frame_hops(client, front, worker)
    assert sum(hops.values()) == pytest.approx(client[3] - client[0], abs=1e-12)
    assert hops["worker_deferred_work_in_the_way"] == pytest.approx(0.001)
    assert hops["front_to_worker"] == pytest.approx(0.0005)
    assert hops["session"] == pytest.approx(0.0005) and hops["stage:motion"] == pytest.approx(0.001)
    assert hops["table"] == pytest.approx(0.0027 - 0.0002 - 0.002)


def test_the_plugin_wraps_nothing_unless_its_folder_is_named(tmp_path):
    check = (
        "import load_tests.frame_profile\n"
        "from camdirector.pipeline.session import Session\n"
        "from camdirector.front.router import SessionRouter\n"
        "from camdirector.worker import main\n"
        "print(all(not hasattr(f, '__wrapped__') for f in (Session.frame, SessionRouter.frame, main.read_request)))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != frame_profile.PROFILE_DIR_ENV}
    done = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True, cwd=ROOT, env=env, check=True)
    assert done.stdout.strip() == "True"
    # the same import with the folder named does wrap (so the check above can fail)
    env[frame_profile.PROFILE_DIR_ENV] = str(tmp_path)
    done = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True, cwd=ROOT, env=env, check=True)
    assert done.stdout.strip() == "False"


def test_a_grpc_client_does_not_take_over_another_channels_failed_connection():
    """A channel of this process that met a closed port and is still open (with the arguments of
    load_tests.stream's and auth_bench's channels, the profile's own before), then a server on that
    port (the kernel gives ports out again): the profile's client reaches the server at once. With
    gRPC's global subchannel pool it took over the old channel's connection, in its reconnect
    backoff, and its first call failed UNAVAILABLE "Connection refused": the echo floor's flaky
    failure."""
    import grpc

    async def check() -> bytes:
        with socket.socket() as probe:  # a port nobody listens on, for the stale channel to meet
            probe.bind(("127.0.0.1", 0))
            address = f"127.0.0.1:{probe.getsockname()[1]}"
        stale = grpc.aio.insecure_channel(address, options=[("grpc.max_send_message_length", 64 << 20)])
        with pytest.raises(grpc.aio.AioRpcError) as refused:
            await stale.unary_unary(frame_profile.ECHO_PATH)(b"", timeout=5)
        assert refused.value.code() == grpc.StatusCode.UNAVAILABLE
        server = grpc.aio.server(options=[("grpc.so_reuseport", 0)])
        server.add_generic_rpc_handlers((frame_profile.echo_grpc_handler(),))
        assert server.add_insecure_port(address) != 0
        await server.start()
        client = frame_profile._Grpc(address)
        try:
            round_trip, done = client.frames(frame_profile.ECHO_PATH)
            reply = await round_trip(frame_profile.echo_request(16, 7))
            await done()
        finally:
            await client.close()
            await stale.close()
            await server.stop(None)
        return reply

    assert asyncio.run(check()) == b"\1" * 7
