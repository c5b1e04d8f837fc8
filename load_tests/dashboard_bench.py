"""Dashboard load: what watching sessions costs the sessions watched.

    python -m load_tests.dashboard_bench --sessions 4 --rate 60 --seconds 10 --watch-hz 2 --json FILE

Two runs of `load_tests.stream` against one server it starts (demo scene, paced game loops, gRPC):
first the sessions alone, which is the baseline, then the same again while a dashboard client
reads `GET /v1/sessions` and every session's `GET /v1/sessions/{id}` `--watch-hz` times a second,
as the dashboard does: all 600 frames the first time, then `after_frame` the last one it has.
Reports both runs' frame round trip p50/p99 and their ratio, and the latency of the detail
requests. The dashboard client runs in a process of its own on the same machine (as a browser
would), so the ratio includes its CPU as well as the server's.
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing
import os
import sys
import time
from pathlib import Path

import httpx

from camdirector.deploy.server_process import ServerProcess
from load_tests import stream
from load_tests.report import emit, percentiles


def _watch(http: str, hz: float, stop, out) -> None:
    """The dashboard client, in a process of its own as a browser is: reads the list and every
    session's detail `hz` times a second until `stop` is set; sends its latencies (ms) and the
    frame counts it got through `out`."""
    latencies_ms, frames_seen, seen = [], [], {}
    with httpx.Client(base_url=f"http://{http}", timeout=30.0) as client:
        while not stop.is_set():
            started = time.perf_counter()
            for session in client.get("/v1/sessions").json()["sessions"]:
                session_id = session["session_id"]
                t0 = time.perf_counter()
                reply = client.get(
                    f"/v1/sessions/{session_id}", params={} if session_id not in seen else {"after_frame": seen[session_id]}
                )
                latencies_ms.append((time.perf_counter() - t0) * 1e3)
                frames = reply.json()["frames"] if reply.status_code == 200 else []
                frames_seen.append(len(frames))
                if frames:
                    seen[session_id] = frames[-1]["frame"]
            stop.wait(max(0.0, 1.0 / hz - (time.perf_counter() - started)))
    out.send((latencies_ms, frames_seen))


def _watched_run(server: ServerProcess, sessions: int, rate_hz: float, seconds: float, hz: float) -> dict:
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    receive, send = context.Pipe(duplex=False)
    watcher = context.Process(target=_watch, args=(server.http, hz, stop, send), daemon=True)
    watcher.start()
    try:
        result = asyncio.run(stream.run("grpc", server.grpc, sessions, rate_hz, seconds))
    finally:
        stop.set()
    latencies_ms, frames_seen = receive.recv()
    watcher.join(30)
    result["detail_requests"] = len(latencies_ms)
    result["detail_ms"] = percentiles(latencies_ms)
    result["detail_frames_median"] = float(sorted(frames_seen)[len(frames_seen) // 2]) if frames_seen else None
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=4)
    parser.add_argument("--rate", type=float, default=60.0, help="frames per second per session")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--watch-hz", type=float, default=2.0, help="dashboard reads per second (the page polls at 2)")
    parser.add_argument("--workers", type=int, default=None, help="server worker processes (default: cores)")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    with ServerProcess("--workers", str(workers), "--max-sessions", str(max(64, 2 * args.sessions))) as server:
        alone = asyncio.run(stream.run("grpc", server.grpc, args.sessions, args.rate, args.seconds))
        watched = _watched_run(server, args.sessions, args.rate, args.seconds, args.watch_hz)
    ratio = {k: watched["rtt_ms"][k] / alone["rtt_ms"][k] for k in ("p50", "p99") if alone["rtt_ms"][k]}
    result = {
        "sessions": args.sessions,
        "rate_hz": args.rate,
        "seconds": args.seconds,
        "watch_hz": args.watch_hz,
        "server_workers": workers,
        "alone": {k: alone[k] for k in ("rtt_ms", "compute_ms", "late_frames", "dropped_frames", "errors")},
        "watched": {
            k: watched[k]
            for k in (
                "rtt_ms",
                "compute_ms",
                "late_frames",
                "dropped_frames",
                "errors",
                "detail_requests",
                "detail_ms",
                "detail_frames_median",
            )
        },
        "rtt_ratio_watched_vs_alone": ratio,
        "cpus": os.cpu_count(),
    }
    emit(result, args.json)
    ok = not alone["errors"] and not watched["errors"] and watched["detail_requests"] > 0
    return 0 if ok and alone["dropped_frames"] == watched["dropped_frames"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
