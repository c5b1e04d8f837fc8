"""The framing of the sockets and pipes between camdirector's processes, written once for both ends.

The front and a worker (front/worker_pool.py holds the front's end, worker/main.py the worker's):
every message is a fixed struct header, then raw bytes; nothing is pickled, and the payload is the
client's serialized request exactly as the front received it (the front read only its session id).
- Request, front to worker: REQUEST (request id, op code, session id length, payload length), the
  session id (UTF-8), the payload.
- A `create` request's payload is the session's tenant around the client's CreateSessionRequest
  (`encode_create`): a zero byte, the tenant's length (u8), the tenant (ASCII), the request's bytes.
  A session's checkpoint keeps this payload, so a session restored on another worker or node
  still finds its tenant's levels. No serialized protobuf message begins with a zero byte (field
  number 0 does not exist), so a payload that is only a request (a checkpoint written before
  tenants) reads as tenant `default`.
- Reply, worker to front: REPLY (request id, status: a gRPC status code, 0 for OK; flags:
  HAS_METRICS, STALE, CHECKPOINT_FAILED; compute_ms; stage count; stage names length; body length), the stage names
  (ASCII, comma-separated, in the frame's stage order), their times (one float64 each, ms), the
  body: the serialized reply, or the UTF-8 error message when the status is not 0.
A frame's metrics thus travel as a few packed numbers beside its reply, taken from the frame's
state in the worker (never read back out of the reply). Replies may come out of order: a `view`
(a monitor's picture) is answered from the render process's reader thread (render/monitor.py)
while the loop goes on with other requests, so every write to the socket takes one lock. Lengths are 64-bit, so a scene of more
than 2 GiB needs no escape (multiprocessing's framing switched to a second, 8-byte length there).
A FRAMING_ONLY frame and its reply carry 136 bytes of framing (headers, session id, stage names
and times) where the pickled tuples took about 275, and building and reading both cost 3.3 us against
4.2 us (measured in one process); a closed loop of `ping`s carrying 1.1 KB through a real
WorkerPool and worker took 19-22 us a round trip (p50) against 27-34 us pickled.

A worker and its render process (render/monitor.py the worker's end, render/main.py the render
process's): length-prefixed pickles over the process's stdin and stdout (`write_message`,
`read_message`); both ends are camdirector's own code over a private pipe.

A monitor's view (the `view` op; the front's end is front/view_hub.py, the worker's
worker/dispatch.py, the picture's maker render/main.py): the request's payload is a `ViewQuery`'s
JSON (`ViewQuery.to_json`, `ViewQuery.from_json`); each reply body is a view (`encode_view`): a
4-byte length, a JSON header (the frame shown, the placeholder's reason if any, the render time,
the media type, and the top view's world bounds), then the image. A query that is not one raises
ValueError, which each end answers as its own refusal (INVALID_ARGUMENT, HTTP 422).
"""

from __future__ import annotations

import pickle
import struct
from dataclasses import dataclass
from typing import IO, Any

import orjson


@dataclass
class FrameMetrics:
    """Timings of one answered frame, for the front's Prometheus histograms."""

    compute_ms: float
    stage_ms: dict[str, float]
    stale: bool
    checkpoint_failed: bool = False  # its input could not be written to the checkpoint store


# request id (u32, wraps), op (u8, index in OPS), session id bytes (u16), payload bytes (u64)
REQUEST = struct.Struct("!IBHQ")
# request id, status (u8), flags (u8), compute_ms (f64), stages (u8), stage names bytes (u16), body bytes (u64)
REPLY = struct.Struct("!IBBdBHQ")
OPS = ("ping", "stop", "create", "frame", "style", "close", "take", "timeline", "amap", "drop", "view")
OP_CODES = {name: code for code, name in enumerate(OPS)}
HAS_METRICS, STALE, CHECKPOINT_FAILED = 1, 2, 4
READ_BUFFER_BYTES = 1 << 16  # the worker's read buffer: a frame request (~1 KB) arrives in one read
REQUEST_ID_MODULUS = 2**32


def encode_request(request_id: int, op: str, session_id: str, payload: bytes) -> list[bytes]:
    """The request's buffers in order (header, session id, payload), for a scatter write."""
    sid = session_id.encode()
    return [REQUEST.pack(request_id, OP_CODES[op], len(sid), len(payload)), sid, payload]


