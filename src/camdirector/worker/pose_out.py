"""Pose outputs: a session's camera poses also sent as UDP datagrams, in the camera-tracking
formats of virtual production (docs/protocol.md, "Pose outputs (OpenTrackIO, FreeD)").

A session created with `pose_outputs` gets a `PoseSender` (one non-blocking UDP socket, opened at
CreateSession and closed with the session). `SessionTable.frame_bytes` calls `PoseSender.send` after
the reply is made, for each answered frame that is not stale and has a pose; the pipeline itself
never sends anything. Sending never fails or slows a frame: `sendto` on an unconnected,
non-blocking socket, so an ICMP "port unreachable" is never reported back (Linux reports it only
on a connected socket) and a full buffer (EAGAIN) or any other OSError drops that datagram, counted
per output (`PoseSender.status`, the session's REST summary) and logged once.

Axes (our world: right-handed, +Y up, metres; the camera looks down its local -Z with +Y up):
OpenTrackIO's stage and FreeD's studio are both right-handed, Z up, the camera looking along +Y
at zero angles, X to its right. Ours map onto them by the proper rotation
    X = x,  Y = -z,  Z = y
applied to positions and to the camera's own axes alike (so our camera's right, forward (-z) and
up become their X, Y, Z). With R our camera-to-world rotation matrix (R[i][j], row i, column j):
    tilt = atan2(-R[1][2], hypot(R[0][2], R[2][2]))   (the elevation of the view direction)
    pan  = atan2(R[0][2], R[2][2])                     (OpenTrackIO: positive turns left, X to Y)
    roll = atan2(-R[1][0], R[1][1])                    (positive: the picture's top turns right)
which decompose the rotation as OpenTrackIO's intrinsic Z-X-Y (pan about Z, tilt about X, roll
about Y, each right-handed: SMPTE's figure "Pan +ve X to Y, Tilt +ve Y to Z, Roll +ve Z to X").
Looking straight up or down (|tilt| = 90 deg) roll is 0 and pan = atan2(-R[2][0], R[0][0]).
FreeD's pan is positive to the right ("clockwise when viewed from above"), so FreeD sends -pan;
its tilt (up positive) and roll ("clockwise when viewed from behind the camera") are the same.

Lens: pinholeFocalLength (mm) = (sensor_height_mm / 2) / tan(vertical_fov / 2); FreeD's zoom
field carries the same focal length in 1/100 mm (Z CAM's FreeD convention), focus 0 (a pinhole
has none).

Cost of `send` per frame and output, measured on the 2-core development VM (shared with other
work) as the median over 40 batches of 500 calls, one output, its own socket sending to a bound
loopback port (a throwaway script, not a test: timings are never asserted): FreeD D1 6.7 us
(the message 3.4, the axes 0.8, sendto about 1.5); OpenTrackIO JSON 13 us and CBOR 17.5 us (a
fresh sampleId 2.0, the sample dict 1.2, orjson 0.4 or cbor2 4.0, the OTrk header with its
Fletcher-16 3.8, the sample rate 0.5, sendto about 2); a sample that carries the static block
(every 2 s) 0.5 to 2.5 us more. `SessionTable.frame_bytes` calls it after `compute_ms` is measured.
"""

from __future__ import annotations

import enum
import importlib.metadata
import logging
import math
import socket
import struct
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import cbor2
import numpy as np
import numpy.typing as npt
import orjson

from camdirector.geometry.camera import CameraPose

log = logging.getLogger("camdirector.pose_out")


class PoseFormat(enum.IntEnum):
    """Same numbers as camdirector.v1.PoseFormat."""

    UNSPECIFIED = 0
    OPENTRACKIO_JSON = 1
    OPENTRACKIO_CBOR = 2
    FREED_D1 = 3


@dataclass(frozen=True)
class PoseOutputSpec:
    """One validated CreateSessionRequest.pose_outputs entry (worker/codec.py)."""

    format: PoseFormat
    address: str  # as the client wrote it, udp://HOST:PORT
    host: str  # the IPv4 address HOST resolved to at CreateSession
    port: int  # [1, 65535]
    source_number: int  # OpenTrackIO sourceNumber [1, 200]; FreeD camera id [1, 255]
    sensor_height_mm: float  # [1, 100]


