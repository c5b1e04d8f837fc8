"""A node that loses a worker, or restarts, loses no session (issue 15's first "done when"): real
server processes, the Python SDK's streams, SIGKILL. Every answer is compared with a session
table that ran the same inputs undisturbed (checkpoints off)."""

from __future__ import annotations

import os
import signal
import threading
import time

import camdirector_client as cd
from camdirector.deploy.server_process import ServerProcess
from camdirector.deploy.services import free_port
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.table import SessionTable
from tests.service.wire_client import two_target_request, walk

FRAMES = 240  # 4 s at 60 Hz


def _undisturbed(tmp_path, create: pb.CreateSessionRequest, updates: list[pb.FrameUpdate]) -> list[pb.CameraPose]:
    table = SessionTable(ServerSettings(data_dir=str(tmp_path / "ref"), checkpoint_store="off"))
    table.create("ref", create)
    poses = []
    for update in updates:
        update = pb.FrameUpdate(session_id="ref", frame=update.frame, time_s=update.time_s, states=update.states)
        poses.append(table.frame(update).pose)
    return poses


def _paced(updates, started: threading.Event):
    start = time.perf_counter()
    for i, update in enumerate(updates):
        delay = start + i / 60.0 - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        if i == 30:
            started.set()
        yield update


def test_a_killed_worker_loses_none_of_16_streaming_sessions(server_factory, tmp_path):
    server = server_factory("--workers", "2", "--checkpoint-every-frames", "60")
    create = two_target_request(style=pb.Style(visibility=pb.FRAMING_ONLY), seed=5)
    client = cd.connect(server.url("grpc"))
    sessions = [client.create_session(create) for _ in range(16)]
    results: dict[str, list] = {}
    started = [threading.Event() for _ in sessions]

    def run(session, ready):
        updates = list(walk(session.id, FRAMES))
        answers, times = [], []
        for answer in session.stream(_paced(updates, ready)):
            answers.append(answer)
            times.append(time.monotonic())
        results[session.id] = (answers, times)

    threads = [threading.Thread(target=run, args=(s, e)) for s, e in zip(sessions, started)]
    for thread in threads:
        thread.start()
    for event in started:
        assert event.wait(30)
    victim = server.worker_pids()[0]
    os.kill(victim, signal.SIGKILL)
    killed_at = time.monotonic()
    for thread in threads:
        thread.join(120)
    expected = _undisturbed(tmp_path, create, list(walk("ref", FRAMES)))
    gaps = []
    for session in sessions:
        answers, times = results[session.id]
        assert [a.frame for a in answers] == list(range(1, FRAMES + 1)), session.id  # none lost, in order
        assert [a.pose for a in answers] == expected, session.id  # bit for bit, restored or not
        assert session.retries <= 1, session.id  # at most one UNAVAILABLE per stream
        after = [t for t in times if t > killed_at]
        before = [t for t in times if t <= killed_at]
        gaps.append(after[0] - before[-1])
    print(f"recovery gaps s: max {max(gaps):.3f}, sessions retried {sum(s.retries for s in sessions)}")  # not asserted
    assert victim not in server.worker_pids() and server.alive()
    for session in sessions:
        assert session.close() == FRAMES
    client.close()


def test_a_session_goes_on_after_its_server_restarts_on_the_same_data(tmp_path):
    port, data_dir = free_port(), tmp_path / "data"
    create = two_target_request(style=pb.Style(visibility=pb.RAYCAST), seed=9)
    updates = list(walk("x", 150))
    first = ServerProcess("--workers", "1", "--grpc", f"127.0.0.1:{port}", "--data-dir", str(data_dir))
    client = cd.connect(f"grpc://127.0.0.1:{port}")
    session = client.create_session(create)
    answers = [session.send(pb.FrameUpdate(frame=u.frame, time_s=u.time_s, states=u.states)) for u in updates[:100]]
    assert first.stop() == 0
    second = ServerProcess("--workers", "1", "--grpc", f"127.0.0.1:{port}", "--data-dir", str(data_dir))
    try:
        answers += [session.send(pb.FrameUpdate(frame=u.frame, time_s=u.time_s, states=u.states)) for u in updates[100:]]
        assert [a.pose for a in answers] == _undisturbed(tmp_path, create, updates)
        assert session.close() == 150
    finally:
        client.close()
        second.stop()


def test_a_node_whose_checkpoint_store_is_down_refuses_to_start(tmp_path):
    import subprocess
    import sys

    port = free_port()  # nothing listens there
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "camdirector.__main__",
            "serve",
            "--grpc",
            "127.0.0.1:0",
            "--zmq",
            "",
            "--http",
            "",
            "--data-dir",
            str(tmp_path),
            "--checkpoint-store",
            f"redis://127.0.0.1:{port}/0",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and "checkpoint store" in done.stderr and str(port) in done.stderr, done.stderr
