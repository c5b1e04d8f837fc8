"""`camdirector demo` (what `make run` runs): a server, the built-in demo game client, a video.

The client streams the procedural demo scene (an avatar walking among columns and moving
obstacles) at 60 Hz of wall-clock time through a real server process and the Python SDK, shows
progress, then renders the directed camera's view offscreen (EGL) to `demo.mp4`, draws a top
view of the paths to `demo-topdown.png`, and writes `demo-summary.json`.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

import camdirector_client as cd
from camdirector.demo.scene import DemoScene, build_demo_scene
from camdirector.deploy.server_process import ServerProcess
from camdirector.geometry.camera import CameraPose, Lens, project_to_screen

FPS = 60
VIDEO_SIZE = (960, 540)  # llvmpipe renders this in ~10 ms a frame; even sizes for yuv420p


def session_request(scene: DemoScene, lens: Lens, visibility: int = cd.pb.FRAMING_ONLY) -> cd.pb.CreateSessionRequest:
    objects = [
        cd.pb.SceneObject(
            id=o.id,
            mesh=cd.mesh_from_arrays(o.vertices, o.faces),
            dynamic=o.dynamic,
            transform=cd.transform_msg(o.transform.position_world, o.transform.rotation_xyzw),
        )
        for o in [*scene.static_objects, *scene.dynamic_objects]
    ]
    avatar = scene.avatar
    target = cd.pb.Target(
        id=avatar.id,
        mesh=cd.mesh_from_arrays(avatar.vertices, avatar.faces),
        transform=cd.transform_msg(avatar.transform.position_world, avatar.transform.rotation_xyzw),
        aim_offset=cd.vec3(scene.avatar_aim_offset),
    )
    return cd.pb.CreateSessionRequest(
        objects=objects,
        targets=[target],
        seed=scene.seed,
        lens=cd.pb.Lens(vertical_fov_deg=lens.vertical_fov_deg, aspect=lens.aspect),
        style=cd.pb.Style(visibility=visibility),
    )


def _paced_frames(scene: DemoScene, n_frames: int, sent_at: list[float]):
    """FrameUpdates at 60 Hz of wall-clock time, as a game loop would send them."""
    start = time.perf_counter()
    for i, update in enumerate(frame_updates(scene, n_frames)):
        delay = start + i / FPS - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        sent_at.append(time.perf_counter())
        yield update


def frame_updates(scene: DemoScene, n_frames: int, rate_hz: float = FPS) -> Iterator[cd.pb.FrameUpdate]:
    """The demo's frames 1 to n_frames at rate_hz of game time, without a session id: the avatar's
    and the moving obstacles' transforms as packed states. Each is built when asked for (a paced
    sender builds it when it is due); the benchmarks stream the same frames."""
    ids = [scene.avatar.id, *[o.id for o in scene.dynamic_objects]]
    for i in range(n_frames):
        time_s = i / rate_hz
        transforms = scene.transforms_at(time_s)
        packed_ids, packed = cd.pack_states(
            ids, np.stack([transforms[k].position_world for k in ids]), np.stack([transforms[k].rotation_xyzw for k in ids])
        )
        yield cd.pb.FrameUpdate(frame=i + 1, time_s=time_s, packed_ids=packed_ids, packed_transforms=packed)


def _progress(i: int, n: int, rtt_ms: list[float], compute_ms: list[float], visibility: list[float]) -> None:
    width = 30
    done = int(width * i / n)
    sys.stderr.write(
        f"\r  streaming [{'#' * done}{'.' * (width - done)}] {i}/{n} frames"
        f"  rtt p50 {np.median(rtt_ms):.2f} ms  compute p50 {np.median(compute_ms):.2f} ms"
        f"  visibility {np.mean(visibility):.2f} "
    )
    sys.stderr.flush()


def stream_demo(
    url: str,
    scene: DemoScene,
    lens: Lens,
    seconds: float,
    visibility: int,
    key: str | None = None,
    zmq_server_key: str | None = None,
) -> dict:
    """Streams the scene through one session (with `key`, and over ZeroMQ the server's CURVE
    `zmq_server_key`, when the server checks keys); returns the poses and the timings."""
    n_frames = int(round(seconds * FPS))
    sent_at: list[float] = []
    updates: list[cd.pb.CameraUpdate] = []
    rtt_ms: list[float] = []
    request = session_request(scene, lens, visibility)
    with cd.connect(url, key=key, zmq_server_key=zmq_server_key) as client, client.create_session(request) as session:
        for update in session.stream(_paced_frames(scene, n_frames, sent_at)):
            rtt_ms.append((time.perf_counter() - sent_at[len(updates)]) * 1e3)
            updates.append(update)
            if len(updates) % 30 == 0 or len(updates) == n_frames:
                _progress(len(updates), n_frames, rtt_ms, [u.compute_ms for u in updates], [u.visibility for u in updates])
    sys.stderr.write("\n")
    return {"updates": updates, "rtt_ms": np.array(rtt_ms), "frames_sent": len(sent_at)}


def _pose(update) -> CameraPose:
    p, q = update.pose.position, update.pose.rotation
    return CameraPose(np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]), update.pose.vertical_fov_deg)


def render_video(scene: DemoScene, lens: Lens, poses: list[CameraPose], out_mp4: Path) -> float:
    """Renders the directed camera's view; returns the median ms per frame (render + encode)."""
    from camdirector.demo.scene import add_scene_to_renderer
    from camdirector.geometry.render import OffscreenRenderer
    from camdirector.geometry.video import VideoWriter

    costs = []
    with OffscreenRenderer(*VIDEO_SIZE) as renderer, VideoWriter(out_mp4, FPS, VIDEO_SIZE) as video:
        add_scene_to_renderer(scene, renderer)
        for i, pose in enumerate(poses):
            t0 = time.perf_counter()
            for object_id, transform in scene.transforms_at(i / FPS).items():
                renderer.set_transform(object_id, transform.matrix())
            video.write(renderer.render(pose, lens))
            costs.append((time.perf_counter() - t0) * 1e3)
            if (i + 1) % 60 == 0 or i + 1 == len(poses):
                sys.stderr.write(f"\r  rendering {i + 1}/{len(poses)} frames")
                sys.stderr.flush()
    sys.stderr.write("\n")
    return float(np.median(costs))


