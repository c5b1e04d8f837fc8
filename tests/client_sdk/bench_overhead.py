"""Client-side overhead of a frame call, against the fake director in a separate process.

    .venv/bin/python tests/client_sdk/bench_overhead.py [--frames 3000] [--objects 50]

Prints JSON: median round trip of ``Session.frame`` (packed states from NumPy arrays) next to the
same round trip made with the bare transport (a prebuilt message on a raw stub or DEALER socket),
the two alternating call by call, their difference (what the SDK adds per call), and the SDK's
in-process cost alone (encode the FrameUpdate, parse a reply) with no network. Not collected by
pytest.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import grpc
import grpc.aio
import numpy as np
import zmq
import zmq.asyncio

import camdirector_client as cd
from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc
from camdirector_client import wire


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def median_us(samples: list[float]) -> float:
    return round(statistics.median(samples) * 1e6, 1)


def interleaved(sdk_call, raw_call, n: int, warmup: int) -> dict[str, float]:
    """Alternates the two calls so that drift in machine load hits both alike."""
    for i in range(warmup):
        sdk_call(i)
        raw_call(i)
    sdk, raw = [], []
    clock = time.perf_counter
    for i in range(warmup, warmup + n):
        started = clock()
        sdk_call(i)
        middle = clock()
        raw_call(i)
        sdk.append(middle - started)
        raw.append(clock() - middle)
    return report(sdk, raw)


async def interleaved_async(sdk_call, raw_call, n: int, warmup: int) -> dict[str, float]:
    for i in range(warmup):
        await sdk_call(i)
        await raw_call(i)
    sdk, raw = [], []
    clock = time.perf_counter
    for i in range(warmup, warmup + n):
        started = clock()
        await sdk_call(i)
        middle = clock()
        await raw_call(i)
        sdk.append(middle - started)
        raw.append(clock() - middle)
    return report(sdk, raw)


def report(sdk: list[float], raw: list[float]) -> dict[str, float]:
    return {
        "sdk_frame_us": median_us(sdk),
        "raw_transport_us": median_us(raw),
        "overhead_us": round(median_us(sdk) - median_us(raw), 1),
    }


def timed(call, n: int, warmup: int) -> list[float]:
    for i in range(warmup):
        call(i)
    samples = []
    clock = time.perf_counter
    for i in range(warmup, warmup + n):
        started = clock()
        call(i)
        samples.append(clock() - started)
    return samples


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", type=int, default=3000)
    parser.add_argument("--objects", type=int, default=50)
    args = parser.parse_args()
    n, warmup = args.frames, 300

    rng = np.random.default_rng(1)
    ids = [f"obj{i}" for i in range(args.objects)]
    positions = rng.normal(size=(args.objects, 3))
    rotations = rng.normal(size=(args.objects, 4))
    rotations /= np.linalg.norm(rotations, axis=1, keepdims=True)

    grpc_port, zmq_port = free_port(), free_port()
    server = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("fake_director.py")), str(grpc_port), str(zmq_port)],
        stdout=subprocess.PIPE,
        text=True,
    )
    results: dict[str, dict[str, float]] = {}
    try:
        server.stdout.readline()  # "serving ..."
        packed = cd.pack_states(ids, positions, rotations)

        # In-process cost, no network: encode a frame, parse a reply; pack_states apart.
        reply_bytes = pb.CameraUpdate(frame=1, pose=pb.CameraPose(vertical_fov_deg=50)).SerializeToString()

        def cpu_only(i):
            wire.encode_frame_update("s1", i, i / 60, None, packed)
            pb.CameraUpdate.FromString(reply_bytes)

        results["sdk_cpu_only"] = {
            "encode_frame_and_parse_reply_us": median_us(timed(cpu_only, n, warmup)),
            "pack_states_us": median_us(timed(lambda i: cd.pack_states(ids, positions, rotations), n, warmup)),
        }

        for name, url in (("grpc", f"grpc://127.0.0.1:{grpc_port}"), ("zmq", f"tcp://127.0.0.1:{zmq_port}")):
            with cd.connect(url) as client, client.create_session(targets=[pb.Target(id="obj0")]) as session:
                prebuilt = session.frame_update(1, 0.0, packed=packed)

                def sdk_call(i):
                    return session.frame(i, i / 60, packed=packed)

                if name == "grpc":
                    channel = grpc.insecure_channel(f"127.0.0.1:{grpc_port}")
                    stub = director_pb2_grpc.DirectorStub(channel)
                    results[f"{name}_sync"] = interleaved(sdk_call, lambda i: stub.Frame(prebuilt), n, warmup)
                    channel.close()
                else:
                    sock = zmq.Context.instance().socket(zmq.DEALER)
                    sock.connect(url)
                    request = [b"Frame", prebuilt.SerializeToString()]

                    def raw_call(i):
                        sock.send_multipart(request)
                        return sock.recv_multipart()

                    results[f"{name}_sync"] = interleaved(sdk_call, raw_call, n, warmup)
                    sock.close(linger=0)

        async def run_async():
            for name, url in (("grpc", f"grpc://127.0.0.1:{grpc_port}"), ("zmq", f"tcp://127.0.0.1:{zmq_port}")):
                async with cd.connect_async(url) as client, client.create_session(targets=[pb.Target(id="obj0")]) as session:
                    prebuilt = session.frame_update(1, 0.0, packed=packed)

                    def sdk_call(i):
                        return session.frame(i, i / 60, packed=packed)

                    if name == "grpc":
                        channel = grpc.aio.insecure_channel(f"127.0.0.1:{grpc_port}")
                        stub = director_pb2_grpc.DirectorStub(channel)
                        results[f"{name}_async"] = await interleaved_async(sdk_call, lambda i: stub.Frame(prebuilt), n, warmup)
                        await channel.close()
                    else:
                        sock = zmq.asyncio.Context.instance().socket(zmq.DEALER)
                        sock.connect(url)
                        request = [b"Frame", prebuilt.SerializeToString()]

                        async def raw_call(i):
                            await sock.send_multipart(request)
                            return await sock.recv_multipart()

                        results[f"{name}_async"] = await interleaved_async(sdk_call, raw_call, n, warmup)
                        sock.close(linger=0)

        asyncio.run(run_async())
    finally:
        server.terminate()
        server.wait()
    print(json.dumps({"frames": n, "objects": args.objects, "results": results}, indent=2))


if __name__ == "__main__":
    main()