# --- OpenTrackIO 1.0.1 -------------------------------------------------------------------------
OPENTRACKIO_VERSION = (1, 0, 1)
OTRK_IDENTIFIER = b"OTrk"
OTRK_HEADER_BYTES = 16
# Identifier, reserved, encoding, sequence number, segment offset, last-segment bit | payload
# length; the Fletcher-16 checksum (2 bytes) follows, then the payload (SMPTE's packet header).
_OTRK_HEAD = struct.Struct("!4sBBHIH")
# A datagram fits one 1500-byte Ethernet frame with its IPv4 and UDP headers (20 + 8 bytes), so
# it is never fragmented; a longer payload goes in segments of this many bytes.
OTRK_MAX_DATAGRAM = 1472
OTRK_MAX_SEGMENT = OTRK_MAX_DATAGRAM - OTRK_HEADER_BYTES
OTRK_ENCODING = {PoseFormat.OPENTRACKIO_JSON: 0x01, PoseFormat.OPENTRACKIO_CBOR: 0x02}
# "It is recommended that a static metadata object is added to a sample approximately every 2
# seconds" (the OpenTrackIO documentation); counted on the frames' time_s, and on the first sample.
STATIC_EVERY_S = 2.0
NOMINAL_RATE = Fraction(60)  # timing.sampleRate until two samples give the frames' own rate
# Broadcast and display rates that an estimated rate within 0.05% snaps to (exact drop-frame ones).
_KNOWN_RATES = (
    Fraction(24000, 1001),
    Fraction(24),
    Fraction(25),
    Fraction(30000, 1001),
    Fraction(30),
    Fraction(48),
    Fraction(50),
    Fraction(60000, 1001),
    Fraction(60),
    Fraction(72),
    Fraction(90),
    Fraction(100),
    Fraction(120000, 1001),
    Fraction(120),
    Fraction(144),
    Fraction(240),
)
_KNOWN_RATE_VALUES = tuple((float(rate), rate) for rate in _KNOWN_RATES)
_RATE_TOLERANCE = 0.0005  # relative; 59.94 and 60 are 0.1% apart
_MAX_RATE_HZ = 10_000.0
CAMERA_TRANSFORM_ID = "Camera"  # the transform's id: SMPTE's reference parser looks for "Camera"
_SOURCE_NAMESPACE = uuid.uuid5(uuid.NAMESPACE_URL, "https://camdirector/sessions")
try:
    _VERSION = importlib.metadata.version("camdirector")
except importlib.metadata.PackageNotFoundError:  # run from a tree that is not installed
    _VERSION = "0"

# --- FreeD D1 ----------------------------------------------------------------------------------
FREED_D1 = 0xD1
FREED_D1_BYTES = 29
FREED_ANGLE_SCALE = 32768.0  # 1/32768 degree per unit (8.15 fixed point)
FREED_POSITION_SCALE = 64.0  # 1/64 mm per unit (17.6 fixed point)
FREED_ZOOM_SCALE = 100.0  # zoom: the focal length in 1/100 mm
_I24_MIN, _I24_MAX, _U24_MAX = -(1 << 23), (1 << 23) - 1, (1 << 24) - 1

Floats = Sequence[float] | npt.NDArray[np.float64]  # a pose's vectors as our geometry holds them, or plain numbers


