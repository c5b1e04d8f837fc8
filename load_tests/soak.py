"""Soak test: sessions created, streamed and closed in a loop for M minutes against a server it
starts, while the server's memory and open descriptors are sampled.

    python -m load_tests.soak --minutes M --json FILE [--workers W] [--clients C] [--frames F]

Each of C client threads (gRPC and ZeroMQ in turn) cycles through every visibility mode of
`style.visibility`, the map modes once with each map backend (GL and EMBREE; the other modes do
not read it), and one recorded session per cycle (a recording file opened and closed): it creates
a session on the demo scene, streams F frames closed loop (as fast as they are answered) and
closes it. A warm-up of the same loop runs first, so that what a process loads once (the GL
driver, the kernel banks, gRPC's and ZeroMQ's buffers) is not counted as growth.
Every `--sample-s` the resident memory (VmRSS) and open descriptors of the front and of each
worker (the server's `spawn` children) are read from /proc. Reported: start and end of each,
the least-squares slope of the total resident memory over the whole run and over its second half
(MB/min), sessions and frames per combination, errors, and worker restarts (a worker pid that
changed). The exit code is 1 on errors or a worker restart; growth is reported, not judged.
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import camdirector_client as cd
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.server_process import ServerProcess, worker_pids
from camdirector.geometry.camera import Lens
from camdirector.pipeline.style import MAP_MODES, MapBackendChoice, VisibilityMode
from load_tests.report import emit


@dataclass(frozen=True)
class ProcessSample:
    """One process's resources at one moment."""

    rss_mb: float  # resident memory (VmRSS), MB
    open_fds: int  # entries of /proc/<pid>/fd


def sample_process(pid: int) -> ProcessSample:
    """VmRSS and open descriptors of a live process (Linux /proc)."""
    rss_kb = next(
        int(line.split()[1]) for line in Path(f"/proc/{pid}/status").read_text().splitlines() if line.startswith("VmRSS:")
    )
    return ProcessSample(rss_mb=rss_kb / 1024.0, open_fds=len(os.listdir(f"/proc/{pid}/fd")))


@dataclass(frozen=True)
class Combination:
    """One session kind of the loop."""

    visibility: VisibilityMode
    map_backend: MapBackendChoice
    record: bool

    @property
    def name(self) -> str:
        backend = f"/{self.map_backend.name}" if self.visibility in MAP_MODES else ""
        return f"{self.visibility.name}{backend}{'/recorded' if self.record else ''}"


def combinations() -> list[Combination]:
    """Every visibility mode, the map modes once per backend, and one recorded session."""
    out = []
    for mode in VisibilityMode:
        if mode == VisibilityMode.UNSPECIFIED:
            continue
        backends = (MapBackendChoice.GL, MapBackendChoice.EMBREE) if mode in MAP_MODES else (MapBackendChoice.AUTO,)
        out += [Combination(mode, backend, record=False) for backend in backends]
    out.append(Combination(VisibilityMode.FRAMING_ONLY, MapBackendChoice.AUTO, record=True))
    return out


