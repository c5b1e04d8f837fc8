"""Every kind of bad input gets a status with a message, over both transports, and loses nothing:
the server keeps running and a healthy session beside the bad ones keeps its exact framing."""

from __future__ import annotations

import math
import re
import struct
import time

import grpc
import pytest

from camdirector.v1 import director_pb2 as pb
from tests.service.wire_client import GrpcRaw, RpcFailed, ZmqRaw, two_target_request, walk


@pytest.fixture
def canary(server):
    """A healthy session streamed before and after each bad-input test; it must not notice."""
    client = GrpcRaw(server.grpc)
    session_id = client.call("CreateSession", two_target_request(seed=5)).session_id
    before = client.stream(list(walk(session_id, 20)))
    yield
    after = client.stream(list(walk(session_id, 20, start_frame=21)))
    assert server.alive()
    assert [u.frame for u in before + after] == list(range(1, 41)) and not any(u.stale for u in after)
    client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    client.close()


def expect(code: grpc.StatusCode, fn, *args, contains: str = ""):
    with pytest.raises(RpcFailed) as err:
        fn(*args)
    assert err.value.code == code, err.value
    assert contains.lower() in err.value.message.lower(), err.value.message
    return err.value


def test_nan_and_infinite_transforms(raw, canary):
    bad = two_target_request()
    bad.targets[0].transform.position.x = math.nan
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "CreateSession", bad, contains="targets[0].transform.position")
    bad = two_target_request()
    bad.objects[0].transform.rotation.CopyFrom(pb.Quat(x=math.inf, w=1))
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "CreateSession", bad, contains="objects[0].transform.rotation")
    session_id = raw.call("CreateSession", two_target_request()).session_id
    frame = list(walk(session_id, 1))[0]
    frame.states[0].transform.position.y = math.inf
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "Frame", frame, contains="NaN or infinite")
    frame = list(walk(session_id, 1))[0]
    frame.time_s = math.nan
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "Frame", frame, contains="time_s")
    packed = pb.FrameUpdate(
        session_id=session_id, frame=1, time_s=0.0, packed_ids=["a"], packed_transforms=[0, 0, math.nan, 0, 0, 0, 1, 1, 1, 1]
    )
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "Frame", packed, contains="NaN")
    # the session survived its bad frames
    assert raw.call("Frame", list(walk(session_id, 1))[0]).frame == 1


def test_zero_length_quaternion_and_zero_scale(raw, canary):
    bad = two_target_request()
    bad.targets[1].transform.rotation.CopyFrom(pb.Quat(x=0, y=0, z=0, w=0))
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "CreateSession", bad, contains="zero-length quaternion")
    session_id = raw.call("CreateSession", two_target_request()).session_id
    frame = pb.FrameUpdate(
        session_id=session_id, frame=1, time_s=0.0, states=[pb.ObjectState(id="a", transform=pb.Transform(rotation=pb.Quat()))]
    )
    # an all-zero Quat message that is set (not absent) is a zero-length quaternion
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "Frame", frame, contains="zero-length quaternion")
    frame = pb.FrameUpdate(
        session_id=session_id,
        frame=1,
        time_s=0.0,
        states=[pb.ObjectState(id="a", transform=pb.Transform(scale=pb.Vec3(x=1, y=0, z=1)))],
    )
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "Frame", frame, contains="scale")


def test_unknown_ids(raw, canary):
    expect(grpc.StatusCode.NOT_FOUND, raw.call, "Frame", list(walk("no-such-session", 1))[0], contains="no-such-session")
    expect(grpc.StatusCode.NOT_FOUND, raw.call, "UpdateStyle", pb.UpdateStyleRequest(session_id="nope"), contains="nope")
    expect(grpc.StatusCode.NOT_FOUND, raw.call, "CloseSession", pb.CloseSessionRequest(session_id="nope"))
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "Frame", pb.FrameUpdate(frame=1), contains="session_id is empty")
    session_id = raw.call("CreateSession", two_target_request()).session_id
    frame = pb.FrameUpdate(
        session_id=session_id, frame=1, time_s=0.0, states=[pb.ObjectState(id="ghost", transform=pb.Transform())]
    )
    expect(grpc.StatusCode.NOT_FOUND, raw.call, "Frame", frame, contains="ghost")
    frame = pb.FrameUpdate(
        session_id=session_id, frame=1, time_s=0.0, states=[pb.ObjectState(id="pillar", transform=pb.Transform())]
    )
    expect(grpc.StatusCode.FAILED_PRECONDITION, raw.call, "Frame", frame, contains="static")
    dup = two_target_request()
    dup.objects[1].id = "a"
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "CreateSession", dup, contains="used twice")
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "CreateSession", pb.CreateSessionRequest(), contains="one or two targets")


