"""The C/C++ SDK's I/O thread recovering in the background while a 60 Hz loop streams: a dropped
connection resumes the same session; so do a server restarted on the same data directory and a
worker killed mid-stream, the server restoring the session from its checkpoint
(worker/checkpointing.py), and a server hung (stopped) for longer than the frame timeout; a
session that expired meanwhile, or one lost by a server
without checkpoints (`--checkpoint-store off`: a restart, a dead worker), gets the session
created again (new id, reported as an event)."""

from __future__ import annotations

import time

from tests.client_sdk.cpp.conftest import StreamRun, free_port
from tests.client_sdk.test_retry import _stopped


def _kinds(report: dict) -> list[str]:
    return [e["kind"] for e in report["events"]]


def _assert_streamed_on(report: dict) -> None:
    assert report["seen"], report
    assert report["answered_after"] >= 60, report  # went on streaming after recovering
    assert report["refused"] == 0  # submits never failed meanwhile: frames waited in the queue
    assert report["game_thread_allocations"] == 0
    assert report["close"] == "OK"


def test_a_dropped_connection_resumes_the_same_session(sdk_bin, server, proxy_to):
    proxy = proxy_to(server.grpc)
    run = StreamRun(sdk_bin / "sdk_check", proxy.address, "resumed")
    ready = run.wait_ready()
    proxy.cut(refuse_s=0.3)
    report = run.report()
    _assert_streamed_on(report)
    assert report["first_session_id"] == ready["session_id"] == report["last_session_id"]
    assert _kinds(report)[:3] == ["STREAMING", "DISCONNECTED", "RESUMED"], report["events"]
    assert report["stats"]["resumes"] >= 1 and report["stats"]["recreations"] == 0
    assert report["last_pose_generation"] == 1
    assert proxy.accepted >= 2  # a second connection carried the resumed stream


def test_a_session_expired_while_disconnected_is_created_again(sdk_bin, server_factory, proxy_to):
    srv = server_factory("--workers", "1", "--session-resume-s", "0.5")
    proxy = proxy_to(srv.grpc)
    run = StreamRun(sdk_bin / "sdk_check", proxy.address, "recreated")
    ready = run.wait_ready()
    proxy.cut(refuse_s=3.0)  # longer than the resume window plus the server's reap interval
    report = run.report()
    _assert_streamed_on(report)
    assert report["last_session_id"] != ready["session_id"]
    kinds = _kinds(report)
    assert kinds[:2] == ["STREAMING", "DISCONNECTED"] and "RECREATED" in kinds, report["events"]
    recreated = report["events"][kinds.index("RECREATED")]
    assert recreated["session_id"] == report["last_session_id"] and recreated["generation"] == 2
    assert ready["session_id"] in recreated["message"]
    assert report["stats"]["recreations"] == 1 and report["last_pose_generation"] == 2


def _assert_same_session(report: dict, ready: dict) -> None:
    """The session went on under its first id, restored by the server, never created again."""
    _assert_streamed_on(report)
    assert report["first_session_id"] == ready["session_id"] == report["last_session_id"], report
    kinds = _kinds(report)
    assert kinds == ["STREAMING", "DISCONNECTED", "RESUMED"], report["events"]
    stats = report["stats"]
    assert stats["recreations"] == 0 and stats["disconnects"] == 1 and stats["resumes"] == 1, stats
    assert report["last_pose_generation"] == 1
    # The server's count of the session's frames includes those before the loss: the same session.
    assert stats["frames_answered"] - stats["frames_stale"] <= report["server_frames"] <= stats["frames_sent"], report


