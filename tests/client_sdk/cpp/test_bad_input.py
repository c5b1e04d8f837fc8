"""The C/C++ SDK given bad input: an address that does not parse, a server that is down, NaN in a
transform, frames out of order, and frames submitted faster than the server answers. The game
thread's calls must answer at once and allocate nothing (sdk_check counts malloc calls)."""

from __future__ import annotations

import socket

import pytest

from tests.client_sdk.cpp.conftest import free_port, run_json


@pytest.mark.parametrize(
    "address, reason",
    [
        ("", "empty"),
        ("127.0.0.1", "no port"),
        ("127.0.0.1:", "port"),
        ("127.0.0.1:99999", "port"),
        ("127.0.0.1:http", "port"),
        (":50051", "no host"),
        ("::1:50051", "brackets"),
        ("tcp://127.0.0.1:5555", "ZeroMQ"),
        ("host name:50051", "space"),
        ("host/x:50051", "host"),
    ],
)
def test_an_unparseable_address_is_refused_at_creation(sdk_bin, address, reason):
    report = run_json(sdk_bin / "sdk_check", "address", address)
    assert report["status"] == "INVALID_ARGUMENT" and report["create_status"] == "INVALID_ARGUMENT"
    assert report["client_is_null"] is True
    assert reason in report["reason"], report


@pytest.mark.parametrize("address", ["127.0.0.1:50051", "grpc://localhost:1", "[::1]:50051", "unix:/tmp/x.sock"])
def test_a_good_address_makes_a_client_without_connecting(sdk_bin, address):
    report = run_json(sdk_bin / "sdk_check", "address", address)
    assert report["status"] == "OK" and report["create_status"] == "OK" and report["client_is_null"] is False


def test_a_server_that_is_down_fails_create_within_its_deadline(sdk_bin):
    report = run_json(sdk_bin / "sdk_check", "down", f"127.0.0.1:{free_port()}")
    fail_fast, waiting = report["fail_fast"], report["wait_for_server"]
    # Refused connection: UNAVAILABLE at once, saying so.
    assert fail_fast["open_status"] == "UNAVAILABLE", fail_fast
    assert "CreateSession" in fail_fast["message"] and "connect" in fail_fast["message"].lower()
    assert fail_fast["elapsed_s"] < fail_fast["timeout_s"]
    # wait_for_server = 1: waits for the server until the deadline, no longer.
    assert waiting["open_status"] == "DEADLINE_EXCEEDED" and "not reachable" in waiting["message"], waiting
    assert waiting["timeout_s"] - 0.1 <= waiting["elapsed_s"] < waiting["timeout_s"] + 5.0
    for case in (fail_fast, waiting):
        # Meanwhile the game thread's calls answer at once: no session yet, no pose yet.
        assert case["submit_status"] == "FAILED_PRECONDITION" and case["poll_status"] == "NOT_FOUND"
        assert case["game_thread_allocations"] == 0
    assert report["alloc_counter"] is True  # the malloc counter was live


def test_nan_and_disordered_frames_are_refused_at_submit(sdk_bin, server):
    report = run_json(sdk_bin / "sdk_check", "nan", server.grpc)
    submits = report["submits"]
    for case in ("nan_position", "inf_rotation", "nan_scale", "nan_time", "unknown_slot"):
        assert submits[case] == "INVALID_ARGUMENT", (case, submits)
    assert submits["repeated_frame"] == "OUT_OF_RANGE" and submits["time_back"] == "OUT_OF_RANGE"
    assert [submits[g] for g in ("good_1", "good_2", "good_3")] == ["OK"] * 3
    assert report["game_thread_allocations"] == 0
    stats = report["stats"]
    # Nothing refused reached the server: the stream never broke and all good frames were answered.
    assert stats["frames_refused"] == 7 and stats["frames_submitted"] == 3
    assert stats["frames_answered"] == 3 and stats["streams_opened"] == 1 and stats["disconnects"] == 0
    assert report["flush"] == "OK" and report["pose_frame"] == 3 and report["pose_finite"] is True
    assert report["close"] == "OK" and report["server_frames"] == 3


def test_a_frame_the_server_refuses_ends_its_stream_but_not_the_session(sdk_bin, server):
    report = run_json(sdk_bin / "sdk_check", "refused", server.grpc)
    assert report["submits"] == ["OK", "OK", "OK"], report  # a zero scale component is the server's to refuse
    kinds = [(e["kind"], e["status"]) for e in report["events"]]
    assert kinds == [("STREAMING", "OK"), ("FRAME_REFUSED", "INVALID_ARGUMENT")], report
    assert "scale" in report["events"][1]["message"], report
    assert report["session_id_kept"] is True and report["last_pose_frame"] == 3, report
    stats = report["stats"]
    assert stats["frames_answered"] == 2 and stats["frames_lost"] == 1 and stats["streams_opened"] == 2, report
    assert stats["disconnects"] == 0 and stats["recreations"] == 0, report


def test_frames_faster_than_answered_drop_the_oldest_without_blocking(sdk_bin, server):
    report = run_json(sdk_bin / "sdk_check", "flood", server.grpc, "3000")
    stats = report["stats"]
    assert report["refused"] == 0 and stats["frames_submitted"] == 3000
    assert stats["frames_dropped"] > 0, stats  # a queue of 4, one frame in flight
    # Every frame is accounted for: sent or dropped; every sent one answered.
    assert stats["frames_sent"] + stats["frames_dropped"] == 3000
    assert stats["frames_answered"] == stats["frames_sent"] == report["server_frames"]
    # The queue keeps the newest: the last frame submitted is the last one answered.
    assert report["flush"] == "OK" and report["last_pose_frame"] == 3000
    assert report["game_thread_allocations"] == 0


def test_a_dropped_frames_updates_are_carried_into_the_next_frame(sdk_bin, server):
    """Objects not mentioned in a frame keep their last transform (docs/protocol.md), so a frame
    that the full queue drops must not take the only update of an object with it."""
    report = run_json(sdk_bin / "sdk_check", "sparse", server.grpc)
    assert report["stats"]["frames_dropped"] >= 1, report  # the I/O thread looks every 200 ms
    assert report["flush"] == "OK" and report["last_pose_frame"] == 6
    # b moved only in frame 1, which was dropped: the camera still frames it where it went.
    assert report["screen_error"] < 1e-6, report
    assert report["game_thread_allocations"] == 0


def test_pose_outputs_from_the_plain_structs_reach_a_udp_listener(sdk_bin, server):
    """cd_session_desc.pose_outputs: the no-plugin path (FreeD / OpenTrackIO datagrams)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.settimeout(10.0)
        report = run_json(sdk_bin / "sdk_check", "pose_output", server.grpc, str(listener.getsockname()[1]))
        assert report["open"] == "OK", report
        assert report["flush"] == "OK" and report["stats"]["frames_answered"] == 10
        datagram = listener.recv(2048)
    assert len(datagram) == 29 and datagram[0] == 0xD1 and datagram[1] == 9  # FreeD D1, camera id 9


def test_a_bad_pose_output_is_refused_at_create(sdk_bin, server):
    report = run_json(sdk_bin / "sdk_check", "pose_output", server.grpc, "0")
    assert report["open"] == "INVALID_ARGUMENT" and "pose_outputs[0]" in report["message"], report
