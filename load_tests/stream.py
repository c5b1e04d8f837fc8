"""Streaming benchmark: N concurrent sessions at a fixed frame rate against a server it starts.

    python -m load_tests.stream --transport grpc|zmq --sessions N --rate 60 --seconds S
        [--generator python|native] [--spread-s S] --json FILE

Each session streams the demo scene (about 2,100 triangles, an avatar and 3-6 moving obstacles,
packed states) paced by wall-clock time, one frame in flight per session, as a game loop does.
`--rate 0` runs closed loop instead: each session sends its next frame as soon as the last is
answered (`--seconds` of frames at a nominal 60 Hz), which measures the service's latency without
the wake-up cost an idle machine adds between paced frames (on this kind of VM a cross-process
round trip after 16 ms idle costs about 10x one made while busy).
Measured: frames sent and received, dropped frames (sent, never answered), late frames (answered
after the next was due), round trip p50/p99 at the client, the server's own compute_ms p50/p99, and
this load generator's own CPU while streaming (seconds, and as a fraction of one core).
`--generator native` streams with the compiled driver (native_generator.py) instead of this
process, at a small part of its CPU; the sessions are opened and the baseline measured here alike.
The baseline, measured in the same run against the same server process, is the transport alone:
a gRPC health check (served by the front process) or a ZeroMQ request the front answers at once
with an error; `rtt_ratio_vs_baseline` divides our round trip by it.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import sys
import time
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager
from pathlib import Path

import grpc
import zmq
import zmq.asyncio
from grpc_health.v1 import health_pb2, health_pb2_grpc

from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.server_process import ServerProcess
from camdirector.geometry.camera import Lens
from camdirector.infra.heap import freeze_startup_heap
from camdirector.v1 import director_pb2 as pb
from load_tests import native_generator
from load_tests.report import emit, percentiles

GENERATORS = ("python", "native")  # run()'s generator: this process's asyncio, or native_generator's driver


def _frames(scene, n_frames: int, rate_hz: float) -> list[bytes]:
    """Serialized FrameUpdates without session id (added per session by concatenation)."""
    return [update.SerializeToString() for update in frame_updates(scene, n_frames, rate_hz)]


def _with_session(session_id: str, frame_bytes: bytes) -> bytes:
    # field 1 (session_id) prepended: protobuf parsers accept fields in any order
    sid = session_id.encode()
    return b"\x0a" + bytes([len(sid)]) + sid + frame_bytes


class GrpcDriver:
    """`key`: sent in every call's metadata (a server with keys)."""

    def __init__(self, address: str, key: str | None = None):
        self.channel = grpc.aio.insecure_channel(address, options=[("grpc.max_send_message_length", 64 << 20)])
        self.metadata = (("authorization", f"Bearer {key}"),) if key else None
        self.create = self.channel.unary_unary(
            "/camdirector.v1.Director/CreateSession",
            request_serializer=pb.CreateSessionRequest.SerializeToString,
            response_deserializer=pb.CreateSessionResponse.FromString,
        )
        self.close_call = self.channel.unary_unary(
            "/camdirector.v1.Director/CloseSession",
            request_serializer=pb.CloseSessionRequest.SerializeToString,
            response_deserializer=pb.CloseSessionResponse.FromString,
        )
        self.stream = self.channel.stream_stream("/camdirector.v1.Director/StreamFrames")  # bytes in, bytes out
        self.health = health_pb2_grpc.HealthStub(self.channel)

    async def open_session(self, request) -> str:
        return (await self.create(request, metadata=self.metadata)).session_id

    async def close_session(self, session_id: str) -> None:
        await self.close_call(pb.CloseSessionRequest(session_id=session_id), metadata=self.metadata)

    async def run_session(self, session_id: str, frames: list[bytes], period_s: float, start: float, record):
        call = self.stream(metadata=self.metadata)
        for i, payload in enumerate(frames):
            await _sleep_until(start + i * period_s)
            t0 = time.perf_counter()
            await call.write(_with_session(session_id, payload))
            reply = await call.read()
            record(i, t0, time.perf_counter(), pb.CameraUpdate.FromString(reply))
        await call.done_writing()

    async def baseline(self) -> float:
        t0 = time.perf_counter()
        await self.health.Check(health_pb2.HealthCheckRequest())
        return time.perf_counter() - t0

    async def close(self):
        await self.channel.close()


