"""One scenario through a real director session: stream its frames, measure, write JSON and plots.

The frames go over gRPC (`Director.StreamFrames`) to a server given by address, or to a
`camdirector serve` subprocess started on free loopback ports for the run. Time is simulated:
frames are sent as fast as the server answers, each with its scenario time_s, so a run is
reproducible (same scenario, mode and seed, same poses) and independent of the machine's speed.

A mode the server answers UNIMPLEMENTED for is an outcome, not an error: the result's status is
"unavailable" (the visibility modes land one by one).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import grpc
import numpy as np

from camdirector.deploy.server_process import ServerProcess
from camdirector.evaluation.scenario import PARK_OFFSET_M, Scenario, Timeline, visibility_mode
from camdirector.evaluation.toric.measure import CameraTrack, Measurement, VisibilityMeter, measure
from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc as pbg

MAX_MESSAGE_BYTES = 256 << 20  # client side; the server applies its own limit
RPC_TIMEOUT_S = 60.0  # CreateSession / CloseSession
STREAM_TIMEOUT_S = 3600.0  # a whole run


@dataclass(eq=False)
class RunResult:
    """status: "ok", "unavailable" (the server does not implement the mode) or "error"."""

    scenario: Scenario
    mode: str  # VisibilityMode name
    status: str
    message: str = ""
    measurement: Measurement | None = None
    wall_s: float = 0.0  # streaming time, s
    server: str = ""
    duration_s: float = 0.0  # simulated time run, s
    timeline: Timeline | None = None  # what the frames carried

    def as_dict(self, series: bool = True) -> dict:
        s = self.scenario
        out = {
            "scenario": {
                "name": s.name,
                "file": str(s.path) if s.path else None,
                "duration_s": self.duration_s,
                "frame_rate_hz": s.frame_rate_hz,
                "seed": s.seed,
                "targets": [a.id for a in s.targets],
                "objects": len(s.objects),
            },
            "mode": self.mode,
            "status": self.status,
            "message": self.message,
            "server": self.server,
            "wall_s": round(self.wall_s, 3),
        }
        if self.measurement is not None:
            out["summary"] = self.measurement.summary()
            if series:
                out["series"] = self.measurement.series()
        return out


def _mode_name(mode: int | str) -> str:
    return pb.VisibilityMode.Name(visibility_mode(mode) if isinstance(mode, str) else int(mode))


def run_on_channel(
    channel: grpc.Channel,
    scenario: Scenario,
    mode: int | str,
    *,
    duration_s: float | None = None,
    meter: VisibilityMeter | None = None,
    map_resolution: int = 0,
    map_backend: str = "AUTO",
) -> RunResult:
    """Runs the scenario (up to duration_s of simulated time) in a new session on `channel`.
    map_resolution (texels per side, 0: the server's default) and map_backend ("AUTO", "GL",
    "EMBREE") override the scenario's style for the map modes."""
    name = _mode_name(mode)
    stub = pbg.DirectorStub(channel)
    timeline = scenario.timeline(duration_s)
    result = RunResult(scenario, name, "error", duration_s=float(timeline.time_s[-1]), timeline=timeline)
    request = scenario.create_session_request(name, timeline=timeline)
    request.style.map_resolution = map_resolution
    request.style.map_backend = pb.MapBackend.Value(f"MAP_BACKEND_{map_backend.upper()}")
    try:
        session_id = stub.CreateSession(request, timeout=RPC_TIMEOUT_S).session_id
    except grpc.RpcError as exc:
        result.status = "unavailable" if exc.code() == grpc.StatusCode.UNIMPLEMENTED else "error"
        result.message = f"CreateSession: {exc.code().name}: {exc.details()}"
        return result
    updates: list[pb.CameraUpdate] = []
    t0 = time.perf_counter()
    try:
        for update in stub.StreamFrames(scenario.frame_updates(session_id, timeline), timeout=STREAM_TIMEOUT_S):
            updates.append(update)
    except grpc.RpcError as exc:
        result.status = "unavailable" if exc.code() == grpc.StatusCode.UNIMPLEMENTED else "error"
        result.message = f"StreamFrames after {len(updates)} frames: {exc.code().name}: {exc.details()}"
    else:
        result.status = "ok"
    result.wall_s = time.perf_counter() - t0
    try:
        stub.CloseSession(pb.CloseSessionRequest(session_id=session_id), timeout=RPC_TIMEOUT_S)
    except grpc.RpcError:
        pass  # the session is reclaimed after the resume window anyway
    if updates:
        result.measurement = measure(scenario, timeline, CameraTrack.from_updates(updates), meter)
    return result


def open_channel(address: str) -> grpc.Channel:
    """An insecure gRPC channel to HOST:PORT (a leading grpc:// is accepted)."""
    address = address.removeprefix("grpc://")
    return grpc.insecure_channel(
        address,
        options=[("grpc.max_send_message_length", MAX_MESSAGE_BYTES), ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES)],
    )