def run_demo(
    out_dir: Path, seconds: float = 20.0, transport: str = "grpc", render: bool = True, visibility: str = "ANTICIPATION"
) -> int:
    out_dir.mkdir(parents=True, exist_ok=True)
    lens = Lens(vertical_fov_deg=50.0, aspect=VIDEO_SIZE[0] / VIDEO_SIZE[1])
    print(f"camdirector demo: {seconds:.0f} s of a walk among columns and moving obstacles at {FPS} Hz, {visibility}")
    scene = build_demo_scene(seed=7, duration_s=seconds)
    with ServerProcess("--workers", "1", auth=True) as server:  # as users run it: keys on (docs/security.md)
        print(f"  server ready: gRPC {server.grpc}, ZeroMQ {server.zmq}, HTTP {server.http}")
        print(
            f"  watch it in the dashboard: http://{server.http}/dashboard/ (log in with the key in "
            f"{server.ready['admin_key_file']})"
        )
        url = server.url(transport)
        assert url is not None  # the server runs every transport
        result = stream_demo(
            url,
            scene,
            lens,
            seconds,
            cd.pb.VisibilityMode.Value(visibility),
            key=server.admin_key,
            zmq_server_key=server.zmq_server_key if transport == "zmq" else None,
        )
    updates = result["updates"]
    poses = [_pose(u) for u in updates]
    aims = np.stack([scene.aim_point_world(i / FPS) for i in range(len(updates))])
    screen_error = max(float(np.abs(project_to_screen(p, lens, a[None])[0] - (-1 / 3, 0.0)).max()) for p, a in zip(poses, aims))
    camera = np.stack([p.position_world for p in poses])
    speed = np.linalg.norm(np.diff(camera, axis=0), axis=1) * FPS
    compute = np.array([u.compute_ms for u in updates])
    summary = {
        "transport": transport,
        "visibility_mode": visibility,
        "frames_sent": result["frames_sent"],
        "frames_received": len(updates),
        "dropped_frames": result["frames_sent"] - len(updates),
        "rtt_ms": {"p50": float(np.median(result["rtt_ms"])), "p99": float(np.percentile(result["rtt_ms"], 99))},
        "compute_ms": {"p50": float(np.median(compute)), "p99": float(np.percentile(compute, 99))},
        "visibility": {
            "mean": float(np.mean([u.visibility for u in updates])),
            "min": float(np.min([u.visibility for u in updates])),
        },
        "camera_speed_m_s": {"p50": float(np.median(speed)), "max": float(speed.max())},
        "cuts": int(sum(u.cut for u in updates)),
        "target_screen_error_max": screen_error,
    }
    from camdirector.demo.topdown import draw_topdown

    cut_indices = [i for i, u in enumerate(updates) if u.cut and i > 0]
    draw_topdown(scene, aims[:, [0, 2]], camera[:, [0, 2]], out_dir / "demo-topdown.png", cut_indices=cut_indices)
    if render:
        summary["render_ms_per_frame_p50"] = render_video(scene, lens, poses, out_dir / "demo.mp4")
    (out_dir / "demo-summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    print(f"wrote {out_dir / 'demo.mp4'}, {out_dir / 'demo-topdown.png'}, {out_dir / 'demo-summary.json'}")
    return 0 if summary["dropped_frames"] == 0 else 1
