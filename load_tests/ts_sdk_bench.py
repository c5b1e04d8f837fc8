"""A frame's round trip through the TypeScript SDK (client_sdk/typescript) against the Python
SDK's, over gRPC, into one server in the same run (issue 28 bounds the ratio at 1.3).

    python -m load_tests.ts_sdk_bench --frames 500 --rounds 4 --json FILE

Each round runs both SDKs, the Python SDK first in even rounds and the TypeScript SDK
(`node bench/frame_rtt.mjs`, started outside the timing) first in odd ones, so that a load on the
machine that drifts during the run weighs on both alike; each on a new session of the same scene
(two capsules) with the same packed transforms: unary `Frame` calls one after another, then one
`StreamFrames` call with one update in flight (the next update is built when the last reply
came). A round trip is timed at the caller, building the update included. Reported per SDK and
mode: median and p99 (ms) over all rounds; `ratio` = TypeScript median / Python median. Needs
`npm ci && npm run build` in client_sdk/typescript first.
"""

from __future__ import annotations

import argparse
import json
import math
import queue
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import camdirector_client as cd
from camdirector.deploy.server_process import ServerProcess
from load_tests.report import emit, summary

PACKAGE = Path(__file__).resolve().parents[1] / "client_sdk" / "typescript"


def scene() -> cd.pb.CreateSessionRequest:
    capsule = cd.pb.Mesh(primitive=cd.pb.Primitive(capsule=cd.pb.Primitive.Capsule(radius=0.3, height=1.8)))
    return cd.pb.CreateSessionRequest(
        seed=1,
        style=cd.pb.Style(visibility=cd.pb.FRAMING_ONLY),
        targets=[
            cd.pb.Target(id="a", mesh=capsule, transform=cd.transform_msg([0, 0.9, 0])),
            cd.pb.Target(id="b", mesh=capsule, transform=cd.transform_msg([3, 0.9, 1])),
        ],
    )


def packed_at(i: int):
    t = i / 60
    return cd.pack_states(
        ["a", "b"],
        np.array([[math.sin(t), 0.9, t], [3 - t, 0.9, 1.0]]),
        np.array([[0, math.sin(t / 4), 0, math.cos(t / 4)], [0, 0, 0, 1.0]]),
    )


def python_round(url: str, frames: int, warmup: int) -> dict[str, list[float]]:
    unary, stream = [], []
    with cd.connect(url) as client:
        with client.create_session(scene()) as session:
            i = 1
            for k in range(warmup + frames):
                t0 = time.perf_counter()
                session.frame(i, i / 60, packed=packed_at(i))
                if k >= warmup:
                    unary.append((time.perf_counter() - t0) * 1e3)
                i += 1
            go: queue.Queue[None] = queue.Queue()
            sent: list[float] = []

            def updates(first=i):
                for k in range(warmup + frames):
                    if k:
                        go.get()
                    sent.append(time.perf_counter())
                    yield session.frame_update(first + k, (first + k) / 60, packed=packed_at(first + k))

            for k, _reply in enumerate(session.stream(updates())):
                if k >= warmup:
                    stream.append((time.perf_counter() - sent[k]) * 1e3)
                go.put(None)
    return {"unary": unary, "stream": stream}


def ts_round(url: str, frames: int, warmup: int) -> dict[str, list[float]]:
    import base64

    create = base64.b64encode(scene().SerializeToString()).decode()
    done = subprocess.run(
        ["node", "bench/frame_rtt.mjs", url, create, str(frames), str(warmup)],
        cwd=PACKAGE,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=500, help="timed frames per mode and round")
    parser.add_argument("--warmup", type=int, default=50, help="untimed frames first, per mode and round")
    parser.add_argument("--rounds", type=int, default=4, help="rounds; an even number runs each SDK first as often")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    if not (PACKAGE / "dist" / "index.js").is_file():
        print(f"build the TypeScript SDK first: cd {PACKAGE} && npm ci && npm run build", file=sys.stderr)
        return 2
    runs = {"python": {"unary": [], "stream": []}, "typescript": {"unary": [], "stream": []}}
    with ServerProcess("--workers", "1", transports=("grpc",)) as server:
        url = server.url("grpc")
        order = (("python", python_round), ("typescript", ts_round))
        for r in range(args.rounds):
            for sdk, run in order if r % 2 == 0 else order[::-1]:
                for mode, values in run(url, args.frames, args.warmup).items():
                    runs[sdk][mode].extend(values)
    result: dict = {
        "benchmark": "ts_sdk_bench",
        "transport": "grpc",
        "frames_per_round": args.frames,
        "rounds": args.rounds,
        "node": subprocess.run(["node", "--version"], capture_output=True, text=True).stdout.strip(),
    }
    for mode in ("unary", "stream"):
        py, ts = summary(runs["python"][mode]), summary(runs["typescript"][mode])
        result[mode] = {
            "python_ms": py,
            "typescript_ms": ts,
            "ratio": round(ts["median"] / py["median"], 3),
            "ratio_p99": round(ts["p99"] / py["p99"], 3),
        }
    result["within_1_3x"] = all(result[m]["ratio"] <= 1.3 for m in ("unary", "stream"))
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
