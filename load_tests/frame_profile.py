"""Per-hop profile of one streamed frame (issue 43, item 1): where each microsecond of a round trip
goes, for each rig and transport, against a real `camdirector serve` it starts.

    python -m load_tests.frame_profile [--frames 2000] [--rigs TORIC_FRAMING_ONLY,...]
        [--transports grpc,zmq] [--workers W] [--rate HZ] [--no-record] [--bare-frames N]
        [--inline-frames N] --json FILE

One session at a time, closed loop by default (each frame sent as soon as the last is answered, as
load_tests.stream's `--rate 0`: the service's latency without an idle machine's wake-ups; `--rate`
paces them instead), for each configuration: TORIC in FRAMING_ONLY and in ANTICIPATION on the
demo scene (the scene of load_tests.stream and load_tests.capacity), TRACKS following one player
of a bot match on the shared nav_test level, MATCH directing that bot match (ten players, our
director, a 1 s delay: the match of load_tests.match_live, simulated as load_tests.real_matches'
sim_nav_test is); each over gRPC (StreamFrames) and over ZeroMQ (Frame). Sessions record
(`record`: the issue counts the recording in a frame's bookkeeping) unless `--no-record`;
checkpoints on disk (the server's default).

How each hop is timed. Every process stamps `time.perf_counter()`, which on Linux is
CLOCK_MONOTONIC, one clock for every process of the machine, so a stamp of the client, one of the
front and one of a worker subtract. The client stamps around its own encode and decode and around
the call. The server is timed from outside its source: this module is also a server plugin
(`camdirector serve --plugin load_tests.frame_profile`, ServerSettings.plugins) that, only when
the environment names a folder in PROFILE_DIR_ENV, wraps a few functions of the front and the
worker with stamps (functools.wraps, the call passed through unchanged) and writes each process's
stamps there as JSON when the process exits. Without that variable the import does nothing, and
without the plugin nothing of it is loaded: it costs a server nothing. The wrappers themselves
cost about 0.3 us each (an estimate), about a dozen per frame.

The hops (HOPS) tile a frame's round trip, so they add up to it frame by frame:
client encode (FrameUpdate.SerializeToString; building the message, the SDK's packing, is the
game's and not counted), client -> front (the client's write, the wire, the gRPC or ZeroMQ server
loop up to SessionRouter.frame), front in (the router and the pool up to the socket pair), front ->
worker (the socket pair and the worker's wake-up; a worker still busy with deferred work, its
idle_work, when the frame came is counted apart as `worker deferred work in the way`), worker loop,
worker decode (the FrameUpdate parsed once, dispatch.parse_routed), dispatch, checkpoint log
append, codec decode (codec.frame_from_msg; --frame-path compiled: codec.frame_from_wire), each
stage of `stage_ms` (the reply carries them; the wrapper reads them off the frame's state),
session (Session.frame beyond its stages), codec encode (codec.camera_update_msg; on the compiled
path also codec.camera_update_wire), timeline, snapshot check (SessionTable._after_input),
recording, table
(the rest of SessionTable.frame_bytes: the session's lookup, the reply's SerializeToString, the
answers kept), reply framing (infra/channels.encode_reply), worker -> front (the socket pair and the
front's reader task), front out (the reply's metrics, the router's counters and histograms),
front -> client (the transport back to the client's read), client decode
(CameraUpdate.FromString).

The floor, measured in the same run: a bare echo of the same transport and message sizes (the
configuration's last request and reply), served by a child process of this module on one asyncio
loop, as the front serves: a grpc.aio stream that answers each message with one of the reply's
size, and a ZeroMQ ROUTER that does the same, paced as the frames were. Its round trip is the
client's write to read, as the profile's `wire round trip` is.

What the stamps cost: `--bare-frames` frames of each configuration are streamed again into a
server started without the plugin, and their round trip is reported beside the profiled one
(`uninstrumented`). What the compiled edge makes of it: `--edge-frames` frames of each into a
server without the plugin whose gRPC port and ZeroMQ socket the edge serves (`serve --grpc-front
compiled --zmq-front compiled`), reported the same way (`edge`). What the hop to a worker costs:
`--inline-frames` frames of each into such a server that holds its sessions in the front process
(`serve --workers 0`), where the edge computes a routed session's frame on its own thread,
reported the same way (`inline`).

Printed JSON, per configuration: each hop's median, p99 and mean in us and its share of the round
trip (mean over mean: means add up, medians do not), the round trip (client encode to client
decode) and the wire round trip (write to read), the echo floor, its server's CPU per round trip
and the ratios to it, the reply's own compute_ms, the message sizes, the CPU microseconds per frame of the front, the workers and
this client (from /proc, as load_tests.capacity reads them: a session's creation included), the
worker's idle work per frame (snapshots, deferred map updates, drawn plans: off the frame's path
unless a frame arrives during it), and the machine's load average before and after (the machine
may be shared: the shares say more than the absolute values).
"""

from __future__ import annotations

import argparse
import asyncio
import atexit
import functools
import json
import multiprocessing
import os
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from camdirector.server_settings import FRAME_PATHS

