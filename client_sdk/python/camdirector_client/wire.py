"""What the sync and asyncio clients share: endpoint URLs, the ZeroMQ envelope, request builders.

ZeroMQ envelope (DEALER side, no delimiter frame): a request is two frames, the RPC name
(``b"CreateSession"``, ``b"Frame"``, ``b"UpdateStyle"``, ``b"CloseSession"``) and the serialized
request; the reply is two frames, the gRPC status code in ASCII decimal (``b"0"`` = OK) and the
serialized response, or a UTF-8 error message when the code is not 0.
"""

from __future__ import annotations

import uuid
from collections.abc import AsyncIterable, AsyncIterator, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import grpc
import numpy as np

from camdirector.v1 import director_pb2 as pb
from camdirector_client.errors import DirectorError

__all__ = [
    "DEFAULT_MAX_MESSAGE_BYTES",
    "DEFAULT_TIMEOUT_S",
    "Endpoint",
    "PackedStates",
    "RETRYABLE",
    "States",
    "ClosedStub",
    "check_timeout",
    "create_session_request",
    "encode_frame_update",
    "frame_update",
    "grpc_channel_options",
    "parse_url",
    "retry_delays_s",
    "style_msg",
    "with_session_id",
    "with_session_id_async",
    "zmq_reply_payload",
]

DEFAULT_TIMEOUT_S = 10.0
"""Seconds a unary call waits for its reply before failing with DEADLINE_EXCEEDED."""

DEFAULT_MAX_MESSAGE_BYTES = 64 * 1024 * 1024
"""gRPC send and receive limit, bytes: scenes with meshes exceed gRPC's default 4 MiB."""

# gRPC metadata on every call of a session, CreateSession included: a balancer in front of many
# nodes routes by a consistent hash of it (docs/scaling.md), so a session's calls meet one node.
ROUTE_HEADER = "x-camdirector-route"


def new_route_key() -> str:
    """A session's ROUTE_HEADER value, picked by the client before the session exists."""
    return uuid.uuid4().hex


# What a session's call or stream is tried again after, by the sync and asyncio clients alike:
# the server restoring the session (its worker was lost) answers UNAVAILABLE; a balancer whose
# node died resets the call's HTTP/2 stream, which gRPC reports as CANCELLED (a client cancels a
# call itself only when its caller has stopped reading it: nothing is left to retry then).
RETRYABLE = (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.CANCELLED)


def retry_delays_s() -> Iterator[float]:
    """Waits before the tries after a RETRYABLE answer: the server is restoring the session (its
    worker or node was lost) or restarting; about 3 s in all."""
    yield from (0.02, 0.05, 0.1, 0.2, 0.4, 0.8, 1.5)


RPC_CREATE_SESSION = b"CreateSession"
RPC_FRAME = b"Frame"
RPC_UPDATE_STYLE = b"UpdateStyle"
RPC_CLOSE_SESSION = b"CloseSession"
RPC_TAKE_SHOT = b"TakeShot"
ZMQ_OK = b"0"

States = Iterable[pb.ObjectState] | Mapping[str, pb.Transform]
"""Object states of one frame: ``ObjectState`` messages, or transforms by id."""

PackedStates = tuple[Sequence[str], Any]
"""``(packed_ids, packed_transforms)`` as :func:`camdirector_client.convert.pack_states` returns
them: n ids and n * 10 doubles (an ndarray, (n, 10) or flat, or a sequence of floats)."""


@dataclass(frozen=True, slots=True)
class Endpoint:
    """Where a client connects. ``address`` is a gRPC target ("host:port") or a ZeroMQ endpoint."""

    transport: Literal["grpc", "zmq"]
    address: str


def parse_url(url: str) -> Endpoint:
    """``grpc://host:port`` (gRPC) or ``tcp://host:port`` (ZeroMQ); ValueError otherwise."""
    scheme, sep, rest = url.partition("://")
    if not sep or not rest or ":" not in rest:
        raise ValueError(f"expected grpc://host:port or tcp://host:port, got {url!r}")
    if scheme == "grpc":
        return Endpoint("grpc", rest)
    if scheme == "tcp":
        return Endpoint("zmq", url)
    raise ValueError(f"unknown scheme {scheme!r} in {url!r}: use grpc:// (gRPC) or tcp:// (ZeroMQ)")


