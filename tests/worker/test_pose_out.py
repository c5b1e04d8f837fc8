"""The pose outputs' encoders and sender (worker/pose_out.py), judged independently: FreeD
by a decoder written here from the FreeD spec (D1 message, Appendix B), OpenTrackIO by SMPTE's
1.0.1 schema and reference receiver (tests/server/opentrackio_ref.py), the axes by rebuilding the
rotation from the sent angles with OpenTrackIO's own definition (intrinsic Z-X-Y, right-handed)."""

from __future__ import annotations

import math
import re
import socket
import uuid
from fractions import Fraction

import cbor2
import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.transforms import matrix_to_quat, quat_to_matrix
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker import pose_out as po
from camdirector.worker.table import SessionTable
from tests.service.opentrackio_ref import load_reference
from tests.service.wire_client import two_target_request, walk

# Our world (+Y up, the camera looking down -Z) onto OpenTrackIO's and FreeD's (+Z up, +Y forward).
M = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
URN_UUID = re.compile(r"^urn:uuid:[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$")


@pytest.fixture(scope="module")
def reference():
    return load_reference()


# --- independent references -------------------------------------------------------------------


def rotation_from_opentrackio(pan_deg: float, tilt_deg: float, roll_deg: float) -> np.ndarray:
    """OpenTrackIO's camera-to-stage rotation: intrinsic Z (pan), X (tilt), Y (roll), each
    right-handed ("Pan +ve X to Y, Tilt +ve Y to Z, Roll +ve Z to X")."""
    p, t, r = np.radians([pan_deg, tilt_deg, roll_deg])
    rz = np.array([[np.cos(p), -np.sin(p), 0], [np.sin(p), np.cos(p), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    ry = np.array([[np.cos(r), 0, np.sin(r)], [0, 1, 0], [-np.sin(r), 0, np.cos(r)]])
    return rz @ rx @ ry


def ours_from_opentrackio(pan_deg: float, tilt_deg: float, roll_deg: float) -> np.ndarray:
    """The same rotation in our world and camera axes."""
    return M.T @ rotation_from_opentrackio(pan_deg, tilt_deg, roll_deg) @ M


def look(forward, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Our camera-to-world quaternion looking along `forward` with its top toward `up`."""
    f = np.asarray(forward, dtype=float) / np.linalg.norm(forward)
    right = np.cross(f, up)
    right /= np.linalg.norm(right)
    return matrix_to_quat(np.column_stack([right, np.cross(right, f), -f]))


def decode_freed(data: bytes) -> dict:
    """A FreeD D1 message read as the spec writes it: 0xD1, camera id, pan, tilt, roll (signed
    24-bit, 1/32768 degree), X, Y, height (signed 24-bit, 1/64 mm), zoom, focus (unsigned 24-bit),
    two spare bytes, checksum = 0x40 minus the sum of the 28 bytes before it, mod 256."""
    assert len(data) == 29 and data[0] == 0xD1
    assert data[28] == (0x40 - sum(data[:28])) % 256, "checksum"

    def signed(at: int) -> int:
        value = int.from_bytes(data[at : at + 3], "big")
        return value - (1 << 24) if value & 0x800000 else value

    def unsigned(at: int) -> int:
        return int.from_bytes(data[at : at + 3], "big")

    return {
        "camera_id": data[1],
        "pan": signed(2) / 32768,
        "tilt": signed(5) / 32768,
        "roll": signed(8) / 32768,
        "x_mm": signed(11) / 64,
        "y_mm": signed(14) / 64,
        "z_mm": signed(17) / 64,
        "zoom": unsigned(20),
        "focus": unsigned(23),
        "spare": int.from_bytes(data[26:28], "big"),
    }


class Capture:
    """A socket stand-in: keeps what is sent, or raises `fail` on every send."""

    def __init__(self, fail: OSError | None = None):
        self.sent: list[tuple[bytes, tuple[str, int]]] = []
        self.fail = fail
        self.closed = False

    def sendto(self, data: bytes, address: tuple[str, int]) -> int:
        if self.fail is not None:
            raise self.fail
        self.sent.append((data, address))
        return len(data)

    def close(self) -> None:
        self.closed = True


def spec(fmt: po.PoseFormat, port: int = 50_000, source_number: int = 1, sensor_height_mm: float = 24.0):
    return po.PoseOutputSpec(fmt, f"udp://127.0.0.1:{port}", "127.0.0.1", port, source_number, sensor_height_mm)


def pose(forward=(0.0, 0.0, -1.0), up=(0.0, 1.0, 0.0), position=(1.0, 1.5, 2.0), fov=40.0) -> CameraPose:
    return CameraPose(np.array(position), look(forward, up), fov)


quaternions = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1)


# --- the conversion ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "forward, up, expected",
    [
        ((0, 0, -1), (0, 1, 0), (0.0, 0.0, 0.0)),  # our -Z: OpenTrackIO's +Y
        ((-1, 0, 0), (0, 1, 0), (90.0, 0.0, 0.0)),  # to the left: pan positive (X to Y)
        ((1, 0, 0), (0, 1, 0), (-90.0, 0.0, 0.0)),
        ((0, 0, 1), (0, 1, 0), (180.0, 0.0, 0.0)),
        ((0, math.sin(math.radians(30)), -math.cos(math.radians(30))), (0, 1, 0), (0.0, 30.0, 0.0)),  # up: tilt positive
        ((0, -math.sin(math.radians(20)), -math.cos(math.radians(20))), (0, 1, 0), (0.0, -20.0, 0.0)),
        # the top leaning to the camera's right: a clockwise roll seen from behind, positive (Z to X)
        ((0, 0, -1), (math.sin(math.radians(15)), math.cos(math.radians(15)), 0), (0.0, 0.0, 15.0)),
        ((-1, 0, -1), (0, 1, 0), (45.0, 0.0, 0.0)),
    ],
)
def test_known_poses_in_opentrackio_axes(forward, up, expected):
    translation, angles = po.opentrackio_transform(np.array([1.0, 1.5, 2.0]), look(forward, up))
    assert translation == pytest.approx((1.0, -2.0, 1.5))  # X = x, Y = -z, Z = y
    pan, tilt, roll = angles
    assert (abs(pan) if expected[0] == 180.0 else pan) == pytest.approx(expected[0], abs=1e-9)
    assert (tilt, roll) == pytest.approx(expected[1:], abs=1e-9)


@pytest.mark.parametrize(
    "forward, up", [((0, 1, 0), (0, 0, 1)), ((0, 1, 0), (1, 0, 0)), ((0, -1, 0), (0, 0, -1)), ((0, -1, 0), (-1, 0, 1))]
)
def test_straight_up_or_down_puts_it_all_in_pan(forward, up):
    _, (pan, tilt, roll) = po.opentrackio_transform([0, 0, 0], look(forward, up))
    assert tilt == pytest.approx(90.0 * forward[1]) and roll == 0.0
    np.testing.assert_allclose(ours_from_opentrackio(pan, tilt, roll), quat_to_matrix(look(forward, up)), atol=1e-7)


@settings(max_examples=300, deadline=None)
@given(quaternions, st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3))
def test_the_angles_rebuild_our_rotation(q, position):
    """pan, tilt, roll rebuilt by OpenTrackIO's definition give back our camera-to-world rotation."""
    q = np.asarray(q) / np.linalg.norm(q)
    translation, (pan, tilt, roll) = po.opentrackio_transform(np.asarray(position), q)
    assert -180.0 <= pan <= 180.0 and -90.0 <= tilt <= 90.0 and -180.0 <= roll <= 180.0
    np.testing.assert_allclose(ours_from_opentrackio(pan, tilt, roll), quat_to_matrix(q), atol=1e-7)
    np.testing.assert_allclose(translation, M @ np.asarray(position), atol=1e-12)


def test_focal_length_from_the_vertical_field_of_view():
    fov = math.degrees(2 * math.atan(12.0 / 35.0))  # a 35 mm lens on a 24 mm-high sensor
    assert po.focal_length_mm(fov, 24.0) == pytest.approx(35.0)
    assert po.focal_length_mm(fov, 12.0) == pytest.approx(17.5)
    assert po.focal_length_mm(90.0, 24.0) == pytest.approx(12.0)


@pytest.mark.parametrize(
    "dt_s, rate",
    [
        (1 / 60, Fraction(60)),
        (1001 / 60000, Fraction(60000, 1001)),
        (1 / 24, Fraction(24)),
        (1001 / 24000, Fraction(24000, 1001)),
        (1 / 25, Fraction(25)),
        (2 / 60, Fraction(30)),
        (1 / 37.5, Fraction(75, 2)),
        (0.0, Fraction(60)),
        (-1.0, Fraction(60)),
        (math.nan, Fraction(60)),
        (10.0, Fraction(1, 10)),
    ],
)
def test_sample_rate_from_the_frames(dt_s, rate):
    assert po.estimate_rate(dt_s) == rate
    assert po.estimate_rate(dt_s, Fraction(30)) == (Fraction(30) if rate == Fraction(60) and not dt_s > 0 else rate)


def test_a_rate_within_a_twentieth_of_a_percent_keeps_the_last():
    assert po.estimate_rate(1 / 60.02, Fraction(60)) == Fraction(60)
    assert po.estimate_rate(1 / 59.94, Fraction(60)) == Fraction(60000, 1001)


# --- FreeD -------------------------------------------------------------------------------------


def test_freed_d1_known_message():
    # Worked by hand from the spec: pan 90 deg = 90 * 32768 = 0x2D0000; tilt -45 deg =
    # 2**24 - 0x168000 = 0xE98000; X 1000 mm = 64000 = 0x00FA00; Y -2000 mm = 2**24 - 128000 =
    # 0xFE0C00; height 1500 mm = 96000 = 0x017700; zoom 3500 = 0x000DAC; the byte sum 1437 = 157
    # mod 256, and 0x40 - 157 = -93 = 0xA3 mod 256.
    message = po.freed_d1(1, 90.0, -45.0, 0.0, 1000.0, -2000.0, 1500.0, 3500, 0)
    assert message.hex() == "d1012d0000e9800000000000fa00fe0c00017700000dac0000000000a3"


def test_freed_d1_range_ends_from_the_spec():
    assert po.freed_d1(0, -180.0, -90.0, 180.0, 0, 0, 0, 0, 0)[2:11].hex() == "a60000d300005a0000"
    assert po.freed_d1(0, 180.0, 90.0, 0, 0, 0, 0, 0, 0)[2:8].hex() == "5a00002d0000"
    far = po.freed_d1(0, 0, 0, 0, -131_072.0, 1e9, 0, 1 << 30, -5)  # clamped to the fields' ranges
    assert far[11:17].hex() == "8000007fffff" and far[20:26].hex() == "ffffff000000"
    with pytest.raises(ValueError, match="camera id"):
        po.freed_d1(256, 0, 0, 0, 0, 0, 0, 0, 0)


@settings(max_examples=300, deadline=None)
@given(
    st.integers(0, 255),
    st.floats(-180, 180),
    st.floats(-90, 90),
    st.floats(-180, 180),
    st.floats(-131_000, 131_000),
    st.floats(-131_000, 131_000),
    st.floats(-131_000, 131_000),
    st.integers(0, (1 << 24) - 1),
    st.integers(0, (1 << 24) - 1),
    st.integers(0, 0xFFFF),
)
def test_freed_d1_round_trip(camera_id, pan, tilt, roll, x, y, z, zoom, focus, spare):
    message = po.freed_d1(camera_id, pan, tilt, roll, x, y, z, zoom, focus, spare)
    decoded = decode_freed(message)
    assert sum(message) % 256 == 0x40  # the checksum's own statement
    assert decoded["camera_id"] == camera_id and (decoded["zoom"], decoded["focus"], decoded["spare"]) == (zoom, focus, spare)
    for name, value in (("pan", pan), ("tilt", tilt), ("roll", roll)):
        assert abs(decoded[name] - value) <= 0.5 / 32768 + 1e-12
    for name, value in (("x_mm", x), ("y_mm", y), ("z_mm", z)):
        assert abs(decoded[name] - value) <= 0.5 / 64 + 1e-9


@pytest.mark.parametrize(
    "forward, up, expected",
    [
        ((0, 0, -1), (0, 1, 0), (0.0, 0.0, 0.0)),
        ((-1, 0, 0), (0, 1, 0), (-90.0, 0.0, 0.0)),  # FreeD: a pan to the right is positive, to the left negative
        ((1, 0, 0), (0, 1, 0), (90.0, 0.0, 0.0)),
        ((0, 0.5, -math.sqrt(0.75)), (0, 1, 0), (0.0, 30.0, 0.0)),
        ((0, 0, -1), (math.sin(math.radians(10)), math.cos(math.radians(10)), 0), (0.0, 0.0, 10.0)),  # clockwise from behind
    ],
)
def test_freed_from_a_pose(forward, up, expected):
    fov = math.degrees(2 * math.atan(12.0 / 35.0))
    decoded = decode_freed(po.freed_from_pose(pose(forward, up, position=(1.0, 1.5, 2.0), fov=fov), 7, 24.0))
    assert decoded["camera_id"] == 7
    assert (decoded["pan"], decoded["tilt"], decoded["roll"]) == pytest.approx(expected, abs=1e-4)
    assert (decoded["x_mm"], decoded["y_mm"], decoded["z_mm"]) == (1000.0, -2000.0, 1500.0)  # X = x, Y = -z, Z = y
    assert decoded["zoom"] == 3500 and decoded["focus"] == 0  # 35 mm in 1/100 mm


# --- OpenTrackIO packets -----------------------------------------------------------------------


def big_sample(related: int = 120) -> dict:
    sample = po.opentrackio_sample(
        (1.0, -2.0, 1.5),
        (10.0, 5.0, -3.0),
        focal_length_mm=35.0,
        source_id=f"urn:uuid:{uuid.uuid4()}",
        sample_id=f"urn:uuid:{uuid.uuid4()}",
        source_number=3,
        sequence=7,
        sample_rate=Fraction(60000, 1001),
        timestamp_s=1_700_000_000.25,
        static=po.opentrackio_static(24.0, 16 / 9, "a-session"),
    )
    sample["relatedSampleIds"] = [f"urn:uuid:{uuid.uuid4()}" for _ in range(related)]  # a payload past the MTU
    return sample


def test_fletcher16_matches_smptes(reference):
    rng = np.random.default_rng(3)
    for n in (0, 1, 2, 15, 16, 700, 1472, 3000):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert po.fletcher16(data).to_bytes(2, "big") == reference.lib.fletcher16(data)


def test_one_packet_header():
    payload = orjson.dumps({"protocol": {"name": "OpenTrackIO", "version": [1, 0, 1]}})
    (packet,) = po.otrk_packets(payload, 0x02, 513)
    assert packet[:4] == b"OTrk" and packet[4] == 0 and packet[5] == 0x02
    assert int.from_bytes(packet[6:8], "big") == 513 and int.from_bytes(packet[8:12], "big") == 0
    assert int.from_bytes(packet[12:14], "big") == 0x8000 | len(payload) and packet[16:] == payload
    assert int.from_bytes(packet[14:16], "big") == po.fletcher16(packet[:14] + payload)


@pytest.mark.parametrize("fmt", [po.PoseFormat.OPENTRACKIO_JSON, po.PoseFormat.OPENTRACKIO_CBOR])
@pytest.mark.parametrize("max_segment", [po.OTRK_MAX_SEGMENT, 300])
def test_a_payload_past_the_mtu_is_segmented_and_smptes_receiver_reassembles_it(reference, fmt, max_segment):
    sample = big_sample()
    assert not reference.errors(sample)
    payload = orjson.dumps(sample) if fmt == po.PoseFormat.OPENTRACKIO_JSON else cbor2.dumps(sample)
    assert len(payload) > 2 * po.OTRK_MAX_DATAGRAM
    packets = po.otrk_packets(payload, po.OTRK_ENCODING[fmt], 65_534, max_segment)
    assert len(packets) == math.ceil(len(payload) / max_segment) >= 3
    assert all(len(p) <= po.OTRK_MAX_DATAGRAM for p in packets)
    assert [int.from_bytes(p[6:8], "big") for p in packets[:3]] == [65_534, 65_535, 0]  # one number per packet, wrapping
    assert [p[12] >> 7 for p in packets] == [0] * (len(packets) - 1) + [1]
    decoded = reference.feed(reference.new_receiver(), packets)
    assert decoded == sample and not reference.errors(decoded)


def test_smptes_receiver_rejects_a_damaged_or_incomplete_payload(reference):
    packets = po.otrk_packets(orjson.dumps(big_sample()), 0x01, 10)
    damaged = bytearray(packets[1])
    damaged[40] ^= 0xFF
    assert reference.feed(reference.new_receiver(), [packets[0], bytes(damaged), *packets[2:]]) is None
    assert reference.feed(reference.new_receiver(), [packets[0], *packets[2:]]) is None  # a segment lost


# --- the sender --------------------------------------------------------------------------------


def samples_of(reference, datagrams: list[bytes]) -> list[dict]:
    receiver = reference.new_receiver()
    return [reference.feed(receiver, [d]) for d in datagrams]


@pytest.mark.parametrize("fmt", [po.PoseFormat.OPENTRACKIO_JSON, po.PoseFormat.OPENTRACKIO_CBOR])
def test_every_sample_passes_smptes_schema_and_receiver(reference, fmt):
    capture = Capture()
    sender = po.PoseSender(
        "session-1", [spec(fmt, source_number=9, sensor_height_mm=18.0)], 16 / 9, wall_clock=lambda: 1_700_000_000.5, sock=capture
    )
    poses = [pose((math.sin(0.1 * i), 0.1, -math.cos(0.1 * i)), position=(i * 0.1, 1.5, -i * 0.2)) for i in range(150)]
    for i, p in enumerate(poses):
        sender.send(p, i / 60)
    assert {address for _, address in capture.sent} == {("127.0.0.1", 50_000)}
    datagrams = [data for data, _ in capture.sent]
    assert [int.from_bytes(d[6:8], "big") for d in datagrams] == list(range(1, 151))  # header: one per packet, from 1
    samples = samples_of(reference, datagrams)
    source_id = f"urn:uuid:{uuid.uuid5(po._SOURCE_NAMESPACE, 'session-1')}"
    for i, (sample, p) in enumerate(zip(samples, poses)):
        assert sample is not None and not reference.errors(sample), (i, reference.errors(sample or {}))
        assert sample["protocol"] == {"name": "OpenTrackIO", "version": [1, 0, 1]}
        assert sample["sourceId"] == source_id and URN_UUID.match(sample["sampleId"]) and sample["sourceNumber"] == 9
        assert sample["timing"] == {
            "mode": "internal",
            "sampleRate": {"num": 60, "denom": 1},
            "sequenceNumber": i,
            "sampleTimestamp": {"seconds": 1_700_000_000, "nanoseconds": 500_000_000},
        }
        assert sample["lens"]["pinholeFocalLength"] == pytest.approx(9.0 / math.tan(math.radians(20.0)))
        (transform,) = sample["transforms"]
        assert transform["id"] == "Camera"
        rotation = transform["rotation"]
        np.testing.assert_allclose(
            ours_from_opentrackio(rotation["pan"], rotation["tilt"], rotation["roll"]), quat_to_matrix(p.rotation_xyzw), atol=1e-9
        )
        t = transform["translation"]
        np.testing.assert_allclose([t["x"], t["y"], t["z"]], M @ p.position_world)
        assert ("static" in sample) == (i in (0, 120)), i  # the first, then every 2 s of the frames' time
    assert len({s["sampleId"] for s in samples}) == len(samples)
    assert samples[0]["static"]["camera"]["activeSensorPhysicalDimensions"] == {"height": 18.0, "width": 32.0}
    assert samples[0]["static"]["tracker"]["serialNumber"] == "session-1"


def test_static_again_when_time_goes_back_and_the_rate_follows_the_frames():
    capture = Capture()
    sender = po.PoseSender("s", [spec(po.PoseFormat.OPENTRACKIO_JSON)], 1.5, sock=capture)
    for t in (0.0, 1 / 30, 2 / 30, 2.1, 1.0, 1.5):  # 2.1: 2 s on; 1.0: before the last static block
        sender.send(pose(), t)
    samples = [orjson.loads(data[16:]) for data, _ in capture.sent]
    assert ["static" in s for s in samples] == [True, False, False, True, True, False]
    assert [Fraction(s["timing"]["sampleRate"]["num"], s["timing"]["sampleRate"]["denom"]) for s in samples[:3]] == [
        Fraction(60),
        Fraction(30),
        Fraction(30),
    ]


def test_freed_output_sends_the_converted_pose():
    capture = Capture()
    sender = po.PoseSender(
        "s", [spec(po.PoseFormat.FREED_D1, port=40_000, source_number=12, sensor_height_mm=12.0)], 16 / 9, sock=capture
    )
    sender.send(pose((-1, 0, 0), position=(0.5, 2.0, -3.0), fov=90.0), 0.0)
    ((data, address),) = capture.sent
    decoded = decode_freed(data)
    assert address == ("127.0.0.1", 40_000) and decoded["camera_id"] == 12
    assert (decoded["pan"], decoded["tilt"], decoded["roll"]) == pytest.approx((-90.0, 0.0, 0.0), abs=1e-4)
    assert (decoded["x_mm"], decoded["y_mm"], decoded["z_mm"]) == (500.0, 3000.0, 2000.0)
    assert decoded["zoom"] == 600  # 6 mm: a 90-degree field of view on a 12 mm-high sensor


@pytest.mark.parametrize(
    "failure",
    [
        BlockingIOError(11, "Resource temporarily unavailable"),
        ConnectionRefusedError(111, "Connection refused"),
        OSError(101, "Network is unreachable"),
    ],
)
def test_a_send_that_fails_is_dropped_and_counted_never_raised(failure):
    capture = Capture(fail=failure)
    outputs = [spec(po.PoseFormat.FREED_D1), spec(po.PoseFormat.OPENTRACKIO_CBOR)]
    sender = po.PoseSender("s", outputs, 1.0, sock=capture)
    for i in range(50):
        sender.send(pose(), i / 60)
    for status in sender.status():
        assert status["sent"] == 0 and status["dropped"] == 50
        assert status["last_error"].startswith(type(failure).__name__)


def test_a_closed_port_on_a_real_socket_never_raises():
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # nobody listens there: the kernel answers ICMP port unreachable
    sender = po.PoseSender("s", [spec(po.PoseFormat.FREED_D1, port=port), spec(po.PoseFormat.OPENTRACKIO_JSON, port=port)], 1.0)
    for i in range(200):
        sender.send(pose(), i / 60)
    assert all(s["sent"] + s["dropped"] == 200 for s in sender.status())
    sender.close()
    assert sender.sock.fileno() == -1


# --- in the session table ----------------------------------------------------------------------


def test_the_table_sends_answered_frames_only_and_closes_the_socket_with_the_session(tmp_path):
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    listener.settimeout(5.0)
    port = listener.getsockname()[1]
    table = SessionTable(ServerSettings(workers=0, data_dir=str(tmp_path)))
    request = two_target_request(
        pose_outputs=[pb.PoseOutput(format=pb.POSE_FORMAT_FREED_D1, address=f"udp://localhost:{port}", source_number=4)]
    )
    table.create("s1", request)
    frames = list(walk("s1", 5))
    replies = [table.frame(f) for f in frames]
    stale = table.frame(frames[2])
    assert stale.stale
    for reply in replies:
        decoded = decode_freed(listener.recv(64))
        _, (pan, tilt, roll) = po.opentrackio_transform(
            [0, 0, 0], [reply.pose.rotation.x, reply.pose.rotation.y, reply.pose.rotation.z, reply.pose.rotation.w]
        )
        assert decoded["camera_id"] == 4 and decoded["pan"] == pytest.approx(-pan, abs=1e-4)
        assert decoded["x_mm"] == pytest.approx(reply.pose.position.x * 1e3, abs=0.01)
    listener.settimeout(0.2)
    with pytest.raises(TimeoutError):  # the stale frame sent nothing
        listener.recv(64)
    (status,) = table.timeline("s1")["pose_outputs"]
    assert status == {
        "format": "POSE_FORMAT_FREED_D1",
        "address": f"udp://localhost:{port}",
        "source_number": 4,
        "sent": 5,
        "dropped": 0,
        "last_error": None,
    }
    sender = table.held["s1"].pose_sender
    table.close("s1")
    assert sender.sock.fileno() == -1
    listener.close()