class ZmqDriver:
    def __init__(self, address: str):
        self.address = address
        self.ctx = zmq.asyncio.Context()
        self.control = self._socket()

    def _socket(self):
        sock = self.ctx.socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(self.address)
        return sock

    async def _call(self, sock, rpc: bytes, payload: bytes) -> tuple[bytes, bytes]:
        await sock.send_multipart([rpc, payload])
        return tuple(await sock.recv_multipart())

    async def _control_call(self, rpc: bytes, payload: bytes) -> bytes:
        """A call on the control socket: the reply's body, a RuntimeError with the server's message where refused."""
        code, body = await self._call(self.control, rpc, payload)
        if code != b"0":
            raise RuntimeError(body.decode())
        return body

    async def open_session(self, request) -> str:
        body = await self._control_call(b"CreateSession", request.SerializeToString())
        return pb.CreateSessionResponse.FromString(body).session_id

    async def close_session(self, session_id: str) -> None:
        await self._control_call(b"CloseSession", pb.CloseSessionRequest(session_id=session_id).SerializeToString())

    async def run_session(self, session_id, frames, period_s, start, record):
        sock = self._socket()
        for i, payload in enumerate(frames):
            await _sleep_until(start + i * period_s)
            t0 = time.perf_counter()
            code, body = await self._call(sock, b"Frame", _with_session(session_id, payload))
            if code != b"0":
                raise RuntimeError(body.decode())
            record(i, t0, time.perf_counter(), pb.CameraUpdate.FromString(body))
        sock.close()

    async def baseline(self) -> float:
        t0 = time.perf_counter()
        await self._call(self.control, b"Ping", b"")  # answered at once by the front (UNIMPLEMENTED)
        return time.perf_counter() - t0

    async def close(self):
        self.control.close()
        self.ctx.term()


async def _sleep_until(deadline: float) -> None:
    delay = deadline - time.perf_counter()
    if delay > 0:
        await asyncio.sleep(delay)