def test_bad_meshes(raw, canary):
    def with_mesh(mesh: pb.Mesh) -> pb.CreateSessionRequest:
        request = two_target_request()
        request.objects[0].mesh.CopyFrom(mesh)
        return request

    cases = [
        (pb.Mesh(), "is empty"),
        (pb.Mesh(triangles=pb.TriangleMesh(vertices=[0, 0, 0, 1, 1, 1, 2, 2, 2], indices=[0, 1, 2])), "degenerate"),
        (pb.Mesh(triangles=pb.TriangleMesh(vertices=[0, 0, 0, 1, 0, 0, 0, 1, 0], indices=[0, 1, 5])), "out of range"),
        (pb.Mesh(triangles=pb.TriangleMesh(vertices=[0, 0, 0, 1, 0], indices=[0, 1, 2])), "multiple of 3"),
        (pb.Mesh(triangles=pb.TriangleMesh(vertices=[], indices=[])), "empty"),
        (pb.Mesh(glb=b"glTF" + struct.pack("<II", 2, 9999) + b"\x00" * 20), "glb"),
        (pb.Mesh(glb=b"not a gltf at all"), "magic"),
        (pb.Mesh(obj=b"\x00\xff this is not an obj file"), "obj"),
        (pb.Mesh(primitive=pb.Primitive(sphere=pb.Primitive.Sphere(radius=-1))), "radius"),
        (pb.Mesh(primitive=pb.Primitive()), "no shape"),
    ]
    for mesh, message in cases:
        expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "CreateSession", with_mesh(mesh), contains=message)


def test_mesh_and_message_over_the_limits(raw, canary):
    # the shared server allows 200,000 triangles per scene and 4 MiB per message
    big = two_target_request()  # one triangle repeated: small on the wire, 200,001 triangles in the scene
    big.objects[0].mesh.CopyFrom(
        pb.Mesh(triangles=pb.TriangleMesh(vertices=[0, 0, 0, 1, 0, 0, 0, 1, 0], indices=[0, 1, 2] * 200_001))
    )
    expect(grpc.StatusCode.RESOURCE_EXHAUSTED, raw.call, "CreateSession", big, contains="200000 triangles")
    huge = two_target_request()  # over the limit, within what ZeroMQ still answers (zmq_service.ENVELOPE_SLACK_BYTES)
    huge.objects[0].mesh.CopyFrom(pb.Mesh(obj=b"#" * (4 * 1024 * 1024 + 16 * 1024)))
    err = expect(grpc.StatusCode.RESOURCE_EXHAUSTED, raw.call, "CreateSession", huge)
    assert "larger than max" in err.message or "exceeds the limit" in err.message


def test_screen_points_and_lens_out_of_range(raw, canary):
    for style, message in [
        (pb.Style(screen_a=pb.ScreenPoint(x=1.5)), "screen_a"),
        (pb.Style(screen_a=pb.ScreenPoint(x=0.1), screen_b=pb.ScreenPoint(x=0.1)), "differ"),
        (pb.Style(gaze_room_m=-1), "gaze_room_m"),
        (pb.Style(visibility=42), "not a VisibilityMode"),
        (pb.Style(map_resolution=8), "map_resolution"),
        (pb.Style(mask=9), "style.mask"),
    ]:
        expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "CreateSession", two_target_request(style=style), contains=message)
    expect(
        grpc.StatusCode.INVALID_ARGUMENT,
        raw.call,
        "CreateSession",
        two_target_request(lens=pb.Lens(vertical_fov_deg=179)),
        contains="vertical_fov_deg",
    )
    session_id = raw.call("CreateSession", two_target_request()).session_id
    expect(
        grpc.StatusCode.INVALID_ARGUMENT,
        raw.call,
        "UpdateStyle",
        pb.UpdateStyleRequest(session_id=session_id, style=pb.Style(max_speed_m_s=0)),
        contains="max_speed_m_s",
    )