def test_a_server_restarted_mid_stream_restores_the_same_session(sdk_bin, server_factory, tmp_path):
    address = f"127.0.0.1:{free_port()}"
    data_dir = str(tmp_path / "data")  # the checkpoints' folder, kept across the restart
    first = server_factory("--workers", "1", "--grpc", address, "--data-dir", data_dir)
    run = StreamRun(sdk_bin / "sdk_check", address, "resumed")
    ready = run.wait_ready()
    first.proc.terminate()  # SIGTERM: the server stops (its streams end) and keeps the checkpoints
    assert first.proc.wait(15) == 0
    second = server_factory("--workers", "1", "--grpc", address, "--data-dir", data_dir)
    assert second.grpc == address
    report = run.report()
    _assert_same_session(report, ready)
    # Retries against the stopped server waited for a connection instead of spending queued frames.
    assert report["stats"]["frames_lost"] <= 4 and report["stats"]["streams_opened"] == 2, report["stats"]


def test_a_worker_killed_mid_stream_costs_one_disconnect_and_keeps_the_session(sdk_bin, server_factory):
    # One worker: the session is on it, and its successor restores the session (with several, one
    # of the others would; which one holds the session is not told outside the server).
    srv = server_factory("--workers", "1")
    run = StreamRun(sdk_bin / "sdk_check", srv.grpc, "resumed")
    ready = run.wait_ready()
    srv.kill_worker_mid_request()
    report = run.report()
    _assert_same_session(report, ready)
    # One UNAVAILABLE ended the first stream; the second, held while the session was restored, went on.
    assert report["stats"]["streams_opened"] == 2 and report["stats"]["last_stream_status"] == "UNAVAILABLE"
    assert report["events"][1]["status"] == "UNAVAILABLE", report["events"]


def test_a_worker_killed_without_checkpoints_gets_the_session_created_again(sdk_bin, server_factory):
    srv = server_factory("--workers", "1", "--checkpoint-store", "off")
    run = StreamRun(sdk_bin / "sdk_check", srv.grpc, "recreated")
    ready = run.wait_ready()
    srv.kill_worker_mid_request()
    report = run.report()
    _assert_streamed_on(report)
    assert report["last_session_id"] != ready["session_id"]
    kinds = _kinds(report)
    assert kinds[:2] == ["STREAMING", "DISCONNECTED"] and "RECREATED" in kinds, report["events"]
    assert report["stats"]["recreations"] == 1 and report["last_pose_generation"] == 2


def test_a_server_killed_and_restarted_without_checkpoints_gets_the_session_again(sdk_bin, server_factory):
    port = free_port()
    address = f"127.0.0.1:{port}"
    first = server_factory("--workers", "1", "--grpc", address, "--checkpoint-store", "off")
    run = StreamRun(sdk_bin / "sdk_check", address, "recreated")
    ready = run.wait_ready()
    first.proc.kill()  # a crash: no goodbye to the stream
    first.proc.wait(15)
    time.sleep(0.5)  # the SDK notices and retries against nothing for a while
    second = server_factory("--workers", "1", "--grpc", address, "--checkpoint-store", "off")
    assert second.grpc == address
    report = run.report()
    _assert_streamed_on(report)
    assert report["last_session_id"] != ready["session_id"]
    kinds = _kinds(report)
    assert kinds[:2] == ["STREAMING", "DISCONNECTED"] and "RECREATED" in kinds, report["events"]
    assert report["stats"]["recreations"] == 1 and report["stats"]["disconnects"] == 1
    # Retries against the dead server waited for a connection instead of spending queued frames.
    assert report["stats"]["frames_lost"] <= 4, report["stats"]


def test_a_server_hung_mid_stream_resumes_the_same_session(sdk_bin, server_factory):
    """A real server and its worker stopped (SIGSTOP) for 4 s, longer than the 3 s frame timeout:
    the I/O thread takes the node as hung (the frame timeout, or the channel's keepalive pings
    first), waits for the server without spending queued frames, and resumes the same session
    once it wakes; no frame is answered twice to the game."""
    srv = server_factory("--workers", "1")
    run = StreamRun(sdk_bin / "sdk_check", srv.grpc, "resumed")
    ready = run.wait_ready()
    _stopped(srv, 4.0)
    report = run.report()
    _assert_same_session(report, ready)
    disconnected = report["events"][1]
    # seen first by the keepalive pings (1 s, 1 s to answer): "keepalive watchdog timeout"
    assert disconnected["status"] == "UNAVAILABLE", disconnected
