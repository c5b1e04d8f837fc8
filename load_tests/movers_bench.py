"""Moving objects benchmark: what a frame costs as the number of moving rigid objects grows.

    python -m load_tests.movers_bench --json FILE [--frames N] [--movers 0,10,50,100] [--modes M,...]
        [--frame-path python|compiled]

Scene: about 2,000 static triangles (a floor and 160 crates in a ring), one actor walking a circle
of 6 m radius, and 0, 10, 50 or 100 moving boxes (1 x 2 x 1 m) circling the actor at 3-14 m, each
at its own speed. For ANTICIPATION (64 x 64 maps, the backend the server picks, AUTO) and
FRAMING_ONLY, a session runs in this process through the worker's own SessionTable, so each
frame goes from the serialized FrameUpdate to the serialized CameraUpdate exactly as in a worker,
and `compute_ms` is the figure a client reads in its CameraUpdate. Reported: median and p99 of
`compute_ms` and the median of each stage (`stage_ms`), per mode and mover count, the ratio of
each count to 0 per mode, and a floor from the same run: the wall-clock time of a stale frame
through the same table (its shortest path: parse, look up, answer the last pose, serialize),
measured after every case, with each case's median over it. Poses are a function of the frame
number and the seed alone, so a run is reproducible frame for frame.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from camdirector.server_settings import FRAME_PATHS, ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.table import SessionTable
from load_tests.report import emit, summary

RATE_HZ = 60.0
ACTOR_RADIUS_M = 6.0
ACTOR_SPEED_M_S = 1.5
MODES = {"ANTICIPATION": pb.ANTICIPATION, "REACTIVE": pb.REACTIVE, "FRAMING_ONLY": pb.FRAMING_ONLY}


def _vec(x: float, y: float, z: float) -> pb.Vec3:
    return pb.Vec3(x=x, y=y, z=z)


def _box(size) -> pb.Mesh:
    return pb.Mesh(primitive=pb.Primitive(box=pb.Primitive.Box(size=_vec(*size))))


def scene_request(movers: int, mode: int, seed: int = 0) -> pb.CreateSessionRequest:
    """The floor (2 triangles), 160 static crates (1,920 triangles), `movers` dynamic boxes, the actor."""
    objects = [
        pb.SceneObject(
            id="floor",
            mesh=pb.Mesh(
                triangles=pb.TriangleMesh(vertices=[-40, 0, -40, 40, 0, -40, 40, 0, 40, -40, 0, 40], indices=[0, 2, 1, 0, 3, 2])
            ),
        )
    ]
    for i in range(160):
        angle = 2.0 * math.pi * i / 160
        radius = 18.0 + 4.0 * (i % 3)
        objects.append(
            pb.SceneObject(
                id=f"crate{i}",
                mesh=_box((1.0, 1.5, 1.0)),
                transform=pb.Transform(position=_vec(radius * math.cos(angle), 0.75, radius * math.sin(angle))),
            )
        )
    for i in range(movers):
        x, z = _mover_xz(i, 0.0, seed)
        objects.append(
            pb.SceneObject(
                id=f"mover{i}", dynamic=True, mesh=_box((1.0, 2.0, 1.0)), transform=pb.Transform(position=_vec(x, 1.0, z))
            )
        )
    actor = pb.Target(
        id="actor",
        mesh=pb.Mesh(primitive=pb.Primitive(capsule=pb.Primitive.Capsule(radius=0.3, height=1.8))),
        transform=pb.Transform(position=_vec(ACTOR_RADIUS_M, 0.9, 0.0)),
        aim_offset=_vec(0.0, 0.6, 0.0),
    )
    return pb.CreateSessionRequest(
        objects=objects, targets=[actor], seed=seed, style=pb.Style(visibility=mode, map_resolution=64)
    )


def _actor_xz(t: float) -> tuple[float, float]:
    angle = ACTOR_SPEED_M_S * t / ACTOR_RADIUS_M
    return ACTOR_RADIUS_M * math.cos(angle), ACTOR_RADIUS_M * math.sin(angle)


def _mover_xz(i: int, t: float, seed: int) -> tuple[float, float]:
    """Mover i circles the actor's circle's centre at 3-14 m, 0.2-0.6 rad/s, either way round."""
    rng = np.random.default_rng((seed, i))
    radius, speed, phase = rng.uniform(3.0, 14.0), rng.uniform(0.2, 0.6) * rng.choice((-1, 1)), rng.uniform(0, 2 * np.pi)
    return radius * math.cos(phase + speed * t), radius * math.sin(phase + speed * t)


def frame_bytes(session_id: str, frame: int, movers: int, seed: int = 0) -> bytes:
    """Frame `frame`: the actor and every mover moved (packed states, as the SDK sends them)."""
    t = frame / RATE_HZ
    ids, values = ["actor"], []
    ax, az = _actor_xz(t)
    values += [ax, 0.9, az, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]
    for i in range(movers):
        x, z = _mover_xz(i, t, seed)
        yaw = 0.3 * t + i
        ids.append(f"mover{i}")
        values += [x, 1.0, z, 0.0, math.sin(yaw / 2), 0.0, math.cos(yaw / 2), 1.0, 1.0, 1.0]
    return pb.FrameUpdate(
        session_id=session_id, frame=frame, time_s=t, packed_ids=ids, packed_transforms=values
    ).SerializeToString()


def run_case(table: SessionTable, mode_name: str, movers: int, frames: int, warmup: int) -> dict:
    session_id = f"{mode_name}-{movers}"
    table.create(session_id, scene_request(movers, MODES[mode_name]))
    requests = Dispatcher(table)  # frames as a worker answers them: bytes in, bytes out
    compute, stages = [], {}
    for k in range(1, warmup + frames + 1):
        reply = pb.CameraUpdate.FromString(requests.handle_bytes("frame", session_id, frame_bytes(session_id, k, movers))[0])
        if k > warmup:
            compute.append(reply.compute_ms)
            for name, ms in reply.diagnostics.stage_ms.items():
                stages.setdefault(name, []).append(ms)
    maps = table.held[session_id].session.rig.maps
    stale_payload, stale = frame_bytes(session_id, 1, movers), []
    for _ in range(200):
        t0 = time.perf_counter()
        requests.handle_bytes("frame", session_id, stale_payload)
        stale.append((time.perf_counter() - t0) * 1e3)
    table.drop(session_id)
    return {
        "mode": mode_name,
        "movers": movers,
        "map_backend": maps.backend_name if maps is not None else None,
        "compute_ms": summary(compute),
        "stage_ms_median": {name: round(float(np.median(v)), 4) for name, v in sorted(stages.items())},
        "stale_frame_wall_ms": summary(stale),
        "median_over_floor": round(float(np.median(compute) / max(np.median(stale), 1e-9)), 2),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=600, help="timed frames per case (after --warmup)")
    parser.add_argument("--warmup", type=int, default=60, help="frames run before timing, per case")
    parser.add_argument("--movers", default="0,10,50,100", help="comma-separated mover counts")
    parser.add_argument("--modes", default=",".join(MODES), help=f"comma-separated visibility modes, of {', '.join(MODES)}")
    parser.add_argument("--frame-path", choices=FRAME_PATHS, default="python", help="the server's frame path (ServerSettings)")
    parser.add_argument("--json", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    try:
        counts = [int(c) for c in args.movers.split(",")]
    except ValueError:
        print(f"movers_bench: --movers must be comma-separated integers, got {args.movers!r}", file=sys.stderr)
        return 2
    modes = args.modes.split(",")
    if not set(modes) <= set(MODES):
        print(f"movers_bench: --modes must be of {', '.join(MODES)}, got {args.modes!r}", file=sys.stderr)
        return 2
    table = SessionTable(ServerSettings(max_objects=10_000, checkpoint_store="off", frame_path=args.frame_path))
    cases = [run_case(table, mode, n, args.frames, args.warmup) for mode in modes for n in counts]
    table.close_all()
    floor = summary([c["stale_frame_wall_ms"]["median"] for c in cases])
    ratios = {}
    for mode in modes:
        by_count = {c["movers"]: c["compute_ms"]["median"] for c in cases if c["mode"] == mode}
        if 0 in by_count:
            ratios[mode] = {f"{n}_over_0": round(ms / max(by_count[0], 1e-9), 3) for n, ms in by_count.items() if n}
    emit(
        {
            "benchmark": "movers_bench",
            "frame_path": args.frame_path,
            "frames_per_case": args.frames,
            "rate_hz": RATE_HZ,
            "static_triangles": 2 + 160 * 12,
            "in_process": True,
            "floor_stale_frame_wall_ms": floor,
            "cases": cases,
            "median_ratio_to_0_movers": ratios,
        },
        args.json,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
