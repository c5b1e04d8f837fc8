"""Helpers of the TRACKS rig tests: levels written as OBJ and added by the CLI, session requests, an
actor's frames, and where a pose puts the actor on screen."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.transforms import quat_to_matrix
from camdirector.v1 import director_pb2 as pb
from tests.service.wire_client import GrpcRaw, capsule_target

ROOT = Path(__file__).resolve().parents[2]
AGENT_HEIGHT_M = 2.0  # the CLI's default; the director frames this far up the actor
LOOK_AT_FRACTION = 0.6  # DirectorSettings.look_at_fraction


def obj_text(mesh: TriMesh) -> str:
    return "".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices) + "".join(
        f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces
    )


def cli_add_level(data_dir: Path, name: str, level_file: Path) -> dict:
    """`camdirector level add NAME FILE --data-dir DIR` in a child process, for the 2.0 m, 0.6 m
    agent these tests' levels and tests/data/recordings were made with (the command's own default
    is the match importers' player since issue 41); its JSON record."""
    done = subprocess.run(
        [
            *(sys.executable, "-m", "camdirector.__main__", "level", "add", name, str(level_file)),
            *("--data-dir", str(data_dir), "--agent-height", "2.0", "--agent-radius", "0.6"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def tracks_request(
    level_id: str, actor_world, shot_size=pb.SHOT_SIZE_LONG, movement=pb.MOVEMENT_DYNAMIC_WITH_CUTS, seed: int = 1, **kwargs
) -> pb.CreateSessionRequest:
    """One capsule actor standing on actor_world (its feet: the capsule stands on its origin)."""
    actor = capsule_target("actor", position=tuple(float(v) for v in actor_world))
    return pb.CreateSessionRequest(
        targets=[actor],
        level_id=level_id,
        seed=seed,
        style=pb.Style(rig=pb.RIG_TRACKS, shot_size=shot_size, movement=movement),
        **kwargs,
    )


def actor_frames(session_id: str, times_s, positions_world, start_frame: int = 1) -> list[pb.FrameUpdate]:
    """Frames moving the actor (packed states), facing its direction of travel about +Y."""
    frames = []
    positions_world = np.asarray(positions_world, dtype=np.float64)
    for i, (t, p) in enumerate(zip(times_s, positions_world)):
        step = positions_world[min(i + 1, len(positions_world) - 1)] - positions_world[max(i - 1, 0)]
        yaw = np.arctan2(step[0], step[2]) if np.hypot(step[0], step[2]) > 1e-9 else 0.0
        frames.append(
            pb.FrameUpdate(
                session_id=session_id,
                frame=start_frame + i,
                time_s=float(t),
                packed_ids=["actor"],
                packed_transforms=[*p, 0.0, np.sin(yaw / 2), 0.0, np.cos(yaw / 2), 1, 1, 1],
            )
        )
    return frames


def corridor_walk(seconds: float, fps: float = 30.0, speed_m_s: float = 1.4) -> tuple[np.ndarray, np.ndarray]:
    """times (F,), feet positions (F, 3) of an actor walking down tiny_levels.corridor() and back."""
    times = np.arange(int(seconds * fps)) / fps
    x = 2.0 + np.abs((speed_m_s * times + 26.0) % 52.0 - 26.0)  # 2 .. 28 and back
    return times, np.stack([x, np.zeros_like(x), np.full_like(x, 2.0)], axis=1)


def pose_of(update: pb.CameraUpdate) -> CameraPose:
    p, q = update.pose.position, update.pose.rotation
    return CameraPose(np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]), update.pose.vertical_fov_deg)


def look_at_world(feet_world) -> np.ndarray:
    return np.asarray(feet_world, dtype=np.float64) + [0.0, LOOK_AT_FRACTION * AGENT_HEIGHT_M, 0.0]


def camera_distance_m(update: pb.CameraUpdate, feet_world) -> float:
    return float(np.linalg.norm(pose_of(update).position_world - look_at_world(feet_world)))


def check_directed(updates: list[pb.CameraUpdate], feet_world) -> None:
    """Every pose looks at the actor (its axis at the screen's vertical centre line, its feet
    below the centre and its head above: the director centres the framed extent) with no roll;
    shot_id counts the cuts; the first frame cuts."""
    assert updates[0].cut
    for update, feet in zip(updates, feet_world):
        feet_head = np.asarray(feet, dtype=np.float64) + np.outer([0.0, AGENT_HEIGHT_M], [0.0, 1.0, 0.0])
        screen = project_to_screen(pose_of(update), Lens(), feet_head)
        assert np.allclose(screen[:, 0], 0.0, atol=1e-6) and screen[0, 1] < 0.0 < screen[1, 1], update.frame
        right_world = quat_to_matrix(pose_of(update).rotation_xyzw)[:, 0]
        assert abs(right_world[1]) < 1e-6, "the camera rolls"
    shots = [u.shot_id for u in updates]
    cuts = [u.cut for u in updates]
    assert all(b - a == int(c) for a, b, c in zip(shots, shots[1:], cuts[1:])), "shot_id must step on every cut"


@contextlib.contextmanager
def tracks_canary(server, level_id: str, start_world):
    """A TRACKS session on level_id streamed before and after the body; it must not notice."""
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", tracks_request(level_id, start_world)).session_id
    times, feet = corridor_walk(2.0)
    before = raw.stream(actor_frames(session_id, times[:30], feet[:30]))
    yield
    after = raw.stream(actor_frames(session_id, times[30:], feet[30:], start_frame=31))
    assert server.alive()
    check_directed(before + after, feet)
    assert not any(u.stale for u in after)
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    raw.close()