FRAME_PATH_ENV = "CAMDIRECTOR_FRAME_PATH"  # ServerSettings.frame_path from the environment: the plugin wraps that path's codec
PROFILE_DIR_ENV = "CAMDIRECTOR_FRAME_PROFILE_DIR"  # the folder the server's processes write their stamps to
PLUGIN = "load_tests.frame_profile"
PYTHON_FRONTS = ("--grpc-front", "python", "--zmq-front", "python")  # the fronts whose hops the plugin stamps
COMPILED_FRONTS = ("--grpc-front", "compiled", "--zmq-front", "compiled")  # the edge (front/edge.py)
ROOT = Path(__file__).resolve().parents[1]
ECHO_SERVICE = "camdirector.profile.Echo"  # the bare echo's gRPC service, one stream method
ECHO_PATH = f"/{ECHO_SERVICE}/Stream"
RIGS = ("TORIC_FRAMING_ONLY", "TORIC_ANTICIPATION", "TRACKS", "MATCH")
TRANSPORTS = ("grpc", "zmq")
MATCH_DELAY_S = 1.0  # the MATCH session's broadcast delay: its first second of frames fills the buffer, s
RATE_HZ = 60.0  # the game time between frames (the frames are sent closed loop), Hz
HOPS = (  # in the order a frame passes them; "stage:<name>" stands where the rig's stages go
    "client_encode",
    "client_to_front",
    "front_in",
    "front_to_worker",
    "worker_deferred_work_in_the_way",
    "worker_loop",
    "worker_decode",
    "dispatch",
    "checkpoint_append",
    "codec_decode",
    "stages",
    "session",
    "codec_encode",
    "timeline",
    "snapshot_check",
    "recording",
    "table",
    "reply_framing",
    "worker_to_front",
    "front_out",
    "front_to_client",
    "client_decode",
)


# ---- the server's side: stamps taken by wrappers, written when the process exits ----------------


class _Stamps:
    """One server process's stamps: `frames[session id]` a list of one dict per frame, in order;
    `current` the frame a worker is answering (its durations summed by name, s)."""

    def __init__(self, role: str):
        self.role = role
        self.frames: dict[str, list[dict[str, Any]]] = {}
        self.current: dict[str, Any] | None = None
        self.idle: list[tuple[float, float]] = []  # a worker's idle_work calls since its last frame (start, end), s
        self.open: dict[str, dict[str, Any]] = {}  # the front's frames in flight, by session id
        self.requests: dict[int, str] = {}  # the front's request id -> session id of a frame in flight

    def done(self, session_id: str, stamps: dict[str, Any]) -> None:
        self.frames.setdefault(session_id, []).append(stamps)

    def dump(self, folder: Path) -> None:
        (folder / f"{self.role}-{os.getpid()}.json").write_text(json.dumps({"role": self.role, "frames": self.frames}))


def _adding(stamps: _Stamps, name: str, fn: Callable) -> Callable:
    """fn, its duration added to the answered frame's `name` (none answered: not counted)."""

    @functools.wraps(fn)
    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            current = stamps.current
            if current is not None:
                current[name] = current.get(name, 0.0) + time.perf_counter() - t0

    return timed


def _install_worker(stamps: _Stamps) -> None:
    from camdirector.pipeline.session import Session
    from camdirector.worker import codec, dispatch, main
    from camdirector.worker.checkpointing import Checkpointing
    from camdirector.worker.recording import RecordingWriter
    from camdirector.worker.table import SessionTable
    from camdirector.worker.timeline import Timeline

    read_request, encode_reply = main.read_request, dispatch.encode_reply  # a frame's reply is framed in dispatch.py

    @functools.wraps(read_request)
    def read_stamped(reader):
        request = read_request(reader)
        if request[1] == "frame":
            stamps.current = {"session_id": request[2], "W0": time.perf_counter(), "idle": stamps.idle}
            stamps.idle = []
        return request

    @functools.wraps(encode_reply)
    def encode_stamped(*args):
        reply = encode_reply(*args)
        current = stamps.current
        if current is not None:
            current["W_end"] = time.perf_counter()
            stamps.done(current.pop("session_id"), current)
            stamps.current = None
        return reply

    def edges(name: str, fn: Callable) -> Callable:
        """fn, its start and end stamped into the answered frame as name_in and name_out."""

        @functools.wraps(fn)
        def stamped(*args, **kwargs):
            t0 = time.perf_counter()
            result = fn(*args, **kwargs)
            if stamps.current is not None:
                stamps.current[f"{name}_in"], stamps.current[f"{name}_out"] = t0, time.perf_counter()
            return result

        return stamped

    session_frame = Session.frame

    @functools.wraps(session_frame)
    def frame_stamped(self, update):
        t0 = time.perf_counter()
        state = session_frame(self, update)
        if stamps.current is not None:
            stamps.current["session"] = time.perf_counter() - t0
            stamps.current["stage_ms"] = dict(state.stage_ms)
        return state

    idle_work = SessionTable.idle_work

    @functools.wraps(idle_work)
    def idle_stamped(self):
        t0 = time.perf_counter()
        more = idle_work(self)
        stamps.idle.append((t0, time.perf_counter()))
        return more

    main.read_request, dispatch.encode_reply = read_stamped, encode_stamped
    dispatch.parse_routed = _adding(stamps, "worker_decode", dispatch.parse_routed)
    dispatch.Dispatcher.handle_bytes = edges("handle", dispatch.Dispatcher.handle_bytes)
    SessionTable.frame_bytes = edges("table", SessionTable.frame_bytes)
    SessionTable.idle_work = idle_stamped
    SessionTable._after_input = _adding(stamps, "snapshot_check", SessionTable._after_input)
    Checkpointing.write_input = _adding(stamps, "checkpoint_append", Checkpointing.write_input)
    if os.environ.get(FRAME_PATH_ENV) == "compiled":  # the wire in camdirector._native; its decode falls back on frame_from_msg
        codec.frame_from_wire = _adding(stamps, "codec_decode", codec.frame_from_wire)
        codec.camera_update_wire = _adding(stamps, "codec_encode", codec.camera_update_wire)
    else:
        codec.frame_from_msg = _adding(stamps, "codec_decode", codec.frame_from_msg)
    codec.camera_update_msg = _adding(stamps, "codec_encode", codec.camera_update_msg)  # MATCH's on either path
    Session.frame = frame_stamped
    Timeline.add = _adding(stamps, "timeline", Timeline.add)
    RecordingWriter.write_frame_and_camera = _adding(stamps, "recording", RecordingWriter.write_frame_and_camera)