def test_packed_states_of_the_wrong_length(raw, canary):
    session_id = raw.call("CreateSession", two_target_request()).session_id
    frame = pb.FrameUpdate(session_id=session_id, frame=1, time_s=0.0, packed_ids=["a", "b"], packed_transforms=[0.0] * 13)
    expect(grpc.StatusCode.INVALID_ARGUMENT, raw.call, "Frame", frame, contains="10 per packed id")


def test_more_sessions_than_allowed(server_factory):
    srv = server_factory("--workers", "0", "--max-sessions", "2")
    for client in (GrpcRaw(srv.grpc), ZmqRaw(srv.zmq)):
        ids = [client.call("CreateSession", two_target_request()).session_id for _ in range(2)]
        expect(
            grpc.StatusCode.RESOURCE_EXHAUSTED,
            client.call,
            "CreateSession",
            two_target_request(),
            contains="maximum of 2 sessions",
        )
        for session_id in ids:
            client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        client.close()
    assert srv.alive()


def test_garbage_on_the_zeromq_socket(server, canary):
    client = ZmqRaw(server.zmq)
    code, message = client.send_raw([b"Frame"])
    assert code == b"3" and b"expected 3 frames (RPC name, payload, key)" in message
    code, message = client.send_raw([b"Frame", b"x", b"y", b"z"])
    assert code == b"3"
    code, message = client.send_raw([b"Explode", b""])
    assert code == b"12" and b"unknown RPC" in message
    code, message = client.send_raw([b"Frame", b"\xff\xff\xff\xff garbage"])
    assert code == b"3" and b"FrameUpdate" in message
    code, message = client.send_raw([b"CreateSession", b"\x0a\xff"])
    assert code == b"3" and b"CreateSessionRequest" in message
    code, message = client.send_raw([b"CloseSession", b"#" * (4 * 1024 * 1024 + 16 * 1024)])
    assert code == b"8" and b"exceeds the limit" in message
    client.close()


def test_a_stream_carries_one_session(server, canary):
    client = GrpcRaw(server.grpc)
    first = client.call("CreateSession", two_target_request()).session_id
    second = client.call("CreateSession", two_target_request()).session_id
    frames = list(walk(first, 3)) + list(walk(second, 1, start_frame=4))
    expect(grpc.StatusCode.INVALID_ARGUMENT, client.stream, frames, contains="a stream carries one session")
    client.close()


def test_client_disconnect_mid_stream_then_resume(server, canary):
    """The stream dies with its client; the session waits for a new stream and goes on."""
    client = GrpcRaw(server.grpc)
    session_id = client.call("CreateSession", two_target_request(seed=9)).session_id
    call = client.stub.StreamFrames(iter(list(walk(session_id, 50))))
    for i, _update in enumerate(call):
        if i == 9:
            call.cancel()  # the client goes away mid-stream
            break
    client.close()
    resumed = GrpcRaw(server.grpc)
    updates = resumed.stream(list(walk(session_id, 20, start_frame=51)))
    assert [u.frame for u in updates] == list(range(51, 71)) and not updates[0].cut
    resumed.close()


def test_abandoned_session_is_reclaimed_after_the_resume_window(server_factory):
    srv = server_factory("--workers", "1", "--session-resume-s", "0.5", env={"CAMDIRECTOR_REAP_INTERVAL_S": "0.1"})
    client = GrpcRaw(srv.grpc)
    session_id = client.call("CreateSession", two_target_request()).session_id
    client.stream(list(walk(session_id, 5)))
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            client.call("Frame", list(walk(session_id, 1, start_frame=6))[0])
        except RpcFailed as exc:
            assert exc.code == grpc.StatusCode.NOT_FOUND
            break
        time.sleep(0.7)  # longer than the resume window, so the next try finds it gone
    else:
        pytest.fail("session was never reclaimed")
    import urllib.request

    text = urllib.request.urlopen(f"http://{srv.http}/metrics").read().decode()
    assert "camdirector_sessions_reclaimed_total 1.0" in text
    client.close()