async def run(
    transport: str,
    address: str,
    sessions: int,
    rate_hz: float,
    seconds: float,
    visibility: int = pb.FRAMING_ONLY,
    warmup_frames: int = 0,
    alongside: Callable[[list[str]], AbstractAsyncContextManager] | None = None,
    key: str | None = None,
    generator: str = "python",
    spread_s: float = 0.0,
) -> dict:
    """warmup_frames: each session's first frames, answered and counted as received but left out of
    the round trips, compute times, late and stale counts (a session's first frame sets up what
    it keeps: about 30 ms in the map modes).
    alongside: called with the session ids once they are open; the context it returns is entered
    before the baseline and the streams and left when they end, so both are measured with it
    running (load_tests.monitors_bench: a live monitor on each session).
    key: the key gRPC sends (a server with keys: load_tests.oversize); ZeroMQ's would need the
    server's CURVE key as well, so it takes none.
    generator: what streams the frames, "python" (this process's asyncio) or "native" (the
    compiled driver, native_generator.py: the sessions are opened and the floor measured here all
    the same, and `client_cpu_s` is then the driver's).
    spread_s: 0 (the default), every session streams the same frames, staggered within one period,
    so the same moment of the demo reaches every session at once (a cut in one is a cut in all: the
    worst case); above 0, session k starts k * spread_s / sessions seconds into the demo, each its
    own stretch of the same game, as independent clients would be (docs/frame_path.md)."""
    if key is not None and transport != "grpc":
        raise ValueError("only the gRPC driver sends a key")
    if generator not in GENERATORS:
        raise ValueError(f"generator must be one of {', '.join(GENERATORS)}, not {generator!r}")
    if spread_s < 0:
        raise ValueError(f"spread_s must be >= 0, not {spread_s}")
    nominal_hz = rate_hz or 60.0
    n_frames = int(round(seconds * nominal_hz))
    stride = int(round(spread_s * nominal_hz / sessions))  # frames between two sessions' starts
    scene = build_demo_scene(seed=7, duration_s=max(seconds + spread_s, 1.0))
    lens = Lens()
    frames = _frames(scene, n_frames + (sessions - 1) * stride, nominal_hz)
    if generator == "native":
        native_generator.build()  # before anything is timed: a first build takes about 25 s
    driver = GrpcDriver(address, key) if transport == "grpc" else ZmqDriver(address)
    session_ids = [await driver.open_session(session_request(scene, lens, visibility)) for _ in range(sessions)]
    period = 1.0 / rate_hz if rate_hz else 0.0
    freeze_startup_heap()  # this generator's own full collections (about 30 ms here) would read as round trips
    rtt_ms, compute_ms, received, late, stale = [], [], [0] * sessions, [0], [0]

    def recorder(k: int):
        def record(i, t_sent, t_recv, update: pb.CameraUpdate):
            received[k] += 1
            if i < warmup_frames:
                return
            rtt_ms.append((t_recv - t_sent) * 1e3)
            compute_ms.append(update.compute_ms)
            late[0] += bool(period) and (t_recv - t_sent) > period
            stale[0] += update.stale

        return record

    async with alongside(session_ids) if alongside is not None else contextlib.nullcontext():
        baseline_s = [await driver.baseline() for _ in range(20)]  # warm-up
        baseline_s = [await driver.baseline() for _ in range(500)]
        if generator == "native":
            streamed = await asyncio.to_thread(
                native_generator.stream, transport, address, session_ids, frames, period, warmup_frames, key, stride
            )
            received, rtt_ms, compute_ms = streamed["received"], streamed["rtt_ms"], streamed["compute_ms"]
            late[0], stale[0], errors = streamed["late"], streamed["stale"], streamed["errors"]
            wall_s, client_cpu_s = streamed["wall_s"], streamed["cpu_s"]
        else:
            start = time.perf_counter() + 0.1
            cpu_start_s = time.process_time()
            # sessions start staggered over one frame period; with spread_s each from its own stretch of the demo
            results = await asyncio.gather(
                *(
                    driver.run_session(
                        sid, frames[k * stride : k * stride + n_frames], period, start + k * period / sessions, recorder(k)
                    )
                    for k, sid in enumerate(session_ids)
                ),
                return_exceptions=True,
            )
            wall_s = time.perf_counter() - start
            client_cpu_s = time.process_time() - cpu_start_s  # this load generator's own CPU while streaming
            errors = [repr(r) for r in results if isinstance(r, BaseException)]
    for sid in session_ids:  # closed, not left to the server's reclaim: the next run starts on an idle server
        try:
            await driver.close_session(sid)
        except Exception as e:  # a session the server reclaimed or lost is the run's error, not a crash here
            errors.append(f"closing {sid}: {e!r}")
    await driver.close()
    sent = sessions * n_frames
    rtt = percentiles(rtt_ms)
    base = percentiles([b * 1e3 for b in baseline_s])
    return {
        "transport": transport,
        "sessions": sessions,
        "rate_hz": rate_hz,
        "seconds": seconds,
        "spread_s": spread_s,
        "wall_s": round(wall_s, 3),
        "frames_sent": sent,
        "frames_received": sum(received),
        "warmup_frames_per_session": warmup_frames,
        "dropped_frames": sent - sum(received),
        "late_frames": late[0],
        "stale_frames": stale[0],
        "rtt_ms": rtt,
        "compute_ms": percentiles(compute_ms),
        "baseline_rtt_ms": base,
        "rtt_ratio_vs_baseline": {
            "p50": rtt["p50"] / base["p50"] if rtt["p50"] else None,
            "p99": rtt["p99"] / base["p99"] if rtt["p99"] else None,
        },
        "errors": errors,
        "generator": generator,
        "cpus": os.cpu_count(),
        "client_cpu_s": round(client_cpu_s, 3),
        "client_cpu_fraction_of_core": round(client_cpu_s / wall_s, 3),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--transport", choices=("grpc", "zmq"), default="grpc")
    parser.add_argument("--sessions", type=int, default=1)
    parser.add_argument("--rate", type=float, default=60.0, help="frames per second per session (0: closed loop)")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--workers", type=int, default=None, help="server worker processes (default: cores)")
    parser.add_argument(
        "--generator", choices=GENERATORS, default="python", help="what streams: this process, or the compiled driver"
    )
    parser.add_argument(
        "--spread-s", type=float, default=0.0, help="sessions start this far apart in the demo, spread evenly (0: all at once)"
    )
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    with ServerProcess("--workers", str(workers), "--max-sessions", str(max(64, args.sessions))) as server:
        address = server.grpc if args.transport == "grpc" else server.zmq
        result = asyncio.run(
            run(args.transport, address, args.sessions, args.rate, args.seconds, generator=args.generator, spread_s=args.spread_s)
        )
        result["server_workers"] = server.ready["workers"]
    emit(result, args.json)
    return 0 if result["dropped_frames"] == 0 and not result["errors"] else 1


if __name__ == "__main__":
    sys.exit(main())
