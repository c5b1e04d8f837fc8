"""Pose outputs end to end (docs/protocol.md, "Pose outputs"): a real server with two workers sends
every answered pose to UDP sockets this test binds on 127.0.0.1; SMPTE's reference receiver
reassembles and decodes the OpenTrackIO datagrams and SMPTE's schema judges every sample; FreeD is
read by the spec's decoder (tests/worker/test_pose_out.py). Bad pose outputs are refused
at CreateSession with INVALID_ARGUMENT, and a destination nobody listens on stalls nothing."""

from __future__ import annotations

import math
import socket
from contextlib import closing

import grpc
import httpx
import numpy as np
import pytest

from camdirector.geometry.transforms import quat_to_matrix
from camdirector.v1 import director_pb2 as pb
from tests.service.opentrackio_ref import load_reference
from tests.service.wire_client import GrpcRaw, RpcFailed, two_target_request, walk
from tests.worker.test_pose_out import M, decode_freed, ours_from_opentrackio

FRAMES = 600  # 10 s at 60 Hz (the 600-frame session): static blocks on the first sample, then every 2 s


@pytest.fixture(scope="module")
def reference():
    return load_reference()


@pytest.fixture
def listeners():
    """UDP sockets bound on 127.0.0.1 (port 0), closed after the test."""
    opened = []

    def bind() -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(10.0)
        opened.append(sock)
        return sock

    yield bind
    for sock in opened:
        sock.close()


@pytest.fixture
def client(server):
    with closing(GrpcRaw(server.grpc)) as raw:
        yield raw


def output(fmt: int, sock_or_port, **kwargs) -> pb.PoseOutput:
    port = sock_or_port if isinstance(sock_or_port, int) else sock_or_port.getsockname()[1]
    return pb.PoseOutput(format=fmt, address=f"udp://127.0.0.1:{port}", **kwargs)


def receive(sock: socket.socket, count: int) -> list[bytes]:
    return [sock.recv(65_536) for _ in range(count)]


def rotation_of(update: pb.CameraUpdate) -> np.ndarray:
    q = update.pose.rotation
    return quat_to_matrix(np.array([q.x, q.y, q.z, q.w]))


def position_of(update: pb.CameraUpdate) -> np.ndarray:
    p = update.pose.position
    return np.array([p.x, p.y, p.z])


def test_every_answered_pose_goes_out_in_each_format(server, client, listeners, reference):
    json_sock, cbor_sock, freed_sock = listeners(), listeners(), listeners()
    request = two_target_request(
        seed=11,
        pose_outputs=[
            output(pb.POSE_FORMAT_OPENTRACKIO_JSON, json_sock, source_number=3),
            output(pb.POSE_FORMAT_OPENTRACKIO_CBOR, cbor_sock, sensor_height_mm=15.6),
            output(pb.POSE_FORMAT_FREED_D1, freed_sock, source_number=200),
        ],
    )
    session_id = client.call("CreateSession", request).session_id
    updates = client.stream(list(walk(session_id, FRAMES)))
    assert len(updates) == FRAMES and not any(u.stale for u in updates)

    for sock, sensor_mm, source_number, encoding in ((json_sock, 24.0, 3, 0x01), (cbor_sock, 15.6, 1, 0x02)):
        datagrams = receive(sock, FRAMES)  # one per sample: a sample with its static block is under the MTU
        assert all(d[5] == encoding for d in datagrams)
        assert [int.from_bytes(d[6:8], "big") for d in datagrams] == list(range(1, FRAMES + 1))
        receiver = reference.new_receiver()
        samples = [reference.feed(receiver, [d]) for d in datagrams]
        for i, (sample, update) in enumerate(zip(samples, updates)):
            assert sample is not None, f"SMPTE's receiver refused sample {i}"
            assert not reference.errors(sample), (i, reference.errors(sample))
            assert sample["sourceNumber"] == source_number and sample["timing"]["sequenceNumber"] == i
            assert sample["timing"]["mode"] == "internal" and sample["timing"]["sampleRate"] == {"num": 60, "denom": 1}
            assert ("static" in sample) == (i % 120 == 0), i  # the first, then every 2 s of the frames' time
            # SMPTE's decoder reads the camera's transform; it is our reply's pose in OpenTrackIO's axes
            receiver.protocol.pd = sample
            pan, tilt, roll = receiver.protocol.get_camera_rotations()
            np.testing.assert_allclose(ours_from_opentrackio(pan, tilt, roll), rotation_of(update), atol=1e-9)
            np.testing.assert_allclose(receiver.protocol.get_camera_translations(), M @ position_of(update), atol=1e-12)
            assert receiver.protocol.get_focal_length() == pytest.approx(
                sensor_mm / 2 / math.tan(math.radians(update.pose.vertical_fov_deg) / 2)
            )
        assert len({s["sourceId"] for s in samples}) == 1 and len({s["sampleId"] for s in samples}) == FRAMES
        assert samples[0]["static"]["camera"]["activeSensorPhysicalDimensions"]["height"] == sensor_mm

    for datagram, update in zip(receive(freed_sock, FRAMES), updates):
        decoded = decode_freed(datagram)
        assert decoded["camera_id"] == 200
        rebuilt = ours_from_opentrackio(-decoded["pan"], decoded["tilt"], decoded["roll"])  # FreeD pans the other way
        np.testing.assert_allclose(rebuilt, rotation_of(update), atol=1e-4)  # 1/32768 degree steps
        np.testing.assert_allclose(
            [decoded["x_mm"], decoded["y_mm"], decoded["z_mm"]], M @ position_of(update) * 1e3, atol=1 / 128
        )
        focal_mm = 12.0 / math.tan(math.radians(update.pose.vertical_fov_deg) / 2)
        assert decoded["zoom"] == round(focal_mm * 100) and decoded["focus"] == 0

    # The stale answer to a repeated frame sends nothing; the counts are in the session's summary.
    assert client.call("Frame", list(walk(session_id, 1, start_frame=FRAMES))[0]).stale
    detail = httpx.get(f"http://{server.http}/v1/sessions/{session_id}", params={"last": 1}, timeout=30).json()
    assert [(o["format"], o["sent"], o["dropped"]) for o in detail["pose_outputs"]] == [
        ("POSE_FORMAT_OPENTRACKIO_JSON", FRAMES, 0),
        ("POSE_FORMAT_OPENTRACKIO_CBOR", FRAMES, 0),
        ("POSE_FORMAT_FREED_D1", FRAMES, 0),
    ]
    client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))


