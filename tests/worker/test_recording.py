"""Recording a session on the server and replaying it bit for bit with `camdirector replay`."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

from camdirector.v1 import director_pb2 as pb
from camdirector.worker.recording import MAGIC, read_entries
from camdirector.worker.replay import replay
from tests.service.wire_client import GrpcRaw, two_target_request, walk


def _record(server) -> Path:
    client = GrpcRaw(server.grpc)
    response = client.call("CreateSession", two_target_request(seed=21, record=True))
    session_id = response.session_id
    client.stream(list(walk(session_id, 90)))
    client.call(
        "UpdateStyle",
        pb.UpdateStyleRequest(
            session_id=session_id,
            style=pb.Style(screen_a=pb.ScreenPoint(x=-0.5), screen_b=pb.ScreenPoint(x=0.2, y=0.1), response_time_s=0.2),
        ),
    )
    client.call("Frame", list(walk(session_id, 1, start_frame=50))[0])  # stale: recorded too
    client.stream(list(walk(session_id, 90, start_frame=91)))
    client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    client.close()
    return server.data_dir / "recordings" / response.recording_path


def test_recording_replays_bit_for_bit(server):
    path = _record(server)
    kinds = [e.WhichOneof("entry") for e in read_entries(path)]
    assert kinds[0] == "create" and kinds.count("frame") == 181 and kinds.count("camera") == 181
    assert kinds.count("style") == 1
    out = subprocess.run(
        [sys.executable, "-m", "camdirector.__main__", "replay", str(path)], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == {"frames": 181, "identical": 181, "first_mismatch": None, "ok": True}


def test_replay_detects_a_changed_pose_and_reads_a_cut_file(server, tmp_path):
    path = _record(server)
    entries = list(read_entries(path))
    changed = tmp_path / "changed.cdrec"
    with open(changed, "wb") as f:
        f.write(MAGIC)
        for entry in entries:
            if entry.WhichOneof("entry") == "camera" and entry.camera.frame == 40:
                entry.camera.pose.position.x += 1e-12
            data = entry.SerializeToString()
            f.write(bytes([len(data)]) if len(data) < 128 else _varint(len(data)))
            f.write(data)
    report = replay(changed)
    assert not report.ok and report.first_mismatch == 40 and report.identical == 180
    cut = tmp_path / "cut.cdrec"
    cut.write_bytes(path.read_bytes()[:-7])  # a crash mid-entry
    report = replay(cut)
    assert report.ok and report.frames == 180


def _varint(n: int) -> bytes:
    out = bytearray()
    while n >= 0x80:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


def test_replay_refuses_a_file_that_is_not_a_recording(tmp_path):
    bogus = tmp_path / "bogus.cdrec"
    bogus.write_bytes(b"hello")
    out = subprocess.run(
        [sys.executable, "-m", "camdirector.__main__", "replay", str(bogus)], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2 and "not a camdirector recording" in out.stderr


def test_a_replay_sends_no_pose_output(server):
    """A session recorded with a pose output replays bit for bit without sending one datagram to
    the recorded address (a replay answers frames again, it does not broadcast them)."""
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(2.0)
    request = two_target_request(seed=21, record=True)
    request.pose_outputs.add(format=pb.POSE_FORMAT_FREED_D1, address=f"udp://127.0.0.1:{receiver.getsockname()[1]}")
    client = GrpcRaw(server.grpc)
    response = client.call("CreateSession", request)
    client.stream(list(walk(response.session_id, 30)))
    client.call("CloseSession", pb.CloseSessionRequest(session_id=response.session_id))
    client.close()
    live = 0
    try:
        while True:
            receiver.recv(64)
            live += 1
    except TimeoutError:
        pass
    assert live == 30, "the live session sent one datagram a frame"
    result = replay(server.data_dir / "recordings" / response.recording_path)
    receiver.settimeout(1.0)
    try:
        receiver.recv(64)
        raise AssertionError("the replay sent a pose output")
    except TimeoutError:
        pass
    finally:
        receiver.close()
    assert result.ok and result.identical == 30