def _install_front(stamps: _Stamps) -> None:
    from camdirector.front import worker_pool
    from camdirector.front.router import SessionRouter

    router_frame = SessionRouter.frame
    encode_request, decode_reply_tail = worker_pool.encode_request, worker_pool.decode_reply_tail

    @functools.wraps(router_frame)
    async def frame_stamped(self, payload, session_id, *args, **kwargs):
        stamps.open[session_id] = {"F0": time.perf_counter()}
        try:
            body = await router_frame(self, payload, session_id, *args, **kwargs)
        except BaseException:
            stamps.open.pop(session_id, None)
            raise
        frame = stamps.open.pop(session_id)
        frame["F3"] = time.perf_counter()
        stamps.done(session_id, frame)
        return body

    @functools.wraps(encode_request)
    def encode_stamped(request_id, op, session_id, payload):
        parts = encode_request(request_id, op, session_id, payload)
        frame = stamps.open.get(session_id)
        if op == "frame" and frame is not None:
            frame["F1"] = time.perf_counter()
            stamps.requests[request_id] = session_id
        return parts

    @functools.wraps(decode_reply_tail)
    def decode_stamped(header, tail):
        session_id = stamps.requests.pop(header[0], None)
        if session_id is not None and session_id in stamps.open:
            stamps.open[session_id]["F2"] = time.perf_counter()
        return decode_reply_tail(header, tail)

    SessionRouter.frame = frame_stamped
    worker_pool.encode_request, worker_pool.decode_reply_tail = encode_stamped, decode_stamped


def _install_if_asked() -> None:
    """Imported as a server plugin with PROFILE_DIR_ENV set: the process's wrappers, and its
    stamps written there at exit (a worker's after the front's "stop", the front's after its shutdown)."""
    folder = os.environ.get(PROFILE_DIR_ENV)
    if not folder:
        return
    is_worker = multiprocessing.current_process().name.startswith("camdirector-worker-")
    stamps = _Stamps("worker" if is_worker else "front")
    (_install_worker if is_worker else _install_front)(stamps)
    atexit.register(stamps.dump, Path(folder))


_install_if_asked()


# ---- the bare echo floor ---------------------------------------------------------------------


def echo_request(request_bytes: int, reply_bytes: int) -> bytes:
    """A request of request_bytes (at least 4) asking the echo for reply_bytes back."""
    return struct.pack("<I", reply_bytes) + b"\0" * max(0, request_bytes - 4)


_replies: dict[int, bytes] = {}  # the echo's replies by size, made once


def _echo_reply(request: bytes) -> bytes:
    """The echo's answer to an echo_request: as many bytes as it asks for."""
    size = struct.unpack_from("<I", request)[0]
    return _replies.setdefault(size, b"\1" * size)


def echo_grpc_handler():
    """The echo's gRPC service (ECHO_PATH): a stream answering each message with _echo_reply."""
    import grpc

    async def stream(requests, context):
        async for request in requests:
            yield _echo_reply(request)

    handler = grpc.stream_stream_rpc_method_handler(stream)
    return grpc.method_handlers_generic_handler(ECHO_SERVICE, {"Stream": handler})


