"""Monitors' cost: what a picture of a session's camera costs, and what live monitors cost the sessions watched.

    python -m load_tests.monitors_bench --sessions 4 --rate 60 --seconds 10 --fps 4 --width 320 --rounds 3 --json FILE

Against one server it starts (demo scene, gRPC):
- Round trips: `--rounds` rounds of two runs of `load_tests.stream`, first the sessions alone (the
  baseline), then the same again while each session is watched by one live monitor, `GET /v1/sessions/{id}/view.mjpeg`
  at `--fps` and `--width`. Reports both runs' frame round trip p50/p99 and their ratio, late and
  dropped frames, their health-check floors (measured with the monitors already on in the watched
  run), the parts and bytes the monitors received while the sessions streamed, and how many
  pictures the server rendered meanwhile (`camdirector_view_renders_total`). The monitors are
  read in a process of their own on the same machine (as a browser would), so the ratio includes
  their CPU as well as the server's and its render processes'. The first round's sessions alone
  run before any render process exists, as on a server nobody watches. Each round's ratio is
  reported, and their median: alternating the two conditions lets a shared machine's bursts of
  load fall on both alike.
- Render cost: one session advanced two frames at a time, then asked `GET /view` at `--width`,
  `--renders` times, each ask past the window in which the server shares one picture among
  viewers, so each is a render of its own. Reports the render process's own time per picture
  (X-Camdirector-Render-Ms: drawing, readback, JPEG), the REST round trip at the client, the
  picture's bytes and size (decoded), and the session's first picture's round trip (its meshes
  sent to the render process, which the watched run has started, and its renderer made).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import io
import multiprocessing
import os
import sys
import threading
import time
from pathlib import Path

import httpx
import numpy as np
from PIL import Image
from prometheus_client.parser import text_string_to_metric_families

from camdirector.demo.client import session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.server_process import ServerProcess
from camdirector.front.http.routes.monitors import BOUNDARY
from camdirector.geometry.camera import Lens
from load_tests import stream
from load_tests.report import emit, summary

SHARE_WINDOW_S = 0.12  # just past the 0.1 s in which the server shares one picture among asks
WARM_FRAMES = 10  # frames before the first picture, so it shows the camera, not a placeholder


def _read_monitor(
    http: str, session_id: str, fps: float, width_px: int, stop, first: threading.Event, parts: list, errors: list
) -> None:
    """One live monitor: reads the session's MJPEG stream until `stop` is set, appending each part's
    (arrival time.monotonic(), frame shown or None, JPEG bytes) to `parts`; sets `first` on the
    first part (or on an error, which goes to `errors`)."""
    try:
        with (
            httpx.Client(base_url=f"http://{http}", timeout=30.0) as client,
            client.stream("GET", f"/v1/sessions/{session_id}/view.mjpeg", params={"fps": fps, "width": width_px}) as reply,
        ):
            reply.raise_for_status()
            buffer = b""
            for chunk in reply.iter_bytes():  # a part at least every second (the stream's keepalive)
                buffer += chunk
                while (head_end := buffer.find(b"\r\n\r\n")) >= 0:
                    boundary, *lines = buffer[:head_end].decode().split("\r\n")
                    if boundary != f"--{BOUNDARY}":
                        raise ValueError(f"a part starts with {boundary!r}")
                    headers = dict(line.split(": ", 1) for line in lines)
                    length = int(headers["Content-Length"])
                    part_end = head_end + 4 + length + 2  # the JPEG, then CRLF
                    if len(buffer) < part_end:
                        break
                    frame = headers.get("X-Camdirector-Frame")
                    parts.append((time.monotonic(), None if frame is None else int(frame), length))
                    buffer = buffer[part_end:]
                    first.set()
                if stop.is_set():
                    return
    except Exception as exc:  # reported, and the run fails
        errors.append(f"{session_id}: {exc!r}")
        first.set()


def _watch(http: str, session_ids: list[str], fps: float, width_px: int, ready, stop, out) -> None:
    """The monitors, in a process of their own as a browser is: one live stream per session (a
    thread each); sets `ready` once each has its first part, then reads until `stop` is set and
    sends the parts (per session, as `_read_monitor` lists them) and any errors through `out`."""
    parts, errors, firsts = {s: [] for s in session_ids}, [], {s: threading.Event() for s in session_ids}
    threads = [
        threading.Thread(target=_read_monitor, args=(http, s, fps, width_px, stop, firsts[s], parts[s], errors))
        for s in session_ids
    ]
    for thread in threads:
        thread.start()
    for first in firsts.values():
        first.wait(60.0)
    ready.set()
    for thread in threads:
        thread.join()
    out.send((parts, errors))


def _view_metrics(http: str) -> dict[str, float]:
    """The server's monitor counters without labels (renders so far, live streams now)."""
    text = httpx.get(f"http://{http}/metrics", timeout=10.0).text
    return {s.name: s.value for family in text_string_to_metric_families(text) for s in family.samples if not s.labels}