def encode_reply(request_id: int, status: int, body: bytes, metrics: FrameMetrics | None) -> bytes:
    if metrics is None:
        return REPLY.pack(request_id, status, 0, 0.0, 0, 0, len(body)) + body
    names = ",".join(metrics.stage_ms).encode("ascii")
    values = struct.pack(f"!{len(metrics.stage_ms)}d", *metrics.stage_ms.values())
    flags = HAS_METRICS | (STALE if metrics.stale else 0) | (CHECKPOINT_FAILED if metrics.checkpoint_failed else 0)
    return (
        REPLY.pack(request_id, status, flags, metrics.compute_ms, len(metrics.stage_ms), len(names), len(body))
        + names
        + values
        + body
    )


ReplyHeader = tuple[int, int, int, float, int, int, int]  # REPLY unpacked

_stage_names: dict[bytes, tuple[str, ...]] = {}  # a rig's stage names recur every frame: split once


def frame_metrics(flags: int, compute_ms: float, names_blob: bytes, values: tuple[float, ...]) -> FrameMetrics:
    """A reply's FrameMetrics from its flags, compute time, stage names' bytes and stage times."""
    names = _stage_names.get(names_blob)
    if names is None:
        names = _stage_names[names_blob] = tuple(names_blob.decode("ascii").split(",")) if names_blob else ()
    return FrameMetrics(compute_ms, dict(zip(names, values)), bool(flags & STALE), bool(flags & CHECKPOINT_FAILED))


def decode_reply_tail(header: ReplyHeader, tail: bytes) -> tuple[bytes, FrameMetrics | None]:
    """The body and metrics of a reply from its unpacked REPLY header and the bytes after it
    (stage names, their times, the body)."""
    _, _, flags, compute_ms, stages, names_len, _ = header
    if not flags & HAS_METRICS:
        return tail, None
    values = struct.unpack_from(f"!{stages}d", tail, names_len)
    body = tail[names_len + 8 * stages :]
    return body, frame_metrics(flags, compute_ms, tail[:names_len], values)


def tail_length(header: ReplyHeader) -> int:
    """How many bytes follow a REPLY header."""
    _, _, _, _, stages, names_len, body_len = header
    return names_len + 8 * stages + body_len


def read_exactly(reader: IO[bytes], n: int) -> bytes:
    data = reader.read(n)
    if len(data) < n:
        raise EOFError("the front closed the socket pair")
    return data


def read_request(reader: IO[bytes]) -> tuple[int, str, str, bytes]:
    """(request id, op, session id, payload) of the next request from a buffered reader of the
    socket (one read system call takes in a whole frame request, header and all); EOFError when
    the front has gone."""
    request_id, op, sid_len, payload_len = REQUEST.unpack(read_exactly(reader, REQUEST.size))
    session_id = read_exactly(reader, sid_len).decode()
    # read apart from the session id, not sliced off a joint read: a multi-GiB scene is not copied
    return request_id, OPS[op], session_id, read_exactly(reader, payload_len)


CREATE_TENANT = struct.Struct("!BB")  # 0 (no protobuf message begins so), tenant bytes (u8)


def encode_create(tenant: str, request: bytes) -> bytes:
    """A `create` op's payload: `tenant` (access/roles.py: at most 63 ASCII characters) and the
    client's serialized CreateSessionRequest (module docstring)."""
    name = tenant.encode("ascii")
    return CREATE_TENANT.pack(0, len(name)) + name + request


def decode_create(payload: bytes) -> tuple[str, bytes | memoryview]:
    """(tenant, serialized CreateSessionRequest) of a `create` op's payload; a bare request (one
    from before tenants) is tenant `default`'s. The request is a view into `payload`: a scene of
    gigabytes is not copied."""
    if not payload.startswith(b"\0"):
        return "default", payload
    _, length = CREATE_TENANT.unpack_from(payload)
    start = CREATE_TENANT.size
    return payload[start : start + length].decode("ascii"), memoryview(payload)[start + length :]


# -- a worker and its render process ----------------------------------------------------------

_MESSAGE_LENGTH = struct.Struct("!Q")


