"""Whether another tenant's session id answers in the time a made-up one does (issue 39): tenant
beta sends gRPC `Frame`s naming tenant alpha's live session and naming an id nobody made, to a
server with keys; both must answer NOT_FOUND with the same words (front/router.py `_entry`: one
path), and their round trips should differ by no more than the noise between two runs of one.

    python -m load_tests.unknown_ids_bench --calls 2000 --json FILE

The two kinds of call alternate, so the machine's drift lands on both alike. Reported: each
kind's round trip median and p99 (us) at the client, and the medians' difference.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import grpc

from camdirector.demo.client import session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.server_process import ServerProcess
from camdirector.geometry.camera import Lens
from camdirector.v1 import director_pb2 as pb
from load_tests.report import emit, summary

MADE_UP = "0123456789abcdef0123456789abcdef"


def measure(server: ServerProcess, beta_key: str, calls: int) -> dict:
    metadata = (("authorization", f"Bearer {beta_key}"),)
    with grpc.insecure_channel(server.grpc) as channel:
        create = channel.unary_unary(
            "/camdirector.v1.Director/CreateSession",
            request_serializer=pb.CreateSessionRequest.SerializeToString,
            response_deserializer=pb.CreateSessionResponse.FromString,
        )
        request = session_request(build_demo_scene(), Lens(), pb.VisibilityMode.ANTICIPATION)
        live = create(request, metadata=(("authorization", f"Bearer {server.admin_key}"),), timeout=60).session_id
        frame = channel.unary_unary("/camdirector.v1.Director/Frame", request_serializer=pb.FrameUpdate.SerializeToString)
        # Refused before any worker reads it: the frame needs its session id only.
        requests = {
            "other_tenant": pb.FrameUpdate(session_id=live, frame=1),
            "made_up": pb.FrameUpdate(session_id=MADE_UP, frame=1),
        }
        times: dict[str, list[float]] = {name: [] for name in requests}
        answers = {}
        for n in range(calls):
            for name, update in requests.items() if n % 2 else reversed(requests.items()):
                start = time.perf_counter()
                try:
                    frame(update, metadata=metadata, timeout=10)
                except grpc.RpcError as exc:
                    answers[name] = (exc.code().name, exc.details().replace(update.session_id, "<ID>"))
                times[name].append(time.perf_counter() - start)
    if answers["other_tenant"] != answers["made_up"]:
        raise AssertionError(f"the two kinds of id answer differently: {answers}")
    result = {name: summary(values, 1e6) for name, values in times.items()}
    result["median_difference_us"] = round(result["other_tenant"]["median"] - result["made_up"]["median"], 3)
    result["answer"] = list(answers["made_up"])
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=2000, help="calls of each kind")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    with ServerProcess("--workers", "1", transports=("grpc",), auth=True) as server:
        beta_key = subprocess.run(
            [sys.executable, "-m", "camdirector", "keys", "create", "--role", "engine", "--tenant", "beta"]
            + ["--data-dir", str(server.data_dir)],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        result = measure(server, beta_key, args.calls)
    result.update(calls=args.calls, transport="grpc Frame, unary, one in flight")
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