@pytest.fixture
def canary(server):
    """A healthy session with a pose output, streamed before and after each bad-input test; it
    must not notice."""
    with closing(GrpcRaw(server.grpc)) as raw, closing(socket.socket(socket.AF_INET, socket.SOCK_DGRAM)) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(10.0)
        session_id = raw.call(
            "CreateSession", two_target_request(seed=5, pose_outputs=[output(pb.POSE_FORMAT_FREED_D1, sock)])
        ).session_id
        before = raw.stream(list(walk(session_id, 10)))
        yield
        after = raw.stream(list(walk(session_id, 10, start_frame=11)))
        assert server.alive()
        assert [u.frame for u in before + after] == list(range(1, 21)) and not any(u.stale for u in after)
        assert len(receive(sock, 20)) == 20
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))


def closed_port() -> int:
    with closing(socket.socket(socket.AF_INET, socket.SOCK_DGRAM)) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.parametrize(
    "outputs, message",
    [
        (
            [pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="tcp://127.0.0.1:40000")],
            "pose_outputs[0].address 'tcp://127.0.0.1:40000' is not udp://HOST:PORT",
        ),
        ([pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="127.0.0.1:40000")], "is not udp://HOST:PORT"),
        ([pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1")], "has no port"),
        ([pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://:40000")], "has no host"),
        ([pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:freed")], "port 'freed' is not a number"),
        ([pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:0")], "port 0 is out of range [1, 65535]"),
        ([pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:65536")], "port 65536 is out of range"),
        (
            [pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://no-such-host.invalid:40000")],
            "host 'no-such-host.invalid' does not resolve to an IPv4 address",
        ),
        ([pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://[::1]:40000")], "IPv6 is not supported"),
        ([pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:40000/x")], "more than HOST:PORT"),
        ([pb.PoseOutput(address="udp://127.0.0.1:40000")], "pose_outputs[0].format is unset"),
        ([pb.PoseOutput(format=9, address="udp://127.0.0.1:40000")], "pose_outputs[0].format 9 is not a PoseFormat"),
        (
            [pb.PoseOutput(format=pb.POSE_FORMAT_OPENTRACKIO_JSON, address="udp://127.0.0.1:40000", sensor_height_mm=-24)],
            "pose_outputs[0].sensor_height_mm must be in [1, 100] mm (0 means 24), got -24",
        ),
        (
            [pb.PoseOutput(format=pb.POSE_FORMAT_OPENTRACKIO_JSON, address="udp://127.0.0.1:40000", sensor_height_mm=1e6)],
            "sensor_height_mm must be in [1, 100] mm",
        ),
        (
            [pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:40000", sensor_height_mm=math.nan)],
            "sensor_height_mm must be in [1, 100] mm",
        ),
        (
            [pb.PoseOutput(format=pb.POSE_FORMAT_OPENTRACKIO_CBOR, address="udp://127.0.0.1:40000", source_number=201)],
            "pose_outputs[0].source_number must be in [1, 200] for POSE_FORMAT_OPENTRACKIO_CBOR",
        ),
        (
            [pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:40000", source_number=256)],
            "source_number must be in [1, 255] for POSE_FORMAT_FREED_D1",
        ),
        (
            [pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:40000")] * 9,
            "a session has at most 8 pose_outputs, got 9",
        ),
        (
            [
                pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:40000"),
                pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://127.0.0.1:99999"),
            ],
            "pose_outputs[1].address",
        ),
    ],
    ids=lambda v: v if isinstance(v, str) else None,
)
def test_bad_pose_outputs_are_refused_at_create(raw, canary, outputs, message):
    with pytest.raises(RpcFailed) as err:
        raw.call("CreateSession", two_target_request(pose_outputs=outputs))
    assert err.value.code == grpc.StatusCode.INVALID_ARGUMENT and message in err.value.message, err.value


@pytest.mark.parametrize("address", ["udp://10.1.2.3:40000", "udp://192.0.2.1:6301", "udp://255.255.255.255:40000"])
def test_a_destination_the_operator_did_not_allow_is_refused_at_create(raw, canary, address):
    """Loopback only by default: an engine key cannot aim the server's datagrams at any host."""
    with pytest.raises(RpcFailed) as err:
        raw.call(
            "CreateSession", two_target_request(pose_outputs=[pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address=address)])
        )
    assert err.value.code == grpc.StatusCode.INVALID_ARGUMENT, err.value
    assert f"pose_outputs[0].address {address!r}" in err.value.message and "--pose-output-allow" in err.value.message


def test_an_allowed_network_is_sent_to(server_factory):
    """`--pose-output-allow` opens a network (and only it): the session is made, its outputs counted."""
    srv = server_factory("--workers", "0", "--pose-output-allow", "192.0.2.0/24", "--pose-output-allow", "127.0.0.1/32")
    with closing(GrpcRaw(srv.grpc)) as client:
        outside = pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://192.0.3.1:6301")
        with pytest.raises(RpcFailed) as err:
            client.call("CreateSession", two_target_request(pose_outputs=[outside]))
        assert err.value.code == grpc.StatusCode.INVALID_ARGUMENT and "--pose-output-allow" in err.value.message
        allowed = pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address="udp://192.0.2.9:6301")
        session_id = client.call("CreateSession", two_target_request(pose_outputs=[allowed])).session_id
        client.stream(list(walk(session_id, 5)))
        detail = httpx.get(f"http://{srv.http}/v1/sessions/{session_id}", params={"last": 1}, timeout=30).json()
        assert detail["pose_outputs"][0]["address"] == "udp://192.0.2.9:6301"
        assert detail["pose_outputs"][0]["sent"] + detail["pose_outputs"][0]["dropped"] == 5


def test_a_destination_nobody_listens_on_fails_and_stalls_nothing(server, client, listeners):
    """ICMP port unreachable from a closed port on 127.0.0.1: frames go on, answered in order,
    and the other outputs of the session still get every pose."""
    port = closed_port()
    healthy = listeners()
    session_id = client.call(
        "CreateSession",
        two_target_request(
            pose_outputs=[
                output(pb.POSE_FORMAT_FREED_D1, port),
                output(pb.POSE_FORMAT_OPENTRACKIO_JSON, port),
                output(pb.POSE_FORMAT_FREED_D1, healthy),
            ]
        ),
    ).session_id
    updates = client.stream(list(walk(session_id, 240)))
    assert [u.frame for u in updates] == list(range(1, 241)) and not any(u.stale for u in updates)
    assert len(receive(healthy, 240)) == 240
    detail = httpx.get(f"http://{server.http}/v1/sessions/{session_id}", params={"last": 1}, timeout=30).json()
    assert [o["sent"] + o["dropped"] for o in detail["pose_outputs"]] == [240, 240, 240]
    assert client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id)).frames == 240