def write_message(stream: IO[bytes], message: object) -> None:
    """One length-prefixed pickle, flushed."""
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_MESSAGE_LENGTH.pack(len(data)) + data)
    stream.flush()


def read_message(stream: IO[bytes]) -> Any:
    """The next message, or None at end of file (or a message cut short by it). Any: whatever the
    other end wrote (both ends are camdirector's, and each knows what its peer sends)."""
    head = stream.read(_MESSAGE_LENGTH.size)
    if len(head) < _MESSAGE_LENGTH.size:
        return None
    (length,) = _MESSAGE_LENGTH.unpack(head)
    data = stream.read(length)
    if len(data) < length:
        return None
    return pickle.loads(data)  # noqa: S301 - both ends are camdirector's, over a private pipe


# -- a monitor's view ---------------------------------------------------------------------------

SHOTS = ("program", "candidate", "cut_before", "cut_after", "top")
FORMATS = ("jpeg", "png")
MIN_SIDE_PX = 16
MAX_WIDTH_PX = 1280  # a monitor is small: a larger picture is refused (the route answers 422)
MAX_HEIGHT_PX = 720
DEFAULT_WIDTH_PX = 320
_VIEW_HEADER = struct.Struct("!I")


@dataclass(frozen=True)
class ViewQuery:
    """A view asked for: which picture (render/snapshots.py says what each shows), its size and
    its image format. ValueError for one that is not allowed."""

    shot: str = "program"
    subjects: tuple[str, ...] = ()  # candidate: its players, in any order
    width_px: int = DEFAULT_WIDTH_PX  # [MIN_SIDE_PX, MAX_WIDTH_PX]; the top view ignores it
    height_px: int | None = None  # None: width / the lens's aspect; [MIN_SIDE_PX, MAX_HEIGHT_PX]
    image_format: str = "jpeg"  # FORMATS; the top view is always PNG

    def __post_init__(self) -> None:
        if self.shot not in SHOTS:
            raise ValueError(f"view shot must be one of {', '.join(SHOTS)}, got {self.shot!r}")
        if self.image_format not in FORMATS:
            raise ValueError(f"view format must be one of {', '.join(FORMATS)}, got {self.image_format!r}")
        if not MIN_SIDE_PX <= self.width_px <= MAX_WIDTH_PX:
            raise ValueError(f"view width must be in [{MIN_SIDE_PX}, {MAX_WIDTH_PX}] px, got {self.width_px}")
        if self.height_px is not None and not MIN_SIDE_PX <= self.height_px <= MAX_HEIGHT_PX:
            raise ValueError(f"view height must be in [{MIN_SIDE_PX}, {MAX_HEIGHT_PX}] px, got {self.height_px}")
        if self.shot == "candidate" and not self.subjects:
            raise ValueError("a candidate view names the candidate's players (subjects)")

    def to_json(self) -> bytes:
        return orjson.dumps(
            {
                "shot": self.shot,
                "subjects": list(self.subjects),
                "width_px": self.width_px,
                "height_px": self.height_px,
                "image_format": self.image_format,
            }
        )

    @classmethod
    def from_json(cls, payload: bytes) -> ViewQuery:
        try:
            fields = orjson.loads(payload)
            shot, subjects = str(fields["shot"]), tuple(str(s) for s in fields["subjects"])
            width_px = int(fields["width_px"])
            height_px = None if fields["height_px"] is None else int(fields["height_px"])
            image_format = str(fields["image_format"])
        except (orjson.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a view query: {exc}") from None
        return cls(shot=shot, subjects=subjects, width_px=width_px, height_px=height_px, image_format=image_format)


def encode_view(header: dict[str, Any], image: bytes) -> bytes:
    """A view's bytes (module docstring)."""
    meta = orjson.dumps(header)
    return _VIEW_HEADER.pack(len(meta)) + meta + image


def decode_view(body: bytes) -> tuple[dict[str, Any], bytes]:
    """(header, image) of a view's bytes (module docstring)."""
    (length,) = _VIEW_HEADER.unpack_from(body)
    start = _VIEW_HEADER.size
    header: dict[str, Any] = orjson.loads(body[start : start + length])
    return header, body[start + length :]