def _monitors(http: str, fps: float, width_px: int, watch: dict):
    """stream.run's `alongside`: a live monitor on each session, started (each with its first
    part) before the run measures anything and stopped after. Leaves in `watch` the parts, the
    errors, the live streams the server counted, its renders meanwhile, and when the run ended."""

    @contextlib.asynccontextmanager
    async def monitors(session_ids: list[str]):
        context = multiprocessing.get_context("spawn")
        ready, stop = context.Event(), context.Event()
        receive, send = context.Pipe(duplex=False)
        viewer = context.Process(target=_watch, args=(http, session_ids, fps, width_px, ready, stop, send), daemon=True)
        viewer.start()
        send.close()  # the viewer's end only: a viewer that dies ends receive.recv with EOFError
        try:
            await asyncio.to_thread(ready.wait, 90.0)
            before = await asyncio.to_thread(_view_metrics, http)
            yield
            watch["ended_s"] = time.monotonic()
            after = await asyncio.to_thread(_view_metrics, http)
        finally:
            stop.set()
        watch["server_view_streams"] = before["camdirector_view_streams"]
        watch["view_renders"] = after["camdirector_view_renders_total"] - before["camdirector_view_renders_total"]
        watch["parts"], watch["errors"] = await asyncio.to_thread(receive.recv)
        await asyncio.to_thread(viewer.join, 30)

    return monitors


def _watched_run(server: ServerProcess, sessions: int, rate_hz: float, seconds: float, fps: float, width_px: int) -> dict:
    watch: dict = {}
    result = asyncio.run(
        stream.run("grpc", server.grpc, sessions, rate_hz, seconds, alongside=_monitors(server.http, fps, width_px, watch))
    )
    ended_s = watch["ended_s"]
    # the parts that arrived while the sessions streamed (not during the health checks before, nor after)
    streamed = [[p for p in parts if ended_s - result["wall_s"] <= p[0] <= ended_s] for parts in watch["parts"].values()]
    n_parts = sum(len(parts) for parts in streamed)
    result.update(
        monitors=len(streamed),
        monitor_errors=watch["errors"],
        server_view_streams=watch["server_view_streams"],
        monitor_parts=n_parts,
        monitor_parts_min=min(len(parts) for parts in streamed),
        monitor_parts_per_s=round(n_parts / len(streamed) / result["wall_s"], 3),
        monitor_kb_per_s=round(sum(p[2] for parts in streamed for p in parts) / len(streamed) / result["wall_s"] / 1e3, 3),
        view_renders=watch["view_renders"],
    )
    return result


async def _render_cost(server: ServerProcess, renders: int, width_px: int) -> dict:
    """One session's picture asked `renders` times, two frames apart (module docstring)."""
    n_frames = WARM_FRAMES + 2 * renders
    scene = build_demo_scene(seed=7, duration_s=n_frames / 60.0 + 1.0)
    frames = stream._frames(scene, n_frames, 60.0)
    driver = stream.GrpcDriver(server.grpc)
    session_id = await driver.open_session(session_request(scene, Lens()))
    call = driver.stream()
    round_trip_ms, render_ms, image_bytes, frames_shown, placeholders = [], [], [], set(), 0

    async def advance(payloads: list[bytes]) -> None:
        for payload in payloads:
            await call.write(stream._with_session(session_id, payload))
            await call.read()

    async with httpx.AsyncClient(base_url=f"http://{server.http}", timeout=30.0) as client:

        async def view() -> tuple[httpx.Response, float]:
            t0 = time.perf_counter()
            reply = await client.get(f"/v1/sessions/{session_id}/view", params={"width": width_px})
            reply.raise_for_status()
            return reply, (time.perf_counter() - t0) * 1e3

        await advance(frames[:WARM_FRAMES])
        _, first_view_ms = await view()
        for k in range(renders):
            await advance(frames[WARM_FRAMES + 2 * k : WARM_FRAMES + 2 * k + 2])
            await asyncio.sleep(SHARE_WINDOW_S)
            reply, elapsed_ms = await view()
            round_trip_ms.append(elapsed_ms)
            render_ms.append(float(reply.headers["X-Camdirector-Render-Ms"]))
            image_bytes.append(len(reply.content))
            frames_shown.add(reply.headers.get("X-Camdirector-Frame"))
            placeholders += "X-Camdirector-Placeholder" in reply.headers
    await call.done_writing()
    await driver.close()
    return {
        "renders": renders,
        "render_ms": summary(render_ms),
        "round_trip_ms": summary(round_trip_ms),
        "image_bytes": summary(image_bytes),
        "picture_px": list(Image.open(io.BytesIO(reply.content)).size),
        "frames_shown": len(frames_shown),
        "placeholders": placeholders,
        "first_view_ms": round(first_view_ms, 3),
    }


