"""Capacity benchmark: the most sessions at 60 Hz one server on this machine holds with a round trip
p99 <= 10 ms and no late frame, for FRAMING_ONLY and ANTICIPATION on the demo scene, over gRPC
and ZeroMQ.

    python -m load_tests.capacity --json FILE [--seconds S] [--max-sessions N] [--modes A,B]
        [--transports grpc,zmq] [--workers W] [--p99-ms MS] [--generator python|native]
        [--spread-s S] [--server-python PATH] [--server-arg ARG ...]

For each mode and transport a fresh server is started (each step closes its sessions when its
streams end, so one step's sessions do not weigh on the next), and session counts are
tried upward (1, 2, 4, 8, 16, then every 8 up to --max-sessions), then the gap between the
last count that passed and the first that failed is halved until they are neighbours (16 passed
and 24 failed: 20, then 18 or 22, ...), each count a short paced run of
load_tests.stream: one frame in flight per session at --rate Hz of wall-clock time, the sessions
staggered over one period. They all stream the same demo frames, so the same moment of the game
reaches every session within that period and they cut together (a map refill in every session
on one frame: docs/frame_path.md, "ANTICIPATION's tail"); `--spread-s S` starts them S / sessions
seconds apart in the demo instead, as independent games would be. A step passes when its round
trip p99 is at most --p99-ms, no frame is late (answered after the next was due), none is dropped
and no stream failed; each session's first --warmup-frames frames are answered but not judged
(its first frame sets up what the session keeps: about 30 ms in ANTICIPATION, late by itself).
A step that fails is run once more (a few seconds on a shared machine can hit one stall); a count
fails when it fails twice, and the capacity is the largest count that passed (0 when even one
session did not).
Reported per case and step: round trip p50/p99 at the client, late and dropped frames, the
server's compute_ms, the health-check floor measured in the same step against the same server
(a gRPC health check, or a ZeroMQ request the front refuses at once), this load generator's
own CPU while streaming (on a 2-core machine the generator shares the cores with the server),
and `cpu_us_per_frame`: the CPU microseconds per answered frame of the server's front process,
of its workers together (from /proc; the step's session creations included) and of this load
generator, which say where a frame's CPU goes when the cores run out.
The sessions are streamed by the compiled driver (load_tests/native_generator.py) unless
`--generator python`: it takes about 0.3 of the Python generator's CPU a frame over gRPC and about
0.45 over ZeroMQ (libzmq's I/O thread wakes for every message), leaving those cores to the server
(docs/frame_path.md, "A load generator cheap enough").
`--server-python` runs the server of another checkout with that checkout's interpreter (e.g. the
venv of a `git worktree` of an older commit) while this checkout drives it, so the same command
measures both; the JSON names the server's checkout and commit.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import time
from pathlib import Path

from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from load_tests import stream
from load_tests.report import emit

MODES = ("FRAMING_ONLY", "ANTICIPATION")
TRANSPORTS = ("grpc", "zmq")
DOUBLING_UP_TO = 16  # session counts double up to here, then grow by this step's half (8)


def session_counts(max_sessions: int) -> list[int]:
    """The counts tried, in order: 1, 2, 4, 8, 16, 24, 32, ... up to max_sessions (included)."""
    counts, n = [], 1
    while n <= max_sessions:
        counts.append(n)
        n = n * 2 if n < DOUBLING_UP_TO else n + DOUBLING_UP_TO // 2
    if counts and counts[-1] != max_sessions:
        counts.append(max_sessions)
    return counts


def largest_passing(counts: list[int], passes) -> int:
    """The capacity search (module docstring): `counts` upward until `passes(n)` is False, then
    bisection between the last count that passed and that one. 0 when the first fails."""
    passed, failed = 0, None
    for n in counts:
        if not passes(n):
            failed = n
            break
        passed = n
    while failed is not None and failed - passed > 1:
        middle = (passed + failed) // 2
        if passes(middle):
            passed = middle
        else:
            failed = middle
    return passed


def step_passes(result: dict, p99_limit_ms: float) -> bool:
    """A stream.run result meets the target: p99 round trip <= the limit, nothing late, dropped or failed."""
    p99 = result["rtt_ms"]["p99"]
    return (
        p99 is not None
        and p99 <= p99_limit_ms
        and result["late_frames"] == 0
        and result["dropped_frames"] == 0
        and not result["errors"]
    )


def _step_summary(result: dict, passed: bool) -> dict:
    def rounded(d: dict) -> dict:
        return {k: None if v is None else round(v, 3) for k, v in d.items()}

    return {
        "sessions": result["sessions"],
        "passed": passed,
        "rtt_ms": rounded(result["rtt_ms"]),
        "late_frames": result["late_frames"],
        "dropped_frames": result["dropped_frames"],
        "frames_sent": result["frames_sent"],
        "compute_ms": rounded(result["compute_ms"]),
        "floor_rtt_ms": rounded(result["baseline_rtt_ms"]),
        "client_cpu_fraction_of_core": result["client_cpu_fraction_of_core"],
        "errors": result["errors"][:3],
    }


def _server_checkout(python: str) -> dict:
    """Where the server's code comes from: the checkout `python` imports camdirector from, and its commit."""
    # camdirector.server: a checkout from before the src layout (measured against in the same run)
    code = (
        "import os\ntry:\n    import camdirector.pipeline as s\nexcept ImportError:\n    import camdirector.server as s\n"
        "print(os.path.dirname(s.__file__))"
    )
    package = subprocess.run([python, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    found = (
        subprocess.run(["git", "-C", package, "rev-parse", "--show-toplevel"], capture_output=True, text=True).stdout.strip()
        or package
    )
    commit = subprocess.run(["git", "-C", found, "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    return {"python": python, "checkout": found, "commit": commit or None}


def _cpu_s(pid: int) -> float:
    """CPU seconds so far of one process's live threads, from their /proc schedstat (in ns:
    /proc/PID/stat counts in 10 ms ticks, too coarse for a short step)."""
    total_ns = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            total_ns += int((task / "schedstat").read_text().split()[0])
        except FileNotFoundError:  # a thread that ended meanwhile
            pass
    return total_ns / 1e9


def server_cpu_s(front_pid: int) -> dict[str, float] | None:
    """CPU seconds so far of the server's front process and of its worker processes (its
    children, summed); None where /proc cannot tell (not Linux, or a process just ended)."""
    try:
        children = [int(p) for p in Path(f"/proc/{front_pid}/task/{front_pid}/children").read_text().split()]
        return {"front": _cpu_s(front_pid), "workers": sum(_cpu_s(c) for c in children)}
    except (OSError, ValueError, IndexError):
        return None


def _cpu_us_per_frame(before: dict | None, after: dict | None, frames: int) -> dict | None:
    if before is None or after is None or not frames:
        return None
    return {k: round((after[k] - before[k]) / frames * 1e6, 1) for k in before}


def measure_case(mode: str, transport: str, counts: list[int], args) -> dict:
    """One mode over one transport: a fresh server, counts tried upward until one fails twice."""
    steps, workers = [], None
    with ServerProcess(
        "--workers",
        str(args.workers),
        "--max-sessions",
        str(max(counts) * 2),
        # stream.run closes its sessions; a step's sessions wait for their streams through the
        # floor's 520 health checks, which took over a second on a loaded machine (a window of
        # 1 s reclaimed them before they streamed)
        "--session-resume-s",
        "60",
        *args.server_arg,
        python=args.server_python,
    ) as server:
        workers = server.ready.get("workers")
        address = server.grpc if transport == "grpc" else server.zmq

        def step(n: int) -> bool:
            """n sessions, run once more when they fail; whether they passed."""
            for _ in range(2):
                cpu_before = server_cpu_s(server.proc.pid)
                result = asyncio.run(
                    stream.run(
                        transport,
                        address,
                        n,
                        args.rate,
                        args.seconds,
                        visibility=pb.VisibilityMode.Value(mode),
                        warmup_frames=args.warmup_frames,
                        generator=args.generator,
                        spread_s=args.spread_s,
                    )
                )
                passed = step_passes(result, args.p99_ms)
                steps.append(
                    {
                        **_step_summary(result, passed),
                        "cpu_us_per_frame": {
                            **(_cpu_us_per_frame(cpu_before, server_cpu_s(server.proc.pid), result["frames_received"]) or {}),
                            "load_generator": round(result["client_cpu_s"] / max(result["frames_received"], 1) * 1e6, 1),
                        },
                    }
                )
                time.sleep(args.settle_s)  # the server settles (closed sessions' state freed) before the next step
                if passed:
                    return True
            return False

        capacity = largest_passing(counts, step)
        if not server.alive():
            raise RuntimeError(f"the server died during {mode} over {transport}: {server.log_tail()}")
    at_capacity = [s for s in steps if s["sessions"] == capacity and s["passed"]]
    return {
        "mode": mode,
        "transport": transport,
        "capacity_sessions": capacity,
        "server_workers": workers,
        "floor_rtt_ms_at_capacity": at_capacity[-1]["floor_rtt_ms"] if at_capacity else None,
        "client_cpu_fraction_of_core_at_capacity": at_capacity[-1]["client_cpu_fraction_of_core"] if at_capacity else None,
        "steps": steps,
    }


def _names(text: str, allowed: tuple[str, ...], what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in allowed]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"{what} must be among {', '.join(allowed)}; got {text!r}")
    return names


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="length of one step, s")
    parser.add_argument("--rate", type=float, default=60.0, help="frames per second per session, Hz")
    parser.add_argument("--max-sessions", type=int, default=64, help="the largest count tried")
    parser.add_argument("--p99-ms", type=float, default=10.0, help="round trip p99 a step must not exceed, ms")
    parser.add_argument(
        "--warmup-frames",
        type=int,
        default=10,
        help="each session's first frames, answered but not judged (set-up: ~30 ms in the map modes)",
    )
    parser.add_argument("--modes", default=",".join(MODES), help="visibility modes, comma-separated")
    parser.add_argument("--transports", default=",".join(TRANSPORTS), help="grpc, zmq or both, comma-separated")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="server worker processes")
    parser.add_argument("--settle-s", type=float, default=1.5, help="pause after a step while the server settles, s")
    parser.add_argument(
        "--server-python",
        default=sys.executable,
        help="the interpreter that runs the server (another checkout's venv measures that checkout)",
    )
    parser.add_argument(
        "--server-arg",
        action="append",
        default=[],
        help="one more argument of `camdirector serve` (repeat it), e.g. --server-arg=--checkpoint-store "
        "--server-arg=off to measure without checkpoints",
    )
    parser.add_argument(
        "--generator",
        choices=stream.GENERATORS,
        default="native",
        help="what streams the sessions: the compiled driver (native_generator.py; it needs CMake, gRPC for C++ and "
        "libzmq: scripts/system-deps.sh --tests), or this process (asyncio)",
    )
    parser.add_argument(
        "--spread-s",
        type=float,
        default=0.0,
        help="sessions start this far apart in the demo, spread evenly (0, the default: all at the same moment, so a "
        "cut in one is a cut in all; load_tests.stream)",
    )
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    try:
        modes = _names(args.modes, MODES, "--modes")
        transports = _names(args.transports, TRANSPORTS, "--transports")
    except argparse.ArgumentTypeError as exc:
        parser.error(str(exc))
    if args.max_sessions < 1 or args.seconds <= 0 or args.rate <= 0:
        parser.error("--max-sessions, --seconds and --rate must be positive")
    if args.spread_s < 0:
        parser.error("--spread-s must be >= 0")
    counts = session_counts(args.max_sessions)
    t0 = time.perf_counter()
    cases = [measure_case(mode, transport, counts, args) for mode in modes for transport in transports]
    result = {
        "p99_limit_ms": args.p99_ms,
        "rate_hz": args.rate,
        "seconds_per_step": args.seconds,
        "warmup_frames_per_session": args.warmup_frames,
        "generator": args.generator,
        "spread_s": args.spread_s,
        "counts_tried_up_to": counts,
        "cpus": os.cpu_count(),
        "server": _server_checkout(args.server_python),
        "server_args": args.server_arg,
        "capacity_sessions": {
            mode: {c["transport"]: c["capacity_sessions"] for c in cases if c["mode"] == mode} for mode in modes
        },
        "wall_s": round(time.perf_counter() - t0, 1),
        "cases": cases,
    }
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