def test_without_checkpoints_a_dead_worker_is_replaced(server_factory):
    """With checkpoints off, a worker killed by the OS loses its sessions, which then answer
    UNAVAILABLE saying so, over both transports; new sessions work again (with checkpoints, the
    default, they are restored: tests/service/test_failover.py)."""
    import os
    import signal

    srv = server_factory("--workers", "1", "--checkpoint-store", "off")
    client, zmq_client = GrpcRaw(srv.grpc), ZmqRaw(srv.zmq)
    session_id = client.call("CreateSession", two_target_request()).session_id
    workers = srv.worker_pids()
    assert workers
    os.kill(workers[0], signal.SIGKILL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            client.call("Frame", list(walk(session_id, 1))[0])
        except RpcFailed as exc:
            assert exc.code == grpc.StatusCode.UNAVAILABLE, exc  # never "unknown session id"
            if "worker process holding it" in exc.message:
                break
        time.sleep(0.2)
    else:
        pytest.fail("the killed worker's session still answers")
    expect(grpc.StatusCode.UNAVAILABLE, zmq_client.call, "Frame", list(walk(session_id, 1, start_frame=2))[0], contains="died")
    expect(
        grpc.StatusCode.UNAVAILABLE, client.call, "CloseSession", pb.CloseSessionRequest(session_id=session_id), contains="died"
    )
    expect(grpc.StatusCode.NOT_FOUND, client.call, "Frame", list(walk("never-made", 1))[0], contains="unknown")
    fresh = client.call("CreateSession", two_target_request()).session_id
    assert client.stream(list(walk(fresh, 5)))[-1].frame == 5
    assert srv.alive()
    client.close()
    zmq_client.close()


def test_an_unexpected_failure_is_internal_on_both_transports(server_factory, tmp_path):
    """A failure the server did not foresee (a real one: its recordings folder cannot be made, a
    file has its name) answers INTERNAL with a short message naming the session, over gRPC and
    ZeroMQ alike (gRPC alone would say UNKNOWN); the session id and the traceback are in the
    server's log, no half-made session is left, and the server keeps serving."""
    data_dir = tmp_path / "data"
    data_dir.mkdir()
    (data_dir / "recordings").write_text("a file where the recordings folder should be")
    srv = server_factory("--workers", "1", "--data-dir", str(data_dir))
    client, zmq_client = GrpcRaw(srv.grpc), ZmqRaw(srv.zmq)
    request = two_target_request()
    request.record = True
    for transport in (client, zmq_client):
        message = expect(
            grpc.StatusCode.INTERNAL,
            transport.call,
            "CreateSession",
            request,
            contains="internal error (FileExistsError) in create of session",
        ).message
        assert "Traceback" not in message and str(data_dir) not in message  # details stay in the log
        session_id = re.search(r"of session (\w+)", message).group(1)
        log = srv.log_tail(1_000_000)
        assert f"create of session {session_id} failed" in log and "Traceback" in log, log[-2000:]
    fresh = client.call("CreateSession", two_target_request()).session_id
    assert client.stream(list(walk(fresh, 3)))[-1].frame == 3
    assert zmq_client.call("CloseSession", pb.CloseSessionRequest(session_id=fresh)).frames == 3
    assert srv.alive()
    client.close()
    zmq_client.close()


def test_session_id_given_twice_is_refused(server, canary):
    """The front routes by the first session_id it reads; a message whose parsed session_id (the
    last one) differs is refused, never run on another session. Raw bytes over both transports."""
    client = GrpcRaw(server.grpc)
    first = client.call("CreateSession", two_target_request(seed=2)).session_id
    second = client.call("CreateSession", two_target_request(seed=3)).session_id
    frame = list(walk(first, 1))[0].SerializeToString() + pb.FrameUpdate(session_id=second).SerializeToString()
    raw_frame = client.channel.unary_unary("/camdirector.v1.Director/Frame")  # bytes in, bytes out
    with pytest.raises(grpc.RpcError) as err:
        raw_frame(frame, timeout=30)
    assert err.value.code() == grpc.StatusCode.INVALID_ARGUMENT and "more than once" in err.value.details()
    zmq_client = ZmqRaw(server.zmq)
    code, body = zmq_client.send_raw([b"Frame", frame])
    assert code == b"3" and b"more than once" in body, (code, body)
    for session_id in (first, second):  # neither was advanced
        assert client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id)).frames == 0
    client.close()
    zmq_client.close()