def opentrackio_transform(
    position_world: Floats, rotation_xyzw: Floats
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Our camera pose as OpenTrackIO's stage transform: ((x, y, z) metres, (pan, tilt, roll)
    degrees), the conversion of the module docstring. rotation_xyzw: camera-to-world, unit."""
    px, py, pz = _floats(position_world)
    x, y, z, w = _floats(rotation_xyzw)
    # The entries of R (geometry.transforms.quat_to_matrix) that the decomposition reads.
    r02, r12, r22 = 2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)
    r00, r01 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z)
    r20, r21 = 2 * (x * z - w * y), 2 * (y * z + w * x)
    cos_tilt = math.hypot(r02, r22)
    tilt = math.atan2(-r12, cos_tilt)
    if cos_tilt > 1e-9:
        pan = math.atan2(r02, r22)
        # Roll from the rotation with pan taken out (entries of size about 1), not from r10 and r11,
        # which shrink with cos(tilt): near straight up or down those lose the angle's precision.
        sin_pan, cos_pan = math.sin(pan), math.cos(pan)
        roll = math.atan2(cos_pan * r01 - sin_pan * r21, cos_pan * r00 - sin_pan * r20)
    else:  # straight up or down: pan and roll turn about the same axis; all of it is pan
        pan, roll = math.atan2(-r20, r00), 0.0
    return (px, -pz, py), (math.degrees(pan), math.degrees(tilt), math.degrees(roll))


def _floats(values: Floats) -> list[float]:
    return values.tolist() if isinstance(values, np.ndarray) else [float(v) for v in values]


def focal_length_mm(vertical_fov_deg: float, sensor_height_mm: float) -> float:
    """Pinhole focal length, mm, that gives this vertical field of view on this sensor height."""
    return 0.5 * sensor_height_mm / math.tan(math.radians(vertical_fov_deg) / 2.0)


def estimate_rate(dt_s: float, previous: Fraction = NOMINAL_RATE) -> Fraction:
    """timing.sampleRate from the time between two samples ("in a variable rate system this should
    be estimated from the last sample delta time"): `previous` again when within 0.05% of it (or
    for a gap that gives no rate), else the nearest known broadcast rate when within 0.05%, else
    the nearest fraction with a denominator up to 1001."""
    if not (math.isfinite(dt_s) and 1.0 / _MAX_RATE_HZ <= dt_s <= 1e6):
        return previous
    rate = 1.0 / dt_s
    if abs(rate * previous.denominator / previous.numerator - 1.0) < _RATE_TOLERANCE:
        return previous  # the steady state: no Fraction arithmetic
    error, known = min((abs(rate / value - 1.0), known) for value, known in _KNOWN_RATE_VALUES)
    if error < _RATE_TOLERANCE:
        return known
    estimate = Fraction(rate).limit_denominator(1001)
    return estimate if estimate.numerator >= 1 else Fraction(1, min(round(dt_s), 4_294_967_295))


def opentrackio_static(sensor_height_mm: float, aspect: float, serial_number: str) -> dict:
    """The sample's `static` block: what describes the source rather than one frame."""
    return {
        "camera": {
            "activeSensorPhysicalDimensions": {"height": sensor_height_mm, "width": sensor_height_mm * aspect},
            "make": "camdirector",
            "model": "virtual camera",
        },
        "lens": {"make": "camdirector", "model": "pinhole"},
        "tracker": {
            "make": "camdirector",
            "model": "automated cinematographer",
            "serialNumber": serial_number[:1023],
            "firmwareVersion": _VERSION,
        },
    }


def opentrackio_sample(
    translation_m: Sequence[float],
    rotation_deg: Sequence[float],
    *,
    focal_length_mm: float,
    source_id: str,
    sample_id: str,
    source_number: int,
    sequence: int,
    sample_rate: Fraction,
    timestamp_s: float,
    static: dict | None = None,
) -> dict:
    """One OpenTrackIO 1.0.1 sample (a dict for JSON or CBOR). translation_m, rotation_deg: the
    stage transform (opentrackio_transform); source_id, sample_id: urn:uuid URNs; sequence: the
    sample's number in its stream; timestamp_s: the system clock at the sample, Unix seconds."""
    seconds = int(timestamp_s)
    sample = {
        "protocol": {"name": "OpenTrackIO", "version": list(OPENTRACKIO_VERSION)},
        "sampleId": sample_id,
        "sourceId": source_id,
        "sourceNumber": source_number,
        "timing": {
            "mode": "internal",
            "sampleRate": {"num": sample_rate.numerator, "denom": sample_rate.denominator},
            "sampleTimestamp": {"seconds": seconds, "nanoseconds": min(int((timestamp_s - seconds) * 1e9), 999_999_999)},
            "sequenceNumber": sequence & 0xFFFFFFFF,
        },
        "lens": {"pinholeFocalLength": focal_length_mm},
        "transforms": [
            {
                "id": CAMERA_TRANSFORM_ID,
                "translation": {"x": translation_m[0], "y": translation_m[1], "z": translation_m[2]},
                "rotation": {"pan": rotation_deg[0], "tilt": rotation_deg[1], "roll": rotation_deg[2]},
            }
        ],
    }
    if static is not None:
        sample["static"] = static
    return sample


_WEIGHTS = np.arange(OTRK_MAX_DATAGRAM, 0, -1, dtype=np.int64)  # n, n-1, ..., 1 for Fletcher's second sum


def fletcher16(data: bytes) -> int:
    """Fletcher-16 with modulus 256, as OpenTrackIO's header (SMPTE's reference code): the second
    byte sum1 = sum of the bytes, the first sum2 = sum of the running sums, both mod 256; in closed
    form sum2 = sum((n - i) * byte_i), vectorised."""
    n = len(data)
    if n > OTRK_MAX_DATAGRAM:  # only a test's own segment size gets here
        weights = np.arange(n, 0, -1, dtype=np.int64)
    else:
        weights = _WEIGHTS[OTRK_MAX_DATAGRAM - n :]
    values = np.frombuffer(data, dtype=np.uint8)
    return ((int(values @ weights) & 0xFF) << 8) | (int(values.sum(dtype=np.int64)) & 0xFF)