def run_scenario(
    scenario: Scenario,
    mode: int | str = "FRAMING_ONLY",
    *,
    server: str | None = None,
    duration_s: float | None = None,
    **overrides,
) -> RunResult:
    """Runs one scenario with one visibility mode on the server at `server` (gRPC HOST:PORT), or on
    a server subprocess started for this run when `server` is None. overrides: run_on_channel's
    map_resolution and map_backend."""
    if server is None:
        with ServerProcess("--workers", "0", transports=("grpc",)) as proc:
            return run_scenario(scenario, mode, server=proc.grpc, duration_s=duration_s, **overrides)
    with open_channel(server) as channel:
        result = run_on_channel(channel, scenario, mode, duration_s=duration_s, **overrides)
    result.server = server
    return result


def write_json(result: RunResult, path: Path | str, series: bool = True) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result.as_dict(series=series), separators=(",", ":")) + "\n")


# --------------------------------------------------------------------------------------------
# Plots (matplotlib, Agg)


def pyplot_agg():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_top_view(ax, scenario: Scenario) -> None:
    """Static geometry seen from above: the walls (near-vertical triangles) as thin grey strokes."""
    from matplotlib.collections import LineCollection

    from camdirector.geometry.transforms import RigidTransform

    segments = []
    for a in scenario.objects:
        if a.dynamic:
            continue
        v = RigidTransform(a.position, a.rotation, a.scale).apply(a.shape.mesh.vertices)
        tri = v[a.shape.mesh.faces]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        upright = np.abs(normal[:, 1]) < 0.3 * np.linalg.norm(normal, axis=1)
        for i, j in ((0, 1), (1, 2), (2, 0)):
            segments.append(np.stack([tri[upright][:, i][:, [0, 2]], tri[upright][:, j][:, [0, 2]]], axis=1))
    if segments:
        ax.add_collection(LineCollection(list(np.concatenate(segments)), colors="0.6", linewidths=0.4))


def draw_dynamic_paths(ax, scenario: Scenario, timeline: Timeline) -> None:
    """The paths of the dynamic objects (not the targets) while they are in the scene, faint."""
    for a in scenario.objects:
        if a.dynamic and a.id in timeline.position:
            p = timeline.position[a.id]
            present = p[:, 1] > PARK_OFFSET_M[1] / 2.0
            if present.any():
                ax.plot(p[present, 0], p[present, 2], color="tab:purple", lw=0.5, alpha=0.35)
                ax.plot(p[present][-1, 0], p[present][-1, 2], "o", color="tab:purple", ms=2, alpha=0.5)


def plot_run(result: RunResult, path: Path | str) -> None:
    """Visibility and speed over time, and a top view of the target and camera paths."""
    m = result.measurement
    if m is None:
        return
    plt = pyplot_agg()
    fig = plt.figure(figsize=(14, 7), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=[1.4, 1])
    ax_vis, ax_speed, ax_top = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[1, 0]), fig.add_subplot(grid[:, 1])
    t = m.track.time_s
    cuts = t[1:][m.track.cut[1:]]
    ax_vis.plot(t, m.visibility, lw=1.0, label="measured: target vertices in frame and unobstructed")
    ax_vis.plot(t, m.line_of_sight, lw=0.8, ls=":", label="unobstructed only (the paper's rays)")
    ax_vis.plot(t, m.track.rig_visibility, lw=0.8, ls="--", alpha=0.7, label="rig's own estimate")
    ax_vis.set_ylim(-0.05, 1.05)
    ax_vis.set_ylabel("visibility")
    ax_vis.legend(loc="lower left", fontsize=8)
    ax_speed.plot(t, m.speed_m_s, lw=1.0, label="speed, m/s")
    ax_speed.set_ylabel("camera speed, m/s")
    ax_speed.set_xlabel("time, s")
    for ax in (ax_vis, ax_speed):
        for c in cuts:
            ax.axvline(c, color="r", lw=0.6, alpha=0.6)
    draw_top_view(ax_top, result.scenario)
    if result.timeline is not None:
        draw_dynamic_paths(ax_top, result.scenario, result.timeline)
    for target_id, p in m.target_position.items():
        ax_top.plot(p[:, 0], p[:, 2], lw=1.5, label=f"target {target_id}")
    cam = m.track.position
    ax_top.plot(cam[:, 0], cam[:, 2], "k-", lw=0.8, label="camera")
    if len(cuts):
        ax_top.plot(cam[1:][m.track.cut[1:], 0], cam[1:][m.track.cut[1:], 2], "rx", label="cut")
    everything = np.concatenate([cam, *m.target_position.values()])
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    pad = 0.1 * max(hi[0] - lo[0], hi[2] - lo[2], 1.0)
    ax_top.set_xlim(lo[0] - pad, hi[0] + pad)
    ax_top.set_ylim(lo[2] - pad, hi[2] + pad)
    ax_top.set_aspect("equal")
    ax_top.set_xlabel("x, m")
    ax_top.set_ylabel("z, m")
    ax_top.legend(loc="best", fontsize=8)
    summary = m.summary()
    fig.suptitle(
        f"{result.scenario.name}, {result.mode}: visibility median {_fmt(summary['visibility']['median'])}, "
        f"speed median {_fmt(summary['speed_m_s']['median'])} m/s, {summary['cuts']} cuts"
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fmt(x: float | None, digits: int = 2) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"