async def _echo_serve() -> None:
    import grpc
    import zmq
    import zmq.asyncio

    # Without SO_REUSEPORT, as the front's server (front/grpc_service.py): the port is this echo's alone.
    server = grpc.aio.server(options=[("grpc.so_reuseport", 0)])
    server.add_generic_rpc_handlers((echo_grpc_handler(),))
    port = server.add_insecure_port("127.0.0.1:0")
    if port == 0:
        raise OSError("the echo could not bind gRPC to 127.0.0.1")
    await server.start()  # listening since add_insecure_port: the ready line below follows it
    sock = zmq.asyncio.Context.instance().socket(zmq.ROUTER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.bind("tcp://127.0.0.1:*")
    print(json.dumps({"grpc": f"127.0.0.1:{port}", "zmq": sock.getsockopt_string(zmq.LAST_ENDPOINT)}), flush=True)
    while True:
        identity, _, payload = await sock.recv_multipart()
        await sock.send_multipart([identity, b"0", _echo_reply(payload)])


class EchoServer:
    """The bare echo in a child process (this module's `--echo-server`), for a `with` block."""

    def __enter__(self) -> EchoServer:
        self.proc = subprocess.Popen([sys.executable, "-m", PLUGIN, "--echo-server"], stdout=subprocess.PIPE, text=True, cwd=ROOT)
        assert self.proc.stdout is not None
        self.address = json.loads(self.proc.stdout.readline())
        return self

    def __exit__(self, *exc: object) -> None:
        self.proc.terminate()
        self.proc.wait(10)


# ---- the client's side -----------------------------------------------------------------------


class _Grpc:
    """Bytes over gRPC: CreateSession and CloseSession unary, frames on one StreamFrames stream."""

    def __init__(self, address: str):
        import grpc

        # A channel of its own to the address: with gRPC's global subchannel pool a new channel
        # takes over the connection of any channel of this process still open to the same address,
        # with its state; one that met a server gone from that port (a port the echo or a server
        # was later given again) is in its reconnect backoff, and the first call fails at once
        # UNAVAILABLE "Connection refused" though the new server listens (how a CI run's echo
        # floor once failed right after the echo's ready line).
        options = [("grpc.max_send_message_length", 64 << 20), ("grpc.use_local_subchannel_pool", 1)]
        self.channel = grpc.aio.insecure_channel(address, options=options)
        self.stream_method = self.channel.stream_stream("/camdirector.v1.Director/StreamFrames")

    async def unary(self, rpc: str, payload: bytes) -> bytes:
        return await self.channel.unary_unary(f"/camdirector.v1.Director/{rpc}")(payload)

    def frames(self, path: str | None = None):
        call = (self.stream_method if path is None else self.channel.stream_stream(path))()

        async def round_trip(payload: bytes) -> bytes:
            await call.write(payload)
            return await call.read()

        return round_trip, call.done_writing

    async def close(self) -> None:
        await self.channel.close()


class _Zmq:
    """Bytes over ZeroMQ: [RPC, payload] on a DEALER socket, [status, reply] back."""

    def __init__(self, address: str):
        import zmq
        import zmq.asyncio

        self.ctx = zmq.asyncio.Context()
        self.sock = self.ctx.socket(zmq.DEALER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.connect(address)

    async def unary(self, rpc: str, payload: bytes) -> bytes:
        await self.sock.send_multipart([rpc.encode(), payload])
        code, body = await self.sock.recv_multipart()
        if code != b"0":
            raise RuntimeError(f"{rpc}: {code.decode()} {body.decode(errors='replace')}")
        return body

    def frames(self, path: str | None = None):
        rpc = b"Frame" if path is None else b"Echo"

        async def round_trip(payload: bytes) -> bytes:
            await self.sock.send_multipart([rpc, payload])
            code, body = await self.sock.recv_multipart()
            if code != b"0":
                raise RuntimeError(f"Frame: {code.decode()} {body.decode(errors='replace')}")
            return body

        async def done() -> None:
            pass

        return round_trip, done

    async def close(self) -> None:
        self.sock.close()
        self.ctx.term()


def _client(transport: str, address: str):
    return _Grpc(address) if transport == "grpc" else _Zmq(address)


@dataclass(frozen=True)
class Workload:
    """One rig's session: its CreateSessionRequest and its frames (FrameUpdates without a session
    id, frame numbers rising), `warmup` of them answered but left out of the profile."""

    rig: str
    request: Any
    frames: list[Any]
    warmup: int


def workloads(rigs: list[str], n_frames: int, warmup: int, match, record: bool) -> Iterator[Workload]:
    """The configurations' sessions (module docstring); `match` the bot match of TRACKS and MATCH."""
    from camdirector.demo.client import frame_updates as demo_frames
    from camdirector.demo.client import session_request
    from camdirector.demo.scene import build_demo_scene
    from camdirector.evaluation.match.session_feed import Feed, match_session_fields, player_targets
    from camdirector.evaluation.match.session_feed import frame_updates as match_frames
    from camdirector.geometry.camera import Lens
    from camdirector.v1 import director_pb2 as pb
    from camdirector_client import wire

    class Unnamed:  # session_feed.frame_updates asks its session for each update; the id is set per run
        frame_update = staticmethod(functools.partial(wire.frame_update, ""))

    scene = build_demo_scene(seed=7, duration_s=(n_frames + warmup) / RATE_HZ + 1.0)
    for rig in rigs:
        if rig.startswith("TORIC_"):
            request = session_request(scene, Lens(), pb.VisibilityMode.Value(rig.removeprefix("TORIC_")))
            frames = list(demo_frames(scene, n_frames + warmup, RATE_HZ))
            rig_warmup = warmup
        elif rig == "TRACKS":
            player = match.players[0].id
            request = pb.CreateSessionRequest(
                targets=player_targets(match, [player]),
                level_id=match.level,
                seed=1,
                style=pb.Style(rig=pb.RIG_TRACKS, shot_size=pb.SHOT_SIZE_LONG, movement=pb.MOVEMENT_DYNAMIC_WITH_CUTS),
            )
            frames = list(match_frames(Unnamed(), match, Feed.of(match, RATE_HZ, 0.0), [0], events=False))
            rig_warmup = warmup
        else:
            request = pb.CreateSessionRequest(**match_session_fields(match, "planned", MATCH_DELAY_S, 1))
            columns = list(range(len(match.players)))
            frames = list(match_frames(Unnamed(), match, Feed.of(match, RATE_HZ, MATCH_DELAY_S), columns, events=True))
            rig_warmup = warmup + int(MATCH_DELAY_S * RATE_HZ)  # while the delay fills there is no pose
        request.record = record
        frames = frames[: n_frames + rig_warmup]
        if len(frames) < n_frames + rig_warmup:
            raise ValueError(f"{rig}: the match gives {len(frames)} frames, {n_frames + rig_warmup} wanted")
        yield Workload(rig, request, frames, rig_warmup)


async def stream_session(
    transport: str, address: str, work: Workload, rate_hz: float
) -> tuple[str, list[tuple[float, ...]], list[float], list[int]]:
    """The workload streamed into a new session (closed after), closed loop (rate_hz 0) or a frame
    every 1/rate_hz s of wall time; its id, the client's stamps (C0 encode starts, C1 encode done
    and sent, C2 the reply read, C3 decoded; s) of every frame, warm-up included, each reply's
    compute_ms, and the sizes of the last request and reply."""
    from camdirector.v1 import director_pb2 as pb

    client = _client(transport, address)
    session_id = pb.CreateSessionResponse.FromString(
        await client.unary("CreateSession", work.request.SerializeToString())
    ).session_id
    round_trip, done = client.frames()
    stamps, compute_ms, sizes = [], [], [0, 0]
    start_s = time.perf_counter()
    for i, update in enumerate(work.frames):
        update.session_id = session_id
        if rate_hz:
            await asyncio.sleep(max(0.0, start_s + i / rate_hz - time.perf_counter()))
        c0 = time.perf_counter()
        payload = update.SerializeToString()
        c1 = time.perf_counter()
        body = await round_trip(payload)
        c2 = time.perf_counter()
        reply = pb.CameraUpdate.FromString(body)
        c3 = time.perf_counter()
        stamps.append((c0, c1, c2, c3))
        compute_ms.append(reply.compute_ms)
        sizes = [len(payload), len(body)]
    await done()
    await client.unary("CloseSession", pb.CloseSessionRequest(session_id=session_id).SerializeToString())
    await client.close()
    return session_id, stamps, compute_ms, sizes


def echo_floor(
    echo: EchoServer, transport: str, request_bytes: int, reply_bytes: int, n: int, rate_hz: float
) -> tuple[list[float], float | None]:
    """n round trips (write to read, s) of the bare echo at these sizes, after 50 unmeasured,
    paced as the frames were (rate_hz; 0: closed loop), and the echo process's CPU per round trip
    meanwhile (s; None where /proc cannot tell)."""
    from load_tests.capacity import server_cpu_s

    before = server_cpu_s(echo.proc.pid)
    times = asyncio.run(
        _echo_round_trips(transport, echo.address[transport], echo_request(request_bytes, reply_bytes), n, rate_hz)
    )
    after = server_cpu_s(echo.proc.pid)
    cpu_s = None if before is None or after is None else (after["front"] - before["front"]) / (n + 50)
    return times, cpu_s


async def _echo_round_trips(transport: str, address: str, payload: bytes, n: int, rate_hz: float) -> list[float]:
    client = _client(transport, address)
    round_trip, done = client.frames(ECHO_PATH)
    times = []
    start_s = time.perf_counter()
    for i in range(n + 50):
        if rate_hz:
            await asyncio.sleep(max(0.0, start_s + i / rate_hz - time.perf_counter()))
        t0 = time.perf_counter()
        await round_trip(payload)
        if i >= 50:
            times.append(time.perf_counter() - t0)
    await done()
    await client.close()
    return times


# ---- the hops ------------------------------------------------------------------------------------


def _overlap_s(intervals: list[tuple[float, float]], start: float, end: float) -> float:
    return sum(max(0.0, min(e, end) - max(s, start)) for s, e in intervals)


def frame_hops(client: tuple[float, ...], front: dict[str, Any], worker: dict[str, Any]) -> dict[str, float]:
    """One frame's hops (HOPS, the stages as "stage:<name>"), s, from its stamps: the client's
    (C0, C1, C2, C3), the front's and the worker's. They add up to C3 - C0."""
    c0, c1, c2, c3 = client
    in_the_way = _overlap_s(worker["idle"], front["F1"], worker["W0"])
    stage_s = {f"stage:{k}": v / 1e3 for k, v in worker.get("stage_ms", {}).items()}
    table_s = worker["table_out"] - worker["table_in"]
    parts = ("checkpoint_append", "codec_decode", "session", "codec_encode", "timeline", "snapshot_check", "recording")
    handled_s = worker["handle_out"] - worker["handle_in"]
    hops = {
        "client_encode": c1 - c0,
        "client_to_front": front["F0"] - c1,
        "front_in": front["F1"] - front["F0"],
        "front_to_worker": worker["W0"] - front["F1"] - in_the_way,
        "worker_deferred_work_in_the_way": in_the_way,
        "worker_loop": worker["handle_in"] - worker["W0"],
        "worker_decode": worker.get("worker_decode", 0.0),
        "dispatch": handled_s - worker.get("worker_decode", 0.0) - table_s,
        "checkpoint_append": worker.get("checkpoint_append", 0.0),
        "codec_decode": worker.get("codec_decode", 0.0),
        **stage_s,
        "session": worker.get("session", 0.0) - sum(stage_s.values()),
        "codec_encode": worker.get("codec_encode", 0.0),
        "timeline": worker.get("timeline", 0.0),
        "snapshot_check": worker.get("snapshot_check", 0.0),
        "recording": worker.get("recording", 0.0),
        "table": table_s - sum(worker.get(k, 0.0) for k in parts),
        "reply_framing": worker["W_end"] - worker["handle_out"],
        "worker_to_front": front["F2"] - worker["W_end"],
        "front_out": front["F3"] - front["F2"],
        "front_to_client": c2 - front["F3"],
        "client_decode": c3 - c2,
    }
    return hops


def _stats_us(values_s) -> dict[str, float]:
    a = np.asarray(values_s, dtype=np.float64) * 1e6
    return {
        "median_us": round(float(np.median(a)), 1),
        "p99_us": round(float(np.percentile(a, 99)), 1),
        "mean_us": round(float(a.mean()), 1),
    }


def profile(hops: list[dict[str, float]], client: list[tuple[float, ...]]) -> dict[str, Any]:
    """The configuration's hops over its measured frames: each hop's median, p99 and mean (us)
    and its share of the round trip (its mean over the round trip's mean), in HOPS's order with
    the stages where "stages" stands; the round trip and the wire round trip."""
    from camdirector.pipeline.stages import MatchStage, Stage, TracksStage

    seen = {k for h in hops for k in h if k.startswith("stage:")}
    order = [f"stage:{s.value}" for kind in (Stage, TracksStage, MatchStage) for s in kind]
    stages = sorted(seen, key=lambda k: order.index(k) if k in order else len(order))
    names = [n for hop in HOPS for n in (stages if hop == "stages" else [hop])]
    round_trip_s = np.array([c[3] - c[0] for c in client])
    table = {}
    for name in names:
        stats = _stats_us([h.get(name, 0.0) for h in hops])
        table[name] = {**stats, "share": round(stats["mean_us"] / (round_trip_s.mean() * 1e6), 4)}
    sums = np.array([sum(h.values()) for h in hops])
    return {
        # a hop below -1 ns in some frame would say the stamps are taken out of order
        "negative_hop_frames": sum(min(h.values()) < -1e-9 for h in hops),
        "round_trip_us": _stats_us(round_trip_s),
        "wire_round_trip_us": _stats_us([c[2] - c[1] for c in client]),
        "hops": table,
        "hops_sum_mean_us": round(float(sums.mean()) * 1e6, 1),
        "hops_sum_over_round_trip_max": round(float(np.max(sums / round_trip_s)), 6),
    }


def _server_stamps(folder: Path) -> tuple[dict[str, list], dict[str, list]]:
    """The front's and the workers' stamps by session id, from the files the server's processes wrote."""
    front: dict[str, list] = {}
    worker: dict[str, list] = {}
    for path in sorted(folder.glob("*.json")):
        data = json.loads(path.read_text())
        (front if data["role"] == "front" else worker).update(data["frames"])
    return front, worker


def _prepared_match(folder: Path, frames: int):
    """The bot match of TRACKS and MATCH on nav_test, its level added in folder/data (the server's
    data folder), long enough for `frames` frames at RATE_HZ after the delay."""
    from load_tests.real_matches import prepare

    return prepare("sim_nav_test", folder, (frames / RATE_HZ + MATCH_DELAY_S + 2.0) / 60.0)


@dataclass
class Streamed:
    """One configuration streamed: the client's stamps (stream_session), the replies' compute_ms,
    the sizes of a request and a reply, the CPU seconds spent meanwhile by the server's front, its
    workers and this client (a session's creation and close included), and the load average
    before and after."""

    work: Workload
    transport: str
    session_id: str
    client: list[tuple[float, ...]]
    compute_ms: list[float]
    sizes: list[int]
    cpu_s: dict[str, float]
    load: dict[str, list[float]]


def _stream_all(server, works: list[Workload], transports: list[str], rate_hz: float) -> list[Streamed]:
    """Each workload over each transport into the server, one session after another."""
    from load_tests.capacity import server_cpu_s

    for transport in transports:  # a server's first session pays its imports and caches: not measured
        first = works[0]
        address = server.grpc if transport == "grpc" else server.zmq
        asyncio.run(
            stream_session(transport, address, Workload(first.rig, first.request, first.frames[: first.warmup + 1], 0), 0.0)
        )
    done = []
    for work in works:
        for transport in transports:
            address = server.grpc if transport == "grpc" else server.zmq
            load_before, cpu_before, client_before = os.getloadavg(), server_cpu_s(server.proc.pid), time.process_time()
            session_id, client, compute_ms, sizes = asyncio.run(stream_session(transport, address, work, rate_hz))
            cpu_after = server_cpu_s(server.proc.pid)
            cpu_s = {"client": time.process_time() - client_before}
            if cpu_before is not None and cpu_after is not None:
                cpu_s.update({k: cpu_after[k] - cpu_before[k] for k in cpu_before})
            load = {"before": [round(v, 2) for v in load_before], "after": [round(v, 2) for v in os.getloadavg()]}
            done.append(Streamed(work, transport, session_id, client, compute_ms, sizes, cpu_s, load))
            print(f"frame_profile: {work.rig} over {transport}: {len(client)} frames", file=sys.stderr, flush=True)
    return done


def _config(
    run: Streamed,
    front: list[dict],
    worker: list[dict],
    floor_s: tuple[list[float], float | None],
    bare: Streamed | None,
    inline: Streamed | None = None,
    edge: Streamed | None = None,
) -> dict:
    """One configuration's report (module docstring) from its stamps, its echo floor and its
    round trips against the server without the plugin (`bare`) and against one holding its
    sessions in the front (`inline`)."""
    work, client = run.work, run.client
    if len(front) != len(client) or len(worker) != len(client):
        raise RuntimeError(
            f"{work.rig} over {run.transport}: {len(client)} frames sent, "
            f"the front stamped {len(front)} and the worker {len(worker)}"
        )
    measured = range(work.warmup, len(client))
    result = profile([frame_hops(client[i], front[i], worker[i]) for i in measured], [client[i] for i in measured])
    floor = _stats_us(floor_s[0])
    compute_ms = run.compute_ms[work.warmup :]
    idle_s = sum(e - s for i in measured for s, e in worker[i]["idle"])
    report = {
        "rig": work.rig,
        "transport": run.transport,
        "frames": len(measured),
        "warmup_frames": work.warmup,
        "request_bytes": run.sizes[0],
        "reply_bytes": run.sizes[1],
        "load_average": run.load,
        "echo_floor_us": floor,
        "echo_server_cpu_us_per_round_trip": None if floor_s[1] is None else round(floor_s[1] * 1e6, 1),
        "round_trip_over_echo_p50": round(result["round_trip_us"]["median_us"] / floor["median_us"], 2),
        "wire_round_trip_over_echo_p50": round(result["wire_round_trip_us"]["median_us"] / floor["median_us"], 2),
        "compute_ms_reported": {
            "median": round(float(np.median(compute_ms)), 3),
            "p99": round(float(np.percentile(compute_ms, 99)), 3),
        },
        # the worker's idle_work (snapshots, deferred map updates, drawn plans): CPU off the frame's path
        "worker_idle_work_us_per_frame": round(idle_s / len(measured) * 1e6, 1),
        "cpu_us_per_frame": {k: round(v / len(client) * 1e6, 1) for k, v in run.cpu_s.items()},
        **result,
    }
    if bare is not None:
        report["uninstrumented"] = _unstamped(bare, floor)
    if inline is not None:
        report["inline"] = _unstamped(inline, floor)
    if edge is not None:
        report["edge"] = _unstamped(edge, floor)
    return report


def _unstamped(streamed: Streamed, floor: dict[str, float]) -> dict:
    """The report of frames streamed into a server without the plugin: their round trip, its
    ratio to the echo's, the compute_ms they reported and the CPU per frame."""
    rtt = _stats_us([c[3] - c[0] for c in streamed.client[streamed.work.warmup :]])
    compute_ms = streamed.compute_ms[streamed.work.warmup :]
    return {
        "frames": len(streamed.client) - streamed.work.warmup,
        "round_trip_us": rtt,
        # without the stamps, a few of which (the checkpoint's, the codec's, the session's) run inside compute_ms
        "compute_ms_reported": {
            "median": round(float(np.median(compute_ms)), 3),
            "p99": round(float(np.percentile(compute_ms, 99)), 3),
        },
        "round_trip_over_echo_p50": round(rtt["median_us"] / floor["median_us"], 2),
        "cpu_us_per_frame": {k: round(v / len(streamed.client) * 1e6, 1) for k, v in streamed.cpu_s.items()},
    }


def run(
    rigs: list[str],
    transports: list[str],
    n_frames: int,
    warmup: int,
    workers: int,
    record: bool,
    bare_frames: int,
    rate_hz: float = 0.0,
    frame_path: str = "python",
    inline_frames: int = 0,
    edge_frames: int = 0,
) -> dict:
    """The profile (module docstring); then, with bare_frames > 0, that many frames of each
    configuration against a server without the plugin: what the stamps cost; with inline_frames >
    0, that many against a server without the plugin holding its sessions in the front (`serve
    --workers 0`) behind the compiled edge: what the hop to a worker costs; with edge_frames > 0,
    that many against a server without the plugin whose gRPC port and ZeroMQ socket the compiled
    edge serves. frame_path: the servers' (`serve --frame-path`)."""
    from camdirector.deploy.server_process import ServerProcess

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="frame-profile-") as tmp:
        folder, stamps_dir = Path(tmp), Path(tmp) / "stamps"
        stamps_dir.mkdir()
        # as many frames as the longest run takes: each run streams its own count of them
        longest = max(n_frames, bare_frames, inline_frames, edge_frames)
        match = _prepared_match(folder, longest + warmup) if {"TRACKS", "MATCH"} & set(rigs) else None
        works = list(workloads(rigs, longest, warmup, match, record))
        serve_args = ("--workers", str(workers), "--data-dir", str(folder / "data"))
        env = {
            PROFILE_DIR_ENV: str(stamps_dir),
            FRAME_PATH_ENV: frame_path,
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        }
        # the Python fronts, whose hops the plugin stamps (the compiled edge's are measured apart: --edge-frames)
        with ServerProcess(*serve_args, "--plugin", PLUGIN, *PYTHON_FRONTS, env=env) as server:
            runs = _stream_all(server, _first(works, n_frames), transports, rate_hz)
            server_workers = server.ready.get("workers")
        front, worker = _server_stamps(stamps_dir)  # written as the server stopped
        with EchoServer() as echo:
            floors = [echo_floor(echo, r.transport, r.sizes[0], r.sizes[1], n_frames, rate_hz) for r in runs]
        bare = _unprofiled(works, transports, rate_hz, bare_frames, serve_args, frame_path)
        inline_args = ("--workers", "0", "--data-dir", str(folder / "data-inline"), *COMPILED_FRONTS)
        inline = _unprofiled(works, transports, rate_hz, inline_frames, inline_args, frame_path)
        edge_args = ("--workers", str(workers), "--data-dir", str(folder / "data-edge"), *COMPILED_FRONTS)
        edge = _unprofiled(works, transports, rate_hz, edge_frames, edge_args, frame_path)
        configs = [
            _config(r, front[r.session_id], worker[r.session_id], floor, b, i, e)
            for r, floor, b, i, e in zip(runs, floors, bare, inline, edge)
        ]
    return {
        "benchmark": "frame_profile",
        "frames_per_config": n_frames,
        "rate_hz": rate_hz or None,  # None: closed loop
        "frame_path": frame_path,
        "recording": record,
        "server_workers": server_workers,
        "cpus": os.cpu_count(),
        "wall_s": round(time.perf_counter() - t0, 1),
        "configs": configs,
    }


def _unprofiled(
    works: list[Workload],
    transports: list[str],
    rate_hz: float,
    frames: int,
    serve_args: tuple[str, ...],
    frame_path: str,
) -> list[Streamed | None]:
    """`frames` frames of each configuration (in the profile's order) streamed into a server started
    with serve_args and without the plugin; a None for each when frames is 0."""
    from camdirector.deploy.server_process import ServerProcess

    if frames == 0:
        return [None] * (len(works) * len(transports))
    if "--grpc-front" not in serve_args:  # the fronts the stamped server ran
        serve_args = (*serve_args, *PYTHON_FRONTS)
    with ServerProcess(*serve_args, env={FRAME_PATH_ENV: frame_path}) as server:
        return list(_stream_all(server, _first(works, frames), transports, rate_hz))


def _first(works: list[Workload], frames: int) -> list[Workload]:
    """Each workload's warmup and its first `frames` frames after it."""
    return [Workload(w.rig, w.request, w.frames[: w.warmup + frames], w.warmup) for w in works]


def _names(text: str, allowed: tuple[str, ...], what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names or any(n not in allowed for n in names):
        raise argparse.ArgumentTypeError(f"{what} must be among {', '.join(allowed)}; got {text!r}")
    return names


def main(argv=None) -> int:
    from load_tests.report import emit

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000, help="frames profiled per rig and transport")
    parser.add_argument("--warmup", type=int, default=20, help="frames answered first and not profiled (MATCH: plus its delay)")
    parser.add_argument("--rigs", default=",".join(RIGS), help="comma-separated, among " + ", ".join(RIGS))
    parser.add_argument("--transports", default=",".join(TRANSPORTS), help="grpc, zmq or both, comma-separated")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="server worker processes (>= 1)")
    parser.add_argument("--rate", type=float, default=0.0, help="frames a second of wall time (0: closed loop)")
    parser.add_argument("--no-record", action="store_true", help="sessions that do not record")
    parser.add_argument("--frame-path", dest="frame_path", choices=FRAME_PATHS, default="python", help="the servers' frame path")
    parser.add_argument(
        "--bare-frames", type=int, default=500, help="frames per configuration against a server without the plugin (0: none)"
    )
    parser.add_argument(
        "--inline-frames",
        type=int,
        default=0,
        help="frames per configuration against a server holding its sessions in the front, without the plugin (0: none)",
    )
    parser.add_argument(
        "--edge-frames",
        type=int,
        default=0,
        help="frames per configuration against a server whose gRPC port the compiled edge serves, without the plugin (0: none)",
    )
    parser.add_argument("--echo-server", action="store_true", help=argparse.SUPPRESS)  # the floor's child process
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    if args.echo_server:
        asyncio.run(_echo_serve())
        return 0
    try:
        rigs = _names(args.rigs, RIGS, "--rigs")
        transports = _names(args.transports, TRANSPORTS, "--transports")
    except argparse.ArgumentTypeError as exc:
        parser.error(str(exc))
    if (
        args.frames < 1
        or args.warmup < 0
        or args.workers < 1
        or min(args.bare_frames, args.inline_frames, args.edge_frames, args.rate) < 0
    ):
        parser.error(
            "--frames and --workers must be positive; --warmup, --bare-frames, --inline-frames, --edge-frames and --rate "
            "not negative"
        )
    emit(
        run(
            rigs,
            transports,
            args.frames,
            args.warmup,
            args.workers,
            not args.no_record,
            args.bare_frames,
            args.rate,
            args.frame_path,
            args.inline_frames,
            args.edge_frames,
        ),
        args.json,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
