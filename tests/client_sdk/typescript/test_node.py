"""The TypeScript SDK (client_sdk/typescript, issue 28) built from proto/ and tested with Node's
test runner against real servers: `npm ci` and `npm run build` once, then each `node --test`
file of client_sdk/typescript/test/ with the servers' addresses, keys and the Python SDK's own
answers passed by environment and JSON files.

- parity: for the same session inputs (the default toric rig with packed transforms, unary and
  streamed; a RIG_MATCH session with events, a take and its release), the TypeScript SDK's replies
  equal the Python SDK's bit for bit, over gRPC and over ZeroMQ (CURVE and a key, both SDKs); its
  encoded FrameUpdate equals the Python SDK's byte for byte;
- ZeroMQ's CURVE: the server key as text or its file, none or another server's (DEADLINE_EXCEEDED
  with a hint), refused bearer keys;
- conversions: Unity and Unreal conversions, rotation matrices and poses equal the Python SDK's
  on the same random poses;
- bad input: every kind answered with its code (DirectorError.code);
- keys and TLS: grpcs:// with the test CA, keys, refused keys never tried again, no key shown;
- a worker SIGKILLed under live TypeScript streams: every frame answered once, in order, as an
  undisturbed run; the same for a cluster node SIGKILLed under streams through its balancer
  (HAProxy, TLS, an engine key; skipped without Debian's cluster packages, failed under CI);
- the HTTP game-state bridge example driven by posted states;
- the protocol: CreateSession says PROTOCOL (read back from the server's recording of the session)
  over gRPC and ZeroMQ, and a request claiming a newer one is FAILED_PRECONDITION with the
  server's words, after which the client opens another session.

Without node or npm the module is skipped with the reason; under CI (.ci/run sets
CAMDIRECTOR_REQUIRE_NODE=1) that is a failure.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import camdirector_client as cd
from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from camdirector.version import PROTOCOL
from camdirector_client import wire
from tests.service.test_match_sessions import frames as match_frames
from tests.service.test_match_sessions import match_request
from tests.service.wire_client import two_target_request, walk

ROOT = Path(__file__).resolve().parents[3]
PACKAGE = ROOT / "client_sdk" / "typescript"
NODE_MAJOR = 20


def _missing_node() -> str | None:
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        return "node and npm are needed for the TypeScript SDK's tests (Node 20+)"
    version = subprocess.run([node, "--version"], capture_output=True, text=True).stdout.strip()
    if int(version.lstrip("v").split(".")[0]) < NODE_MAJOR:
        return f"Node {NODE_MAJOR}+ is needed for the TypeScript SDK's tests, found {version}"
    return None


def _run(cmd: list[str], timeout: float, env: dict | None = None) -> subprocess.CompletedProcess:
    done = subprocess.run(cmd, cwd=PACKAGE, capture_output=True, text=True, timeout=timeout, env={**os.environ, **(env or {})})
    if done.returncode != 0:
        pytest.fail(f"{' '.join(cmd)} exited {done.returncode}\n{done.stdout[-6000:]}\n{done.stderr[-4000:]}")
    return done


@pytest.fixture(scope="module")
def built():
    """`npm ci` (skipped when node_modules already holds this package-lock's tree) and `npm run build`."""
    reason = _missing_node()
    if reason is not None:
        if os.environ.get("CAMDIRECTOR_REQUIRE_NODE") == "1":
            pytest.fail(f"{reason} (CAMDIRECTOR_REQUIRE_NODE=1)")
        pytest.skip(reason)
    installed = PACKAGE / "node_modules" / ".package-lock.json"
    lock = PACKAGE / "package-lock.json"
    if not installed.is_file() or installed.stat().st_mtime < lock.stat().st_mtime:
        _run(["npm", "ci", "--no-audit", "--no-fund"], timeout=300)
    _run(["npm", "run", "build"], timeout=300)
    return PACKAGE


def node_test(name: str, timeout: float = 90.0, **env: str) -> str:
    """Runs `node --test test/NAME.test.mjs` with `env`; its output."""
    done = _run(["node", "--test", "--test-reporter=spec", f"test/{name}.test.mjs"], timeout=timeout, env=env)
    return done.stdout


@pytest.fixture(scope="module")
def server(built):
    """Two workers, gRPC only, checkpoints every 60 frames (the worker-kill test's, last), at most 5000
    triangles a scene (the bad-input test's RESOURCE_EXHAUSTED)."""
    with ServerProcess(
        "--workers", "2", "--checkpoint-every-frames", "60", "--max-triangles", "5000", transports=("grpc",)
    ) as srv:
        yield srv


# --- what the Python SDK answers, as JSON both sides read exactly --------------------------------


def _pose(p: pb.CameraPose) -> list[float]:
    return [p.position.x, p.position.y, p.position.z, p.rotation.x, p.rotation.y, p.rotation.z, p.rotation.w, p.vertical_fov_deg]


def reply_json(u: pb.CameraUpdate) -> dict:
    """What of a reply must be the same for the same inputs (not compute_ms nor stage_ms)."""
    return {
        "frame": u.frame,
        "timeS": u.time_s,
        "pose": _pose(u.pose) if u.HasField("pose") else None,
        "cut": u.cut,
        "shotId": u.shot_id,
        "visibility": u.visibility,
        "stale": u.stale,
        "buffering": u.buffering,
        "message": u.message,
        "diagnostics": [u.diagnostics.theta, u.diagnostics.phi, u.diagnostics.alpha],
        "shot": [list(u.shot.subject_ids), u.shot.kind, u.shot.reason, u.shot.held],
        "candidates": [[_pose(c.pose), list(c.shot.subject_ids), c.shot.kind, c.score] for c in u.candidates],
    }


def frame_json(u: pb.FrameUpdate) -> dict:
    """A FrameUpdate (states and events) for the TypeScript side to build again."""
    states = []
    for s in u.states:
        t = s.transform
        states.append(
            {
                "id": s.id,
                "p": [t.position.x, t.position.y, t.position.z],
                "q": [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w] if t.HasField("rotation") else None,
            }
        )
    events = [{"kind": e.kind, "actorId": e.actor_id, "otherActorId": e.other_actor_id} for e in u.events]
    return {"frame": u.frame, "timeS": u.time_s, "states": states, "events": events}


def _b64(message) -> str:
    return base64.b64encode(message.SerializeToString()).decode()


def _write(path: Path, data: dict) -> str:
    path.write_text(json.dumps(data, allow_nan=False))
    return str(path)


def _packed_walk(n: int, start: int = 1):
    for i in range(start, start + n):
        t = i / 60
        ids, packed = cd.pack_states(
            ["a", "cart"], np.array([[np.sin(t), 0.9, t], [-2 + t, 0.5, 2.0]]), np.array([[0, 0, 0, 1.0], [0, 0, 0, 1.0]])
        )
        yield i, t, ids, packed


def _toric_reference(url: str, **options) -> dict:
    create = two_target_request(seed=4)
    unary, streamed = list(_packed_walk(40)), list(_packed_walk(40, start=41))
    with cd.connect(url, **options) as client:
        with client.create_session(create) as session:
            replies = [session.frame(i, t, packed=(ids, p)) for i, t, ids, p in unary]
            replies += list(session.stream(session.frame_update(i, t, packed=(ids, p)) for i, t, ids, p in streamed))
            session.update_style({"screen_a": {"x": -0.5}, "screen_b": {"x": 0.5}})
            replies.append(session.frame(81, 81 / 60))
    frames = [{"frame": i, "timeS": t, "ids": ids, "transforms": p.tolist()} for i, t, ids, p in unary + streamed]
    encoded = wire.encode_frame_update("sid", 7, 0.125, packed=(unary[0][2], unary[0][3]))
    return {
        "create": _b64(create),
        "frames": frames,
        "unary": len(unary),
        "expected": [reply_json(u) for u in replies],
        "encoded": {
            "sessionId": "sid",
            "frame": 7,
            "timeS": 0.125,
            "ids": unary[0][2],
            "transforms": unary[0][3].tolist(),
            "bytes": base64.b64encode(encoded).decode(),
        },
    }


def _match_reference(url: str, **options) -> dict:
    create = match_request(delay_s=0.0)
    first, second, third = (
        list(match_frames("", 60, kill_at={40: ("a0", "b0")})),
        list(match_frames("", 30, start=60)),
        list(match_frames("", 30, start=90)),
    )
    with cd.connect(url, **options) as client:
        with client.create_session(create) as session:
            replies = list(session.stream(first))
            taken = session.take_shot(["a1", "b1"])
            replies += list(session.stream(second))
            released = session.take_shot(release=True)
            replies += list(session.stream(third))
    return {
        "create": _b64(create),
        "parts": [[frame_json(u) for u in part] for part in (first, second, third)],
        "take": ["a1", "b1"],
        "taken": [list(taken.subject_ids), taken.kind, taken.held],
        "released": list(released.subject_ids),
        "expected": [reply_json(u) for u in replies],
    }


def test_replies_equal_the_python_sdks_bit_for_bit(server, tmp_path):
    url = server.url("grpc")
    data = {"toric": _toric_reference(url), "match": _match_reference(url)}
    assert data["match"]["expected"][-1]["shot"][0], "the match reference has a shot"
    node_test("parity", CAMDIRECTOR_TEST_URL=url, CAMDIRECTOR_TEST_DATA=_write(tmp_path / "parity.json", data))


@pytest.fixture(scope="module")
def zmq_server(built, tmp_path_factory):
    """Authentication on, ZeroMQ only: its socket a CURVE server; a viewer key beside the admin's."""
    data_dir = tmp_path_factory.mktemp("ts-zmq")
    with ServerProcess("--workers", "1", "--data-dir", str(data_dir), transports=("zmq",), auth=True) as srv:
        srv.viewer_key = subprocess.run(
            [sys.executable, "-m", "camdirector", "keys", "create", "--role", "viewer", "--data-dir", str(data_dir)],
            capture_output=True,
            text=True,
            timeout=60,
            check=True,
        ).stdout.strip()
        srv.key_file = data_dir / "zmq" / "server.key"
        yield srv


def test_replies_over_zeromq_with_curve_equal_the_python_sdks_bit_for_bit(zmq_server, tmp_path, monkeypatch):
    monkeypatch.delenv(wire.KEY_ENV, raising=False)
    url, key, server_key = zmq_server.url("zmq"), zmq_server.admin_key, zmq_server.zmq_server_key
    data = {
        "toric": _toric_reference(url, key=key, zmq_server_key=server_key),
        "match": _match_reference(url, key=key, zmq_server_key=server_key),
    }
    node_test(
        "parity",
        CAMDIRECTOR_TEST_URL=url,
        CAMDIRECTOR_TEST_DATA=_write(tmp_path / "parity.json", data),
        CAMDIRECTOR_TEST_CONNECT=json.dumps({"key": key, "zmqServerKey": server_key}),
    )


def test_zeromq_curve_and_keys(zmq_server, monkeypatch):
    monkeypatch.delenv(wire.KEY_ENV, raising=False)
    assert zmq_server.key_file.is_file()
    node_test(
        "zmq_curve",
        CAMDIRECTOR_TEST_URL=zmq_server.url("zmq"),
        CAMDIRECTOR_TEST_ADMIN_KEY=zmq_server.admin_key,
        CAMDIRECTOR_TEST_VIEWER_KEY=zmq_server.viewer_key,
        CAMDIRECTOR_TEST_ZMQ_SERVER_KEY=zmq_server.zmq_server_key,
        CAMDIRECTOR_TEST_ZMQ_SERVER_KEY_FILE=str(zmq_server.key_file),
    )


def _said_protocol(srv: ServerProcess, transport: str, tmp_path: Path, **connect_options) -> int:
    """test/protocol.test.mjs against `url`; the client_protocol its recorded session's
    CreateSessionRequest reached the server with (the recording's first entry)."""
    from camdirector.worker.recording import read_entries

    out = tmp_path / "protocol.json"
    node_test(
        "protocol",
        CAMDIRECTOR_TEST_URL=srv.url(transport),
        CAMDIRECTOR_TEST_OUT=str(out),
        CAMDIRECTOR_TEST_CONNECT=json.dumps(connect_options),
    )
    said = json.loads(out.read_text())
    assert said["protocol"] == PROTOCOL, "the SDK's PROTOCOL (src/wire.ts) is the server's"
    return next(read_entries(srv.data_dir / "recordings" / said["recordingPath"])).create.client_protocol


def test_create_session_says_the_protocol_over_grpc(server, tmp_path):
    assert _said_protocol(server, "grpc", tmp_path) == PROTOCOL


def test_create_session_says_the_protocol_over_zeromq(zmq_server, tmp_path, monkeypatch):
    monkeypatch.delenv(wire.KEY_ENV, raising=False)
    said = _said_protocol(zmq_server, "zmq", tmp_path, key=zmq_server.admin_key, zmqServerKey=zmq_server.zmq_server_key)
    assert said == PROTOCOL


def test_conversions_equal_the_python_sdks(built, tmp_path):
    rng = np.random.default_rng(28)
    n = 64
    positions = rng.normal(scale=50.0, size=(n, 3))
    rotations = rng.normal(size=(n, 4))
    rotations /= np.linalg.norm(rotations, axis=1, keepdims=True)
    raw_rotations = rng.normal(size=(n, 4)) * 3.0  # not unit: rotation_matrix and pose_from_msg normalise
    raw_rotations[0] = 0.0
    scales = rng.uniform(0.1, 4.0, size=(n, 3))
    fovs, aspects = rng.uniform(5.0, 120.0, size=n), rng.uniform(0.5, 3.0, size=n)
    poses = [
        pb.CameraPose(position=cd.vec3(p), rotation=cd.quat(q), vertical_fov_deg=f)
        for p, q, f in zip(positions, raw_rotations, fovs)
    ]
    converted = [cd.pose_from_msg(m) for m in poses]
    data = {
        "positions": positions.ravel().tolist(),
        "rotations": rotations.ravel().tolist(),
        "rawRotations": raw_rotations.ravel().tolist(),
        "scales": scales.ravel().tolist(),
        "fovs": fovs.tolist(),
        "aspects": aspects.tolist(),
        "expected": {
            "fromUnityPosition": cd.from_unity_position(positions).ravel().tolist(),
            "toUnityPosition": cd.to_unity_position(positions).ravel().tolist(),
            "fromUnityRotation": cd.from_unity_rotation(rotations).ravel().tolist(),
            "toUnityRotation": cd.to_unity_rotation(rotations).ravel().tolist(),
            "fromUnityScale": cd.from_unity_scale(scales).ravel().tolist(),
            "toUnityScale": cd.to_unity_scale(scales).ravel().tolist(),
            "fromUnrealPosition": cd.from_unreal_position(positions).ravel().tolist(),
            "toUnrealPosition": cd.to_unreal_position(positions).ravel().tolist(),
            "fromUnrealRotation": cd.from_unreal_rotation(rotations).ravel().tolist(),
            "toUnrealRotation": cd.to_unreal_rotation(rotations).ravel().tolist(),
            "fromUnrealScale": cd.from_unreal_scale(scales).ravel().tolist(),
            "toUnrealScale": cd.to_unreal_scale(scales).ravel().tolist(),
            "rotationMatrix": cd.rotation_matrix(raw_rotations).ravel().tolist(),
            "poseFromMsg": [[*c.position, *c.rotation_xyzw, c.vertical_fov_deg] for c in converted],
            "cameraPoseToUnity": [np.concatenate(cd.camera_pose_to_unity(m)).tolist() for m in poses],
            "cameraPoseToUnreal": [np.concatenate(cd.camera_pose_to_unreal(m)).tolist() for m in poses],
            "horizontalFovDeg": [cd.horizontal_fov_deg(f, a) for f, a in zip(fovs, aspects)],
            "packStates": cd.pack_states([f"p{i}" for i in range(n)], positions, rotations, scales)[1].tolist(),
        },
    }
    node_test("convert", CAMDIRECTOR_TEST_DATA=_write(tmp_path / "convert.json", data))


def test_every_kind_of_bad_input_is_answered_with_its_code(server):
    node_test("errors", CAMDIRECTOR_TEST_URL=server.url("grpc"))


@pytest.fixture(scope="module")
def tls_server(built, tmp_path_factory):
    """Authentication on, gRPC over TLS with a certificate of the test CA; a viewer key beside the admin's."""
    from camdirector.deploy.tls import make_tls_files

    tls = make_tls_files(tmp_path_factory.mktemp("ts-tls"))
    data_dir = tmp_path_factory.mktemp("ts-auth")
    with ServerProcess(
        "--workers",
        "1",
        "--data-dir",
        str(data_dir),
        "--tls-cert",
        str(tls.cert),
        "--tls-key",
        str(tls.key),
        transports=("grpc",),
        auth=True,
    ) as srv:
        srv.viewer_key = subprocess.run(
            [sys.executable, "-m", "camdirector", "keys", "create", "--role", "viewer", "--data-dir", str(data_dir)],
            capture_output=True,
            text=True,
            timeout=60,
            check=True,
        ).stdout.strip()
        srv.ca = tls.ca_cert
        yield srv


def test_keys_and_tls(tls_server, monkeypatch):
    monkeypatch.delenv(wire.KEY_ENV, raising=False)
    node_test(
        "keys_tls",
        CAMDIRECTOR_TEST_URL=tls_server.url("grpc"),
        CAMDIRECTOR_TEST_CA=str(tls_server.ca),
        CAMDIRECTOR_TEST_ADMIN_KEY=tls_server.admin_key,
        CAMDIRECTOR_TEST_VIEWER_KEY=tls_server.viewer_key,
    )


def test_game_state_bridge(server):
    """examples/game_state_bridge.mjs, started by the Node test, against `server`."""
    node_test("bridge", timeout=150.0, CAMDIRECTOR_TEST_URL=server.url("grpc"))


def test_streams_survive_a_worker_sigkill(server, tmp_path):
    """Last in this module: it kills one of `server`'s workers (SIGSTOP, 0.1 s, SIGKILL, as
    ServerProcess.kill_worker_mid_request) from the Node test, once all four streams are running."""
    frames = 300
    create = two_target_request(style=pb.Style(visibility=pb.FRAMING_ONLY), seed=5)
    updates = list(walk("", frames))
    with cd.connect(server.url("grpc")) as client:
        with client.create_session(create) as session:
            expected = [reply_json(u) for u in session.stream(updates)]
    data = {"create": _b64(create), "frames": [frame_json(u) for u in updates], "expected": expected}
    worker = server.worker_pids()[0]
    started = time.monotonic()
    output = node_test(
        "worker_kill",
        CAMDIRECTOR_TEST_URL=server.url("grpc"),
        CAMDIRECTOR_TEST_WORKER_PID=str(worker),
        CAMDIRECTOR_TEST_DATA=_write(tmp_path / "kill.json", data),
    )
    assert server.alive() and worker not in server.worker_pids()
    print(f"worker kill under 4 TypeScript streams: {time.monotonic() - started:.1f} s\n{output[-1500:]}")


@pytest.fixture(scope="module")
def cluster(built, tmp_path_factory):
    """Redis, PostgreSQL, two nodes and HAProxy (deploy/cluster.py), keys and TLS on every hop."""
    from camdirector.deploy.cluster import Cluster
    from tests.conftest import service_or_skip

    started = service_or_skip(lambda: Cluster.up(2, tmp_path_factory.mktemp("ts-cluster")))
    yield started
    started.down()


def _paced(updates: list, rate_hz: float):
    """The updates, one every 1 / rate_hz s."""
    for update in updates:
        yield update
        time.sleep(1.0 / rate_hz)


def test_streams_survive_a_node_sigkill(cluster, tmp_path, monkeypatch):
    """Eight TypeScript streams through the balancer; once they run, the node holding the most of
    them is SIGKILLed (the Node test waits for it, then checks every answer against an undisturbed
    run of the Python SDK through the same balancer, and prints the worst stall)."""
    from tests.deploy.conftest import make_key, sessions_by_node

    monkeypatch.delenv(wire.KEY_ENV, raising=False)
    engine = make_key(cluster, "engine")["key"]
    url, options = f"grpcs://{cluster.grpc}", {"key": engine, "caFile": str(cluster.ca_file)}
    create = two_target_request(style=pb.Style(visibility=pb.FRAMING_ONLY), seed=6)
    updates = list(walk("", 300))
    with cd.connect(url, key=engine, ca_file=cluster.ca_file) as client:
        with client.create_session(create) as session:
            # paced under the engine key's 240 frames a second: sent unpaced, a server that answers
            # faster than that refuses the rest (RESOURCE_EXHAUSTED), as it should
            expected = [reply_json(u) for u in session.stream(_paced(updates, 200.0))]
    data = {"create": _b64(create), "frames": [frame_json(u) for u in updates], "expected": expected}
    ready, killed = tmp_path / "ready.json", tmp_path / "killed.json"
    env = {
        **os.environ,
        "CAMDIRECTOR_TEST_URL": url,
        "CAMDIRECTOR_TEST_CONNECT": json.dumps(options),
        "CAMDIRECTOR_TEST_DATA": _write(tmp_path / "node_kill.json", data),
        "CAMDIRECTOR_TEST_READY": str(ready),
        "CAMDIRECTOR_TEST_KILLED": str(killed),
    }
    node = subprocess.Popen(
        ["node", "--test", "--test-reporter=spec", "test/node_kill.test.mjs"],
        cwd=PACKAGE,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        deadline = time.monotonic() + 90
        while not ready.is_file() and node.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert ready.is_file(), f"the streams never got going\n{node.communicate(timeout=30)[0][-4000:]}"
        ours = set(json.loads(ready.read_text()))
        held = sessions_by_node(cluster)
        counts = [len(held[n.node_id] & ours) for n in cluster.nodes]
        victim = max(range(len(counts)), key=counts.__getitem__)
        cluster.kill_node(victim)
        killed.write_text(json.dumps({"node": cluster.nodes[victim].node_id, "sessions_on_killed": counts[victim]}))
        output, _ = node.communicate(timeout=150)
    finally:
        if node.poll() is None:
            node.kill()
            node.wait()
    assert node.returncode == 0, output[-6000:]
    print(f"node kill under 8 TypeScript streams ({counts} sessions per node)\n{output[-1500:]}")