def _gl_renderer() -> str | None:
    """GL_RENDERER of a standalone EGL context, as the server's render processes make theirs."""
    try:
        import moderngl

        ctx = moderngl.create_standalone_context(backend="egl")
        try:
            return ctx.info["GL_RENDERER"]
        finally:
            ctx.release()
    except Exception:  # no EGL here: the renderer stays unknown, the figures stand
        return None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=4)
    parser.add_argument("--rate", type=float, default=60.0, help="frames per second per session")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--fps", type=float, default=4.0, help="each live monitor's frames per second")
    parser.add_argument("--width", type=int, default=320, help="pictures' width, px (height from the lens: 16:9)")
    parser.add_argument("--renders", type=int, default=50, help="pictures asked for the render cost")
    parser.add_argument("--rounds", type=int, default=3, help="unwatched-then-watched rounds; the ratio reported is their median")
    parser.add_argument("--workers", type=int, default=None, help="server worker processes (default: cores)")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    with ServerProcess("--workers", str(workers), "--max-sessions", str(max(64, 2 * args.sessions + 1))) as server:
        # Alternated rounds: a shared machine's bursts of load then fall on both conditions alike.
        rounds = []
        for _ in range(args.rounds):
            alone = asyncio.run(stream.run("grpc", server.grpc, args.sessions, args.rate, args.seconds))
            watched = _watched_run(server, args.sessions, args.rate, args.seconds, args.fps, args.width)
            rounds.append((alone, watched))
        render = asyncio.run(_render_cost(server, args.renders, args.width))
    keys = ("rtt_ms", "baseline_rtt_ms", "compute_ms", "late_frames", "dropped_frames", "errors")
    watch_keys = (
        *keys,
        "monitors",
        "monitor_errors",
        "server_view_streams",
        "monitor_parts",
        "monitor_parts_min",
        "monitor_parts_per_s",
        "monitor_kb_per_s",
        "view_renders",
    )
    reported = [
        {
            "unwatched": {k: alone[k] for k in keys},
            "watched": {k: watched[k] for k in watch_keys},
            "rtt_ratio_watched_vs_unwatched": {
                k: watched["rtt_ms"][k] / alone["rtt_ms"][k] for k in ("p50", "p99") if alone["rtt_ms"][k]
            },
        }
        for alone, watched in rounds
    ]
    ratio = {
        k: round(float(np.median([r["rtt_ratio_watched_vs_unwatched"][k] for r in reported])), 3)
        for k in ("p50", "p99")
        if all(k in r["rtt_ratio_watched_vs_unwatched"] for r in reported)
    }
    result = {
        "sessions": args.sessions,
        "rate_hz": args.rate,
        "seconds": args.seconds,
        "fps": args.fps,
        "width_px": args.width,
        "server_workers": workers,
        "cpus": os.cpu_count(),
        "gl_renderer": _gl_renderer(),
        "render": render,
        "rounds": reported,
        "rtt_ratio_watched_vs_unwatched": ratio,
    }
    emit(result, args.json)
    ok = all(
        not alone["errors"]
        and not watched["errors"]
        and not watched["monitor_errors"]
        and watched["monitor_parts_min"] > 0
        and alone["dropped_frames"] == watched["dropped_frames"] == 0
        for alone, watched in rounds
    )
    return 0 if ok and render["picture_px"] == [args.width, round(args.width / Lens().aspect)] else 1


if __name__ == "__main__":
    sys.exit(main())