def grpc_channel_options(
    max_message_bytes: int, extra: Sequence[tuple[str, Any]] | None
) -> list[tuple[str, Any]]:
    if max_message_bytes <= 0:
        raise ValueError(f"max_message_bytes must be > 0, got {max_message_bytes}")
    options: dict[str, Any] = {
        "grpc.max_send_message_length": max_message_bytes,
        "grpc.max_receive_message_length": max_message_bytes,
    }
    options.update(extra or ())
    return list(options.items())


def check_timeout(timeout_s: float) -> float:
    timeout_s = float(timeout_s)
    if not timeout_s > 0.0:
        raise ValueError(f"timeout_s must be > 0, got {timeout_s}")
    return timeout_s


def create_session_request(
    request: pb.CreateSessionRequest | None,
    *,
    objects: Iterable[pb.SceneObject] | None,
    targets: Iterable[pb.Target] | None,
    lens: pb.Lens | None,
    style: pb.Style | Mapping[str, Any] | None,
    seed: int,
    record: bool,
    level_id: str = "",
    delay_s: float = 0.0,
) -> pb.CreateSessionRequest:
    """``request`` as it is, or one built from the keywords; TypeError when given both.
    ``level_id``: the level of a ``RIG_TRACKS`` or ``RIG_MATCH`` session; ``delay_s``: a
    ``RIG_MATCH`` session's broadcast delay, seconds."""
    if request is not None:
        if (objects is not None or targets is not None or lens is not None or style is not None or seed or record
                or level_id or delay_s):
            raise TypeError("pass either a CreateSessionRequest or keywords, not both")
        return request
    msg = pb.CreateSessionRequest(seed=seed, record=record, level_id=level_id, delay_s=delay_s)
    if objects is not None:
        msg.objects.extend(objects)
    if targets is not None:
        msg.targets.extend(targets)
    if lens is not None:
        msg.lens.CopyFrom(lens)
    if style is not None:
        msg.style.CopyFrom(style_msg(style))
    return msg


def take_shot_request(session_id: str, subject_ids: Iterable[str], kind: int, release: bool) -> pb.TakeShotRequest:
    """A ``TakeShotRequest``: hold ``subject_ids`` as ``kind`` (a ``pb.ShotKind``; 0: by their
    count), or give the program back to the director with ``release``."""
    return pb.TakeShotRequest(session_id=session_id, subject_ids=list(subject_ids), kind=kind, release=release)


def style_msg(style: pb.Style | Mapping[str, Any]) -> pb.Style:
    """A ``Style`` as it is, or one built from a mapping of its fields."""
    return style if isinstance(style, pb.Style) else pb.Style(**style)


def frame_update(
    session_id: str,
    frame: int,
    time_s: float,
    states: States | None = None,
    packed: PackedStates | None = None,
) -> pb.FrameUpdate:
    """One ``FrameUpdate``; ``states`` and ``packed`` may both be given."""
    msg = _frame_update_head(session_id, frame, time_s, states)
    if packed is not None:
        ids, transforms = packed
        msg.packed_ids.extend(ids)
        msg.packed_transforms.extend(_packed_doubles(len(msg.packed_ids), transforms).tolist())
    return msg


def encode_frame_update(
    session_id: str,
    frame: int,
    time_s: float,
    states: States | None = None,
    packed: PackedStates | None = None,
) -> bytes:
    """``frame_update(...).SerializeToString()``, cheaper: the packed transforms are copied as
    raw little-endian doubles (protobuf's packed encoding) instead of going through Python floats.

    Protobuf parsers merge fields in any order and concatenate the chunks of a packed repeated
    field, so the serialized head followed by field 6 parses as the one message.
    """
    msg = _frame_update_head(session_id, frame, time_s, states)
    if packed is None:
        return msg.SerializeToString()
    ids, transforms = packed
    msg.packed_ids.extend(ids)
    body = _packed_doubles(len(msg.packed_ids), transforms).tobytes()
    if not body:
        return msg.SerializeToString()
    return b"".join((msg.SerializeToString(), _PACKED_TRANSFORMS_TAG, _varint(len(body)), body))


