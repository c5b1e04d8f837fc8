"""The compiled load generator (load_tests/driver/load_driver.cpp) against a real server: it streams
every frame over both transports and reports what the Python generator reports, its reading of
the replies checked by frames the server answers stale, and a session it cannot stream (an
unknown id, a bad argument) reported rather than hung on. No timing is asserted."""

from __future__ import annotations

import asyncio
import json
import os

import pytest

from camdirector.demo.client import session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.server_process import ServerProcess
from camdirector.geometry.camera import Lens
from camdirector.v1 import director_pb2 as pb
from load_tests import capacity, native_generator, stream


@pytest.fixture(scope="module")
def driver():
    missing = native_generator.missing_toolchain()
    if missing is not None:
        reason = f"the native load generator cannot be built here ({missing}): scripts/system-deps.sh --tests installs it"
        if os.environ.get("CAMDIRECTOR_REQUIRE_CPP_SDK") == "1":
            pytest.fail(reason + " (required: CAMDIRECTOR_REQUIRE_CPP_SDK=1)")
        pytest.skip(reason)
    return native_generator.build()


@pytest.fixture(scope="module")
def server(driver):
    with ServerProcess("--workers", "1") as running:
        yield running


def _address(server, transport: str) -> str:
    return server.grpc if transport == "grpc" else server.zmq


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
def test_it_streams_every_frame_of_every_session_and_reports_as_the_python_generator(server, transport):
    common = dict(transport=transport, address=_address(server, transport), sessions=3, rate_hz=60.0, seconds=1.0)
    native = asyncio.run(stream.run(**common, warmup_frames=5, generator="native"))
    python = asyncio.run(stream.run(**common, warmup_frames=5))
    assert native.keys() == python.keys() and (native["generator"], python["generator"]) == ("native", "python")
    assert native["frames_sent"] == native["frames_received"] == 3 * 60 and native["dropped_frames"] == 0
    assert not native["errors"] and native["stale_frames"] == 0
    assert 0 < native["rtt_ms"]["p50"] <= native["rtt_ms"]["p99"] <= native["rtt_ms"]["max"]
    assert 0 < native["compute_ms"]["p50"] < native["rtt_ms"]["max"]  # read from the replies: the server's own time
    assert native["client_cpu_s"] > 0


def _session(server, n_frames: int = 30) -> tuple[list[bytes], str]:
    """A FRAMING_ONLY session of the demo scene, and n_frames of its frames."""
    scene = build_demo_scene(seed=7, duration_s=1.0)
    frames = stream._frames(scene, n_frames, 60.0)
    driver = stream.ZmqDriver(server.zmq)

    async def open_one() -> str:
        try:
            return await driver.open_session(session_request(scene, Lens(), pb.FRAMING_ONLY))
        finally:
            await driver.close()

    return frames, asyncio.run(open_one())


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
def test_frames_sent_again_are_counted_stale_from_the_replies(server, transport):
    frames, session_id = _session(server)
    first = native_generator.stream(transport, _address(server, transport), [session_id], frames, 0.0, 0)
    again = native_generator.stream(transport, _address(server, transport), [session_id], frames, 0.0, 4)
    assert first["received"] == again["received"] == [30] and not first["errors"] and not again["errors"]
    assert first["stale"] == 0 and len(first["rtt_ms"]) == len(first["compute_ms"]) == 30
    assert again["stale"] == len(again["rtt_ms"]) == 26  # not newer than the last answered: every one stale


@pytest.mark.parametrize(
    ("transport", "said"), [("grpc", "gRPC status 5: unknown session id"), ("zmq", "ZeroMQ status 5: unknown session id")]
)
def test_an_unknown_session_is_reported_and_the_others_stream_on(server, transport, said):
    frames, session_id = _session(server)
    result = native_generator.stream(transport, _address(server, transport), ["f" * 32, session_id], frames, 1 / 60, 0)
    (error,) = result["errors"]
    assert error.startswith(said) and result["received"] == [0, 30]


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
def test_a_stride_gives_each_session_its_own_stretch_of_the_frames(server, transport):
    frames, first = _session(server, 40)
    _, second = _session(server)
    address = _address(server, transport)
    strided = native_generator.stream(transport, address, [first, second], frames, 0.0, 0, stride=10)
    assert strided["received"] == [30, 30] and strided["stale"] == 0 and not strided["errors"]
    # the first session answered frames 1-30, the second 11-40: frames 31-40 are new to the first alone
    assert native_generator.stream(transport, address, [first], frames[30:], 0.0, 0)["stale"] == 0
    assert native_generator.stream(transport, address, [second], frames[30:], 0.0, 0)["stale"] == 10


def test_a_bad_argument_is_refused_with_the_reason(driver):
    with pytest.raises(RuntimeError, match="--transport must be grpc or zmq"):
        native_generator.stream("carrier-pigeon", "127.0.0.1:1", ["a"], [b"\x10\x01"], 0.0, 0)
    with pytest.raises(RuntimeError, match="--stride leaves the last session no frame to send"):
        native_generator.stream("grpc", "127.0.0.1:1", ["a", "b"], [b"\x10\x01"] * 3, 0.0, 0, stride=3)


@pytest.mark.parametrize("generator", ["native", "python"])
def test_sessions_spread_over_the_demo_each_stream_every_frame_in_order(server, generator):
    spread = asyncio.run(stream.run("zmq", server.zmq, 3, 60.0, 0.5, generator=generator, spread_s=0.5))
    assert spread["spread_s"] == 0.5 and spread["frames_sent"] == spread["frames_received"] == 3 * 30
    assert spread["stale_frames"] == 0 and not spread["errors"]  # each session's frames newer than the one before
    with pytest.raises(ValueError, match="spread_s must be >= 0"):
        asyncio.run(stream.run("zmq", server.zmq, 1, 60.0, 0.5, spread_s=-1.0))


def test_capacity_streams_with_it_by_default(driver, tmp_path):
    out = tmp_path / "capacity.json"
    args = ["--modes", "FRAMING_ONLY", "--transports", "grpc", "--max-sessions", "2", "--seconds", "0.5"]
    assert capacity.main([*args, "--warmup-frames", "2", "--settle-s", "0", "--workers", "1", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    (case,) = result["cases"]
    assert result["generator"] == "native" and case["steps"]
    for step in case["steps"]:  # every frame streamed and answered; the driver's own CPU counted
        assert step["frames_sent"] == step["sessions"] * 30 and step["dropped_frames"] == 0 and not step["errors"]
        assert step["cpu_us_per_frame"]["load_generator"] > 0