class Loop:
    """Client threads running sessions of every combination until told to stop."""

    def __init__(self, server: ServerProcess, clients: int, frames: int):
        scene = build_demo_scene(seed=7, duration_s=max(frames / 60.0, 1.0))
        base = session_request(scene, Lens())
        self.requests = {}
        for combo in combinations():
            request = cd.pb.CreateSessionRequest()
            request.CopyFrom(base)
            request.style.visibility = int(combo.visibility)
            request.style.map_backend = int(combo.map_backend)
            request.record = combo.record
            self.requests[combo] = request
        # serialized: the SDK writes the session id into the messages it streams
        self.updates = [update.SerializeToString() for update in frame_updates(scene, frames, 60.0)]
        self.urls = [server.url("grpc" if k % 2 == 0 else "zmq") for k in range(clients)]
        self.sessions = {combo.name: 0 for combo in self.requests}
        self.frames = 0
        self.errors: list[str] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._run, args=(url, k), daemon=True) for k, url in enumerate(self.urls)]

    def start(self) -> None:
        for thread in self._threads:
            thread.start()

    def stop(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join()

    def _run(self, url: str, k: int) -> None:
        combos = list(self.requests)
        # each thread starts at a different place in the cycle, so the workers see every kind at once
        order = itertools.islice(itertools.cycle(combos), k * len(combos) // max(len(self.urls), 1), None)
        with cd.connect(url) as client:
            for combo in order:
                if self._stop.is_set():
                    return
                try:
                    with client.create_session(self.requests[combo]) as session:
                        updates = (cd.pb.FrameUpdate.FromString(update) for update in self.updates)
                        answered = sum(1 for _ in session.stream(updates))
                except Exception as exc:  # reported, and the soak goes on
                    with self._lock:
                        self.errors.append(f"{combo.name} over {url}: {exc!r}")
                    continue
                with self._lock:
                    self.sessions[combo.name] += 1
                    self.frames += answered


def _slope_mb_min(t_min: np.ndarray, mb: np.ndarray) -> float | None:
    """Least-squares slope, MB per minute (None with fewer than 3 samples)."""
    if len(t_min) < 3 or np.ptp(t_min) <= 0:
        return None
    return round(float(np.polyfit(t_min, mb, 1)[0]), 3)


def run(server: ServerProcess, minutes: float, warmup_s: float, sample_s: float, clients: int, frames: int) -> dict:
    loop = Loop(server, clients, frames)
    loop.start()
    time.sleep(warmup_s)
    front = server.proc.pid
    workers = worker_pids(front)
    warm_sessions = sum(loop.sessions.values())
    samples = []  # (minutes since start, front sample, [worker samples])
    restarted = False
    start = time.monotonic()
    end = start + minutes * 60.0
    while True:
        now = time.monotonic()
        current = worker_pids(front)
        if current != workers:
            restarted = True
            break
        try:
            samples.append(((now - start) / 60.0, sample_process(front), [sample_process(p) for p in workers]))
        except (OSError, StopIteration):  # a worker went away between listing and reading
            restarted = True
            break
        if now >= end:
            break
        time.sleep(min(sample_s, max(end - now, 0.0)))
    loop.stop()
    t_min = np.array([s[0] for s in samples])
    total_mb = np.array([s[1].rss_mb + sum(w.rss_mb for w in s[2]) for s in samples])
    half = t_min >= t_min[-1] / 2 if len(t_min) else t_min.astype(bool)

    def start_end(values) -> dict:
        return {"start": round(float(values[0]), 1), "end": round(float(values[-1]), 1)} if len(values) else {}

    return {
        "minutes": minutes,
        "warmup_s": warmup_s,
        "sample_s": sample_s,
        "clients": clients,
        "frames_per_session": frames,
        "samples": len(samples),
        "sessions": dict(loop.sessions),
        "sessions_total": sum(loop.sessions.values()) - warm_sessions,
        "sessions_in_warmup": warm_sessions,
        "frames_total": loop.frames,
        "rss_total_mb": start_end(total_mb),
        "rss_slope_mb_per_min": _slope_mb_min(t_min, total_mb),
        "rss_slope_second_half_mb_per_min": _slope_mb_min(t_min[half], total_mb[half]),
        "front": {"rss_mb": start_end([s[1].rss_mb for s in samples]), "open_fds": start_end([s[1].open_fds for s in samples])},
        "workers": [
            {"rss_mb": start_end([s[2][i].rss_mb for s in samples]), "open_fds": start_end([s[2][i].open_fds for s in samples])}
            for i in range(len(workers))
        ],
        "series": {
            "t_min": [round(float(t), 3) for t in t_min],
            "rss_total_mb": [round(float(m), 1) for m in total_mb],
            "open_fds_total": [s[1].open_fds + sum(w.open_fds for w in s[2]) for s in samples],
        },
        "worker_restarted": restarted,
        "errors": loop.errors[:20],
        "error_count": len(loop.errors),
        "cpus": os.cpu_count(),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="measured duration, after the warm-up")
    parser.add_argument("--warmup-s", type=float, default=30.0, help="the loop runs this long before the first sample")
    parser.add_argument("--sample-s", type=float, default=5.0, help="seconds between samples")
    parser.add_argument("--workers", type=int, default=None, help="server worker processes (default: cores)")
    parser.add_argument("--clients", type=int, default=None, help="client threads (default: one per worker)")
    parser.add_argument("--frames", type=int, default=30, help="frames streamed per session")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    clients = args.clients if args.clients is not None else max(workers, 1)
    with ServerProcess("--workers", str(workers), "--max-sessions", str(max(64, 2 * clients))) as server:
        result = run(server, args.minutes, args.warmup_s, args.sample_s, clients, args.frames)
        result["server_workers"] = server.ready["workers"]
    emit(result, args.json)
    return 0 if not result["error_count"] and not result["worker_restarted"] else 1


if __name__ == "__main__":
    sys.exit(main())