def otrk_packets(payload: bytes, encoding: int, sequence: int, max_segment: int = OTRK_MAX_SEGMENT) -> list[bytes]:
    """A payload in OTrk packets: one per segment of at most `max_segment` bytes, numbered from
    `sequence` (mod 2**16: every packet has its own number, as SMPTE's sender does), each with its
    segment offset, the last-segment bit on the last, and the Fletcher-16 of header and segment.
    encoding: 0x01 JSON, 0x02 CBOR (OTRK_ENCODING)."""
    if not 1 <= max_segment <= 0x7FFF:
        raise ValueError(f"max_segment must be in [1, 32767], got {max_segment}")
    packets = []
    offsets = range(0, len(payload), max_segment) if payload else (0,)
    for i, offset in enumerate(offsets):
        segment = payload[offset : offset + max_segment]
        last = offset + max_segment >= len(payload)
        head = _OTRK_HEAD.pack(
            OTRK_IDENTIFIER, 0, encoding, (sequence + i) & 0xFFFF, offset, (0x8000 if last else 0) | len(segment)
        )
        packets.append(head + fletcher16(head + segment).to_bytes(2, "big") + segment)
    return packets


def _i24(value: float, scale: float) -> bytes:
    units = max(_I24_MIN, min(_I24_MAX, round(value * scale)))
    return (units & 0xFFFFFF).to_bytes(3, "big")


def _u24(value: int) -> bytes:
    return max(0, min(_U24_MAX, int(value))).to_bytes(3, "big")


def freed_d1(
    camera_id: int,
    pan_deg: float,
    tilt_deg: float,
    roll_deg: float,
    x_mm: float,
    y_mm: float,
    z_mm: float,
    zoom: int,
    focus: int,
    spare: int = 0,
) -> bytes:
    """A FreeD D1 message (29 bytes): 0xD1, the camera id, pan, tilt, roll (signed 24-bit,
    1/32768 degree), X, Y, Z (signed 24-bit, 1/64 mm), zoom and focus (unsigned 24-bit), 16 spare
    bits, and the checksum 0x40 minus the sum of the 28 bytes before it, mod 256. Each field is
    big-endian; a value past its field's range is clamped to the range (positions beyond
    +-131.072 m)."""
    if not 0 <= camera_id <= 0xFF:
        raise ValueError(f"FreeD camera id must be in [0, 255], got {camera_id}")
    body = b"".join(
        (
            bytes((FREED_D1, camera_id)),
            _i24(pan_deg, FREED_ANGLE_SCALE),
            _i24(tilt_deg, FREED_ANGLE_SCALE),
            _i24(roll_deg, FREED_ANGLE_SCALE),
            _i24(x_mm, FREED_POSITION_SCALE),
            _i24(y_mm, FREED_POSITION_SCALE),
            _i24(z_mm, FREED_POSITION_SCALE),
            _u24(zoom),
            _u24(focus),
            (spare & 0xFFFF).to_bytes(2, "big"),
        )
    )
    return body + bytes(((0x40 - sum(body)) & 0xFF,))


def freed_from_transform(
    translation_m: Sequence[float], rotation_deg: Sequence[float], focal_length_mm: float, camera_id: int
) -> bytes:
    """A FreeD D1 message from the stage transform (opentrackio_transform: FreeD's axes are the
    same, its pan the opposite way) and the lens's focal length (zoom, in 1/100 mm; focus 0)."""
    (x, y, z), (pan, tilt, roll) = translation_m, rotation_deg
    return freed_d1(camera_id, -pan, tilt, roll, x * 1e3, y * 1e3, z * 1e3, round(focal_length_mm * FREED_ZOOM_SCALE), 0)


def freed_from_pose(pose: CameraPose, camera_id: int, sensor_height_mm: float) -> bytes:
    """Our pose as a FreeD D1 message (the module docstring's axes and lens mapping)."""
    return freed_from_transform(
        *opentrackio_transform(pose.position_world, pose.rotation_xyzw),
        focal_length_mm(pose.vertical_fov_deg, sensor_height_mm),
        camera_id,
    )


