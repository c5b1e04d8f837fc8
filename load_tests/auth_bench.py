"""What checking a key costs a streaming frame: the same frames streamed closed loop over gRPC
`StreamFrames` into two servers started side by side, one with authentication (a key in the
stream's metadata, checked on every message: access/guard.py) and one with `--no-auth`.

    python -m load_tests.auth_bench --frames 600 --rounds 5 --json FILE

Rounds alternate between the two servers so that the machine's drift lands on both alike. Each
round opens a new stream on its session. Reported per server: round trip p50/p99 (ms) at the
client, and the floor measured in the same run (a gRPC health check, open on both: what the
transport alone costs); `overhead_ratio` = auth p50 / no-auth p50 - 1, the figure the issue
bounds at 0.05. Also the guard's own check timed in this process (us per frame's check, cached
key: a SHA-256 and two dict lookups), which says how much of any difference is the check itself.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
import timeit
from pathlib import Path

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from camdirector.access.guard import Guard
from camdirector.access.keys import SqliteAccessStore
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.server_process import ServerProcess
from camdirector.geometry.camera import Lens
from camdirector.v1 import director_pb2 as pb
from load_tests.report import emit, summary


class Streamer:
    """One server's session, streamed from this process over one channel."""

    def __init__(self, address: str, key: str | None):
        self.channel = grpc.aio.insecure_channel(address, options=[("grpc.max_send_message_length", 64 << 20)])
        self.metadata = (("authorization", f"Bearer {key}"),) if key else None
        self.create = self.channel.unary_unary(
            "/camdirector.v1.Director/CreateSession",
            request_serializer=pb.CreateSessionRequest.SerializeToString,
            response_deserializer=pb.CreateSessionResponse.FromString,
        )
        self.stream = self.channel.stream_stream("/camdirector.v1.Director/StreamFrames")
        self.health = health_pb2_grpc.HealthStub(self.channel)
        self.session_id = ""

    async def open(self, request) -> None:
        self.session_id = (await self.create(request, metadata=self.metadata)).session_id

    async def round(self, frames: list[pb.FrameUpdate]) -> list[float]:
        """Round trips (s) of `frames` on a new stream, one in flight."""
        call = self.stream(metadata=self.metadata)
        rtts = []
        for update in frames:
            update.session_id = self.session_id
            payload = update.SerializeToString()
            t0 = time.perf_counter()
            await call.write(payload)
            await call.read()
            rtts.append(time.perf_counter() - t0)
        await call.done_writing()
        return rtts

    async def floor(self, n: int) -> list[float]:
        out = []
        for _ in range(n):
            t0 = time.perf_counter()
            await self.health.Check(health_pb2.HealthCheckRequest())
            out.append(time.perf_counter() - t0)
        return out


def guard_check_us(repeats: int = 20000) -> float:
    """Microseconds per cached check of a key (identify with fresh=False), in this process."""
    with tempfile.TemporaryDirectory() as folder:
        store = SqliteAccessStore(folder)
        _, key = store.create_key("engine")
        guard = Guard(store)
        header = f"Bearer {key}"
        guard.identify(header, fresh=False)
        seconds = min(timeit.repeat(lambda: guard.identify(header, fresh=False), number=repeats, repeat=5))
        store.close()
    return seconds / repeats * 1e6


async def measure(servers: dict[str, ServerProcess], frames_per_round: int, rounds: int) -> dict:
    scene = build_demo_scene()
    request = session_request(scene, Lens(), pb.VisibilityMode.ANTICIPATION)
    streamers = {name: Streamer(s.grpc, s.admin_key) for name, s in servers.items()}
    for streamer in streamers.values():
        await streamer.open(request)
    rtts = {name: [] for name in servers}
    floors = {name: [] for name in servers}
    for r in range(rounds + 1):  # round 0 warms both up and is not counted
        for name, streamer in streamers.items():
            frames = list(frame_updates(scene, frames_per_round, 60.0))
            got = await streamer.round(frames[:frames_per_round])
            floor = await streamer.floor(50)
            if r:
                rtts[name] += got
                floors[name] += floor
    for streamer in streamers.values():
        await streamer.channel.close()
    result = {name: {"rtt_ms": summary(rtts[name], 1e3), "floor_ms": summary(floors[name], 1e3)} for name in servers}
    result["overhead_ratio"] = round(result["auth"]["rtt_ms"]["median"] / result["no_auth"]["rtt_ms"]["median"] - 1, 4)
    result["overhead_p99_ratio"] = round(result["auth"]["rtt_ms"]["p99"] / result["no_auth"]["rtt_ms"]["p99"] - 1, 4)
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=600, help="frames per round and server")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    with (
        ServerProcess("--workers", "1", "--tenant-max-fps", "10000", transports=("grpc",), auth=True) as auth,
        ServerProcess("--workers", "1", transports=("grpc",)) as open_server,
    ):
        result = asyncio.run(measure({"auth": auth, "no_auth": open_server}, args.frames, args.rounds))
    result.update(
        guard_check_us=round(guard_check_us(), 3),
        frames_per_round=args.frames,
        rounds=args.rounds,
        transport="grpc StreamFrames, closed loop, one session per server",
    )
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