_PACKED_TRANSFORMS_TAG = bytes([6 << 3 | 2])  # FrameUpdate.packed_transforms, length-delimited
_LITTLE_ENDIAN_DOUBLE = np.dtype("<f8")


def _varint(value: int) -> bytes:
    out = bytearray()
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _frame_update_head(session_id: str, frame: int, time_s: float, states: States | None) -> pb.FrameUpdate:
    msg = pb.FrameUpdate(session_id=session_id, frame=frame, time_s=time_s)
    if states is not None:
        if isinstance(states, Mapping):
            add = msg.states.add
            for object_id, transform in states.items():
                add(id=object_id, transform=transform)
        else:
            msg.states.extend(states)
    return msg


def _packed_doubles(n_ids: int, transforms: Any) -> np.ndarray:
    """``transforms`` as a flat little-endian float64 array of 10 doubles per id."""
    doubles = np.asarray(transforms, dtype=_LITTLE_ENDIAN_DOUBLE).reshape(-1)
    if doubles.size != 10 * n_ids:
        raise ValueError(f"{n_ids} packed ids need {10 * n_ids} doubles, got {doubles.size}")
    return doubles


def with_session_id(updates: Iterable[pb.FrameUpdate], session_id: str) -> Iterator[pb.FrameUpdate]:
    """``updates``, each with ``session_id`` set where it was empty (the message is changed)."""
    for update in updates:
        if not update.session_id:
            update.session_id = session_id
        yield update


async def with_session_id_async(
    updates: Iterable[pb.FrameUpdate] | AsyncIterable[pb.FrameUpdate], session_id: str
) -> AsyncIterator[pb.FrameUpdate]:
    """Async form of :func:`with_session_id`, over a sync or async iterable."""
    if isinstance(updates, AsyncIterable):
        async for update in updates:
            if not update.session_id:
                update.session_id = session_id
            yield update
    else:
        for update in updates:
            if not update.session_id:
                update.session_id = session_id
            yield update


def zmq_reply_payload(reply: list[bytes]) -> bytes:
    """The response bytes of a ZeroMQ reply; DirectorError for an error reply or a broken one."""
    if len(reply) != 2:
        raise DirectorError(grpc.StatusCode.INTERNAL, f"malformed reply: {len(reply)} frames, expected 2")
    code, payload = reply
    if code != ZMQ_OK:
        raise DirectorError.from_zmq_reply(code, payload)
    return payload


class ClosedStub:
    """Stands in for a closed client's gRPC stub: any RPC raises DirectorError(CANCELLED), as a
    closed ZeroMQ client does (grpc itself would raise ValueError)."""

    def __getattr__(self, name: str) -> ClosedStub:
        return self

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        raise DirectorError(grpc.StatusCode.CANCELLED, "the client is closed")


class SessionBase:
    """What the sync and async sessions share: the id, the recording path and message building.

    Attributes
    ----------
    id : str
        The session id the server chose.
    recording_path : str
        Where the server records the session; empty unless ``record=True`` and it records.
    """

    __slots__ = ("_closed_frames", "_transport", "id", "recording_path", "retries", "route")

    def __init__(self, transport, response: pb.CreateSessionResponse, route: str = "") -> None:
        self._transport = transport
        self.id: str = response.session_id
        self.recording_path: str = response.recording_path
        self.route = route        # the ROUTE_HEADER key of every call of this session (new_route_key)
        self.retries = 0          # calls and streams tried again after UNAVAILABLE (the server restoring the session)
        self._closed_frames: int | None = None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(id={self.id!r}, closed={self._closed_frames is not None})"

    def _retry_after(self, error: DirectorError, delays: Iterator[float]) -> float:
        """How long to wait before trying again after `error` (from retry_delays_s), the retry
        counted; raises `error` instead when it is not RETRYABLE, the tries are used up, or the
        client is closed (its CANCELLED is its own)."""
        delay = None if error.code not in RETRYABLE or self._transport.closed else next(delays, None)
        if delay is None:
            raise error
        self.retries += 1
        return delay

    def frame_update(
        self,
        frame: int,
        time_s: float,
        *,
        states: States | None = None,
        packed: PackedStates | None = None,
    ) -> pb.FrameUpdate:
        """A ``FrameUpdate`` for this session, e.g. to feed ``stream``."""
        return frame_update(self.id, frame, time_s, states, packed)