@dataclass
class _Output:
    spec: PoseOutputSpec
    sequence: int = 1  # OTrk header; SMPTE's receiver takes a first packet numbered 0 for a repeat
    sent: int = 0  # datagrams
    dropped: int = 0  # datagrams whose sendto failed
    last_error: str = ""
    static_block: dict | None = field(default=None, repr=False)


class PoseSender:
    """Sends a session's poses to its outputs (the module docstring); one UDP socket per session.

    session_id: names the source (sourceId is uuid5 of it, the static block's serial number);
    aspect: the session lens's width over height, for the sensor's width; wall_clock: the
    sampleTimestamp's clock (Unix seconds); sock: a socket to send on instead of a new one (tests).
    """

    def __init__(
        self,
        session_id: str,
        outputs: Sequence[PoseOutputSpec],
        aspect: float,
        *,
        wall_clock: Callable[[], float] = time.time,
        sock: socket.socket | None = None,
    ):
        self.outputs = [_Output(spec) for spec in outputs]
        self.source_id = f"urn:uuid:{uuid.uuid5(_SOURCE_NAMESPACE, session_id)}"
        self.session_id = session_id
        self.aspect = aspect
        self.wall_clock = wall_clock
        self.samples = 0  # samples sent so far: the next timing.sequenceNumber
        self.rate = NOMINAL_RATE  # timing.sampleRate, from the frames' own times
        self._last_time_s: float | None = None
        self._last_static_s: float | None = None
        if sock is None:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.setblocking(False)
            # A broadcast address is sent to only when the client wrote one; this lets it through.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        self.sock = sock

    def send(self, pose: CameraPose, time_s: float) -> None:
        """One answered frame's pose (time_s: the frame's, for the sample rate and the static
        block's cadence) to every output. Never raises for the network: a datagram that cannot be
        sent is dropped and counted."""
        if self._last_time_s is not None:
            self.rate = estimate_rate(time_s - self._last_time_s, self.rate)
        self._last_time_s = time_s
        static_due = self._last_static_s is None or not 0.0 <= time_s - self._last_static_s < STATIC_EVERY_S
        if static_due:
            self._last_static_s = time_s
        translation, rotation = opentrackio_transform(pose.position_world, pose.rotation_xyzw)
        timestamp_s = self.wall_clock()
        for out in self.outputs:
            spec = out.spec
            focal_mm = focal_length_mm(pose.vertical_fov_deg, spec.sensor_height_mm)
            if spec.format == PoseFormat.FREED_D1:
                datagrams = [freed_from_transform(translation, rotation, focal_mm, spec.source_number)]
            else:
                if static_due and out.static_block is None:
                    out.static_block = opentrackio_static(spec.sensor_height_mm, self.aspect, self.session_id)
                sample = opentrackio_sample(
                    translation,
                    rotation,
                    focal_length_mm=focal_mm,
                    source_id=self.source_id,
                    sample_id=f"urn:uuid:{uuid.uuid4()}",
                    source_number=spec.source_number,
                    sequence=self.samples,
                    sample_rate=self.rate,
                    timestamp_s=timestamp_s,
                    static=out.static_block if static_due else None,
                )
                payload = orjson.dumps(sample) if spec.format == PoseFormat.OPENTRACKIO_JSON else cbor2.dumps(sample)
                datagrams = otrk_packets(payload, OTRK_ENCODING[spec.format], out.sequence)
                out.sequence = (out.sequence + len(datagrams)) & 0xFFFF
            for datagram in datagrams:
                try:
                    self.sock.sendto(datagram, (spec.host, spec.port))
                    out.sent += 1
                except OSError as exc:  # a full buffer, an unreachable network: drop it, never the frame
                    out.dropped += 1
                    if not out.last_error:
                        log.warning(
                            "session %s: pose output %s dropped a datagram (%s); counting further drops without logging them",
                            self.session_id,
                            spec.address,
                            exc,
                        )
                    out.last_error = f"{type(exc).__name__}: {exc.strerror or exc}"
        self.samples += 1

    def status(self) -> list[dict]:
        """Each output's format, address and counts, for the session's summary."""
        return [
            {
                "format": f"POSE_FORMAT_{out.spec.format.name}",
                "address": out.spec.address,
                "source_number": out.spec.source_number,
                "sent": out.sent,
                "dropped": out.dropped,
                "last_error": out.last_error or None,
            }
            for out in self.outputs
        ]

    def close(self) -> None:
        self.sock.close()
