"""What the sync and asyncio clients share: endpoint URLs, keys and TLS, the ZeroMQ envelope,
request builders.

ZeroMQ envelope (DEALER side, no delimiter frame): a request is the RPC name (``b"CreateSession"``,
``b"Frame"``, ``b"UpdateStyle"``, ``b"TakeShot"``, ``b"CloseSession"``), the serialized request
and, when the client has a key, a third frame ``b"Bearer KEY"``; the reply is two frames, the gRPC
status code in ASCII decimal (``b"0"`` = OK) and the serialized response, or a UTF-8 error message
when the code is not 0. Over gRPC the key is the ``authorization: Bearer KEY`` metadata of every
call (docs/security.md).
"""

from __future__ import annotations

import logging
import math
import os
import random
import re
import threading
import time
import uuid
from collections import deque
from collections.abc import AsyncIterable, AsyncIterator, Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple

import grpc
import numpy as np
import zmq
import zmq.auth
from zmq.utils import z85

from camdirector.v1 import director_pb2 as pb
from camdirector_client.errors import DirectorError

# each try again is logged at INFO with the error that caused it (a flaky network shows here)
log = logging.getLogger("camdirector_client")

__all__ = [
    "DEFAULT_MAX_MESSAGE_BYTES",
    "DEFAULT_RETRY",
    "DEFAULT_TIMEOUT_S",
    "Endpoint",
    "KEY_ENV",
    "PackedStates",
    "PlayerStatsLike",
    "RETRYABLE",
    "Backoff",
    "FrameDeadlines",
    "RetryPolicy",
    "Sent",
    "SentHistory",
    "Security",
    "States",
    "ClosedStub",
    "check_timeout",
    "create_session_request",
    "encode_frame_update",
    "frame_error",
    "frame_update",
    "grpc_channel_options",
    "open_dealer",
    "parse_url",
    "resend_from",
    "security",
    "style_msg",
    "with_session_id",
    "with_answered_frame",
    "with_session_id_async",
    "zmq_frame_timeout_s",
    "zmq_no_reply",
    "zmq_reply_payload",
]

DEFAULT_TIMEOUT_S = 10.0
"""Seconds a unary call waits for its reply before failing with DEADLINE_EXCEEDED."""

DEFAULT_MAX_MESSAGE_BYTES = 64 * 1024 * 1024
"""gRPC send and receive limit, bytes: scenes with meshes exceed gRPC's default 4 MiB."""

# gRPC metadata on every call of a session, CreateSession included: a balancer in front of many
# nodes routes by a consistent hash of it (docs/scaling.md), so a session's calls meet one node.
ROUTE_HEADER = "x-camdirector-route"
# The wire contract's revision this SDK speaks, sent on every gRPC call and, on every transport,
# as CreateSessionRequest.client_protocol: a server that speaks an older one refuses CreateSession
# with FAILED_PRECONDITION and says which (its own revision is in its initial metadata,
# camdirector-protocol, and in /healthz).
PROTOCOL_HEADER = "camdirector-protocol"
PROTOCOL = 1


def new_route_key() -> str:
    """A session's ROUTE_HEADER value, picked by the client before the session exists."""
    return uuid.uuid4().hex


# What a session's call or stream is tried again after, by the sync and asyncio clients alike:
# the server restoring the session (its worker was lost) answers UNAVAILABLE; a balancer whose
# node died resets the call's HTTP/2 stream, which gRPC reports as CANCELLED (a client cancels a
# call itself only when its caller has stopped reading it: nothing is left to retry then). A frame
# left unanswered for RetryPolicy.frame_timeout_s (a hung node) counts as UNAVAILABLE.
RETRYABLE = (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.CANCELLED)

_RESEND_FROM = re.compile(r"resend from (\d+)")


def resend_from(error: DirectorError) -> int | None:
    """The frame a DATA_LOSS answer asks the client to send again from ("state lost after frame N:
    resend from N+1": its node was lost while the checkpoint store was behind); None for any other
    error."""
    if error.code is not grpc.StatusCode.DATA_LOSS:
        return None
    found = _RESEND_FROM.search(error.message)
    return int(found.group(1)) if found else None


@dataclass(frozen=True, slots=True)
class RetryPolicy:
    """How a session rides out a lost node, a restarting balancer and a hung node.

    A call or stream that fails with a RETRYABLE code is tried again after waits that start near
    ``initial_backoff_s`` and double up to ``max_backoff_s``, each with equal jitter (half fixed,
    half drawn from ``random``), until ``retry_window_s`` has passed since its first failure; an
    answer starts the count again. A stream is opened again from its first unanswered update.
    """

    retry_window_s: float = 30.0  # a failing call is tried again until this long after its first failure, s
    initial_backoff_s: float = 0.1  # the first wait, s; each next one doubles
    max_backoff_s: float = 0.5  # the longest wait, s: a balancer back is found within it (and a connection made)
    # gRPC: a stream with frames in flight that answers nothing this long (FrameDeadlines), or a
    # unary Frame unanswered this long, means a hung node: the call is cancelled and tried again
    # (through a balancer, on a live node), s; None: frames wait forever on a stream, timeout_s on
    # a unary Frame. The last resort: a balancer's checks take a hung node out within 1.2 s and cut
    # its streams, and keepalive pings find a hung server reached directly
    # within 2 s; a frame that is only slow (a TRACKS session's first, a restore on a loaded
    # machine) can take over 1 s, and a cut would have it answered stale.
    frame_timeout_s: float | None = 3.0
    resend_history_frames: int = 600  # updates kept for a DATA_LOSS resend (10 s at 60 Hz)
    random: Callable[[], float] = random.random  # jitter in [0, 1); e.g. random.Random(seed).random

    def __post_init__(self) -> None:
        for name in ("retry_window_s", "initial_backoff_s", "max_backoff_s"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.frame_timeout_s is not None and not self.frame_timeout_s > 0.0:
            raise ValueError(f"frame_timeout_s must be > 0 or None, got {self.frame_timeout_s}")
        if self.resend_history_frames < 0:
            raise ValueError(f"resend_history_frames must be >= 0, got {self.resend_history_frames}")

    def grpc_options(self) -> dict[str, int]:
        """Channel arguments: the channel reconnects as often as calls are tried again (gRPC's own
        first wait is 1 s, growing to 120 s: a balancer back after 6 s was found after 10 s), and
        pings its server every second while a call is open, closing a connection that does not
        answer within a second."""
        return {
            "grpc.initial_reconnect_backoff_ms": max(1, round(self.initial_backoff_s * 1000.0)),
            "grpc.min_reconnect_backoff_ms": max(1, round(self.initial_backoff_s * 1000.0)),
            "grpc.max_reconnect_backoff_ms": max(1, round(self.max_backoff_s * 1000.0)),
            "grpc.keepalive_time_ms": 1000,
            "grpc.keepalive_timeout_ms": 1000,
        }


DEFAULT_RETRY = RetryPolicy()


class Backoff:
    """The waits of one call's tries after its first failure (made then); see RetryPolicy."""

    __slots__ = ("_clock", "_policy", "_started_s", "_tries")

    def __init__(self, policy: RetryPolicy, clock: Callable[[], float] = time.monotonic) -> None:
        self._policy = policy
        self._clock = clock
        self._started_s = clock()
        self._tries = 0

    def next_delay_s(self, at_once: bool = False) -> float | None:
        """The wait before the next try; None when the window is spent. ``at_once``: no wait (a
        DATA_LOSS resend), the window still counted."""
        left_s = self._policy.retry_window_s - (self._clock() - self._started_s)
        if left_s <= 0.0:
            return None
        if at_once:
            return 0.0
        cap_s = min(self._policy.max_backoff_s, self._policy.initial_backoff_s * 2.0**self._tries)
        self._tries += 1
        return min(left_s, cap_s * (0.5 + 0.5 * self._policy.random()))


class Sent(NamedTuple):
    """A frame update a session sent: its order among the session's updates, the frame of the one
    sent before it (0: none), its frame, and the update (a FrameUpdate, or its bytes)."""

    seq: int
    previous_frame: int
    frame: int
    update: Any


class SentHistory:
    """The frame updates a session sent, oldest first, up to ``limit`` of them: what it sends
    again when the server answers DATA_LOSS "resend from K". Shared by a session's unary calls
    and streams, from any thread."""

    __slots__ = ("_kept", "_last_frame", "_lock", "_seq", "_dropped_through")

    def __init__(self, limit: int) -> None:
        self._kept: deque[Sent] = deque(maxlen=limit)
        self._lock = threading.Lock()
        self._seq = 0
        self._last_frame = 0
        self._dropped_through = 0  # the newest frame sent and no longer kept (0: none)

    def add(self, frame: int, update: Any) -> Sent:
        """Keeps ``update``, the session's newest, and answers its entry."""
        with self._lock:
            self._seq += 1
            sent = Sent(self._seq, self._last_frame, frame, update)
            self._last_frame = frame
            if len(self._kept) == self._kept.maxlen:
                dropped = self._kept[0].frame if self._kept else frame
                self._dropped_through = max(self._dropped_through, dropped)
            self._kept.append(sent)
            return sent

    def since(self, frame: int, through_seq: int | None, error: DirectorError) -> list[Sent]:
        """The kept updates from ``frame`` on, up to sequence number ``through_seq`` (None: all); ``error``
        (the DATA_LOSS), with a word added, when an update from ``frame`` on is no longer kept."""
        with self._lock:
            if frame <= self._dropped_through:
                raise DirectorError(
                    error.code,
                    f"{error.message} (this client kept the last {self._kept.maxlen} updates it sent, "
                    f"resend_history_frames: frame {frame} is no longer among them)",
                )
            last = self._seq if through_seq is None else through_seq
            return [s for s in self._kept if s.seq <= last and s.frame >= frame]


def frame_error(error: DirectorError, frame_timeout_s: float) -> DirectorError:
    """A unary Frame's error, its deadline of ``frame_timeout_s`` passed taken as a hung node
    (UNAVAILABLE, tried again) rather than DEADLINE_EXCEEDED."""
    if error.code is not grpc.StatusCode.DEADLINE_EXCEEDED:
        return error
    return DirectorError(
        grpc.StatusCode.UNAVAILABLE,
        f"the frame was not answered within {frame_timeout_s:g} s (frame_timeout_s): the node may be hung",
    )


class FrameDeadlines:
    """When each frame in flight on a stream call was sent, oldest first, and when the last answer
    came: a hung node is one that, with frames in flight, answers nothing for ``timeout_s`` (since
    the oldest unanswered frame was sent or, if later, since its last answer). Not the oldest
    frame's age alone: a caller that sends faster than the server answers (a recorded match
    streamed unpaced) queues seconds of frames on a live node, and cutting its call then had frames
    it had answered resent and answered stale, a program with frames missing that differed from
    run to run (issue 41). Written by the thread or task sending and the one reading, read by the
    watchdog (deque appends and pops and a float's assignment are atomic)."""

    __slots__ = ("_answered_s", "_sent", "expired", "timeout_s")

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s
        self._sent: deque[tuple[float, int]] = deque()  # (time.monotonic() when sent, frame)
        self._answered_s = -math.inf  # time.monotonic() of the last answer
        self.expired: DirectorError | None = None  # set when a frame was left unanswered

    def sent(self, frame: int) -> None:
        self._sent.append((time.monotonic(), frame))

    def answered(self) -> None:
        self._answered_s = time.monotonic()
        if self._sent:
            self._sent.popleft()

    def wait_s(self) -> float:
        """How long until the call's deadline (the whole timeout when no frame is in flight); 0
        when it has passed, which sets ``expired``."""
        if not self._sent:
            return self.timeout_s
        sent_s, frame = self._sent[0]
        left_s = max(sent_s, self._answered_s) + self.timeout_s - time.monotonic()
        if left_s <= 0.0:
            self.expired = DirectorError(
                grpc.StatusCode.UNAVAILABLE,
                f"frame {frame} was not answered within {self.timeout_s:g} s (frame_timeout_s) of the last answer: "
                "the node may be hung",
            )
            return 0.0
        return left_s


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

PlayerStatsLike = pb.PlayerStats | Mapping[str, Any]
"""A ``RIG_MATCH`` player's scoreboard values: a ``PlayerStats`` message, or a mapping of its
fields (``id``, ``health``, ``armor``, ``items``, ``frags``; the ones left out are 0)."""


@dataclass(frozen=True, slots=True)
class Endpoint:
    """Where a client connects. ``address`` is a gRPC target ("host:port") or a ZeroMQ endpoint;
    ``tls``: gRPC over TLS (``grpcs://``)."""

    transport: Literal["grpc", "zmq"]
    address: str
    tls: bool = False


def parse_url(url: str) -> Endpoint:
    """``grpc://host:port`` (gRPC), ``grpcs://host:port`` (gRPC over TLS) or ``tcp://host:port``
    (ZeroMQ); ValueError otherwise."""
    scheme, sep, rest = url.partition("://")
    if not sep or not rest or ":" not in rest:
        raise ValueError(f"expected grpc://host:port, grpcs://host:port or tcp://host:port, got {url!r}")
    if scheme in ("grpc", "grpcs"):
        return Endpoint("grpc", rest, tls=scheme == "grpcs")
    if scheme == "tcp":
        return Endpoint("zmq", url)
    raise ValueError(f"unknown scheme {scheme!r} in {url!r}: use grpc:// (gRPC), grpcs:// (gRPC over TLS) or tcp:// (ZeroMQ)")


KEY_ENV = "CAMDIRECTOR_KEY"
"""The environment variable a client takes its key from when ``connect`` is given none."""

_CURVE_KEY_CHARS = 40  # a CURVE public key in Z85 text


class Security:
    """What a client proves and whom it trusts: the key (``authorization``, "Bearer KEY"), the
    roots a ``grpcs://`` channel checks the server's certificate against, and the ZeroMQ CURVE
    keys (the server's public key, this client's ephemeral pair).

    The key is a secret: this object's repr, and every message the SDK writes, leave it out."""

    __slots__ = ("_grpc_auth", "_zmq_frames", "credentials", "curve")

    def __init__(
        self,
        authorization: str | None,
        credentials: grpc.ChannelCredentials | None,
        curve: tuple[bytes, bytes, bytes] | None,
    ) -> None:
        self._grpc_auth: tuple[tuple[str, str], ...] = (("authorization", authorization),) if authorization else ()
        self._zmq_frames: tuple[bytes, ...] = (authorization.encode(),) if authorization else ()
        self.credentials = credentials  # None: a plaintext channel
        self.curve = curve  # (server public, client public, client secret), Z85; None: no CURVE

    def __repr__(self) -> str:
        return (
            f"Security(key={'set' if self._grpc_auth else 'none'}, tls={self.credentials is not None}, "
            f"curve={self.curve is not None})"
        )

    def grpc_metadata(self, route: str) -> tuple[tuple[str, str], ...]:
        """The metadata of a session's gRPC call: its route key (ROUTE_HEADER), the protocol this
        SDK speaks and the key."""
        return ((ROUTE_HEADER, route), (PROTOCOL_HEADER, str(PROTOCOL)), *self._grpc_auth)

    def zmq_request(self, rpc: bytes, payload: bytes) -> tuple[bytes, ...]:
        """A ZeroMQ request's frames: the RPC name, the payload and the key frame if any."""
        return (rpc, payload, *self._zmq_frames)

    def grpc_error(self, error: grpc.RpcError) -> DirectorError:
        """A failed gRPC call as a DirectorError, with a word on what to check when no connection
        could be made: gRPC's own details name a closed socket or a failed handshake, not the
        likely cause, TLS on one side only or a CA the client does not trust."""
        wrapped = DirectorError.from_rpc_error(error)
        hint = _connection_hint(wrapped, tls=self.credentials is not None)
        return wrapped if hint is None else DirectorError(wrapped.code, f"{wrapped.message} ({hint})")


def _connection_hint(error: DirectorError, *, tls: bool) -> str | None:
    if error.code is not grpc.StatusCode.UNAVAILABLE or not error.message.startswith("failed to connect"):
        return None  # the server's own answer, or a call cut short: it says what happened
    if "Connection refused" in error.message:
        return None
    said = error.message.lower().replace("_", " ")  # BoringSSL: CERTIFICATE_VERIFY_FAILED; OpenSSL 3: in words
    if not tls:
        return "the server closed the connection: if it serves TLS, connect with grpcs://"
    if "certificate verify failed" in said:
        return (
            "the server's certificate is not signed by an authority this client trusts: "
            "give ca_file, the PEM of the CA that signed it"
        )
    if "handshake" in said:
        return "the TLS handshake failed: does the server serve TLS (--tls-cert)? grpc:// is plaintext"
    return None


def security(
    endpoint: Endpoint,
    key: str | None,
    ca_file: str | os.PathLike[str] | None,
    zmq_server_key: str | bytes | os.PathLike[str] | None,
) -> Security:
    """The :class:`Security` of ``connect(url, key=..., ca_file=..., zmq_server_key=...)``.

    ``key`` None: the ``CAMDIRECTOR_KEY`` environment variable, if set and not empty. ValueError
    for an option that does not fit the URL's transport (a CA file for plaintext gRPC or ZeroMQ, a
    CURVE key for gRPC) and for a key a header can not carry."""
    source = "key"
    if key is None:
        key, source = os.environ.get(KEY_ENV) or None, f"the {KEY_ENV} environment variable"
    if key is not None:
        if not isinstance(key, str):
            raise TypeError(f"key must be a str, got {type(key).__name__}")
        if not key or not all("!" <= c <= "~" for c in key):  # what a header value may hold, no space
            raise ValueError(f"{source} must be non-empty printable ASCII without spaces (the key is not shown)")
    if ca_file is not None and not endpoint.tls:
        instead = "ZeroMQ is encrypted with CURVE: give zmq_server_key" if endpoint.transport == "zmq" else "use grpcs://"
        raise ValueError(f"ca_file is for grpcs:// URLs (gRPC over TLS); {instead}")
    if zmq_server_key is not None and endpoint.transport != "zmq":
        raise ValueError("zmq_server_key is for tcp:// URLs (ZeroMQ); gRPC is encrypted with TLS: use grpcs://")
    credentials = None
    if endpoint.tls:
        roots = None if ca_file is None else Path(ca_file).read_bytes()  # None: the system's roots
        credentials = grpc.ssl_channel_credentials(root_certificates=roots)
    curve = None
    if zmq_server_key is not None:
        if not zmq.has("curve"):
            raise RuntimeError("this libzmq was built without CURVE: it can not encrypt ZeroMQ (zmq_server_key)")
        curve = (_curve_server_key(zmq_server_key), *zmq.curve_keypair())
    return Security(f"Bearer {key}" if key is not None else None, credentials, curve)


def _curve_server_key(value: str | bytes | os.PathLike[str]) -> bytes:
    """The server's CURVE public key, Z85: ``value`` itself (40 characters), or read from the
    certificate file it names (the server's ``DIR/zmq/server.key``)."""
    if isinstance(value, (str, bytes)) and len(value) == _CURVE_KEY_CHARS and not os.path.exists(value):
        text = value.encode("ascii", errors="replace") if isinstance(value, str) else value
        try:
            z85.decode(text)
        except (KeyError, ValueError):  # KeyError: a character outside Z85's alphabet
            raise ValueError("zmq_server_key is 40 characters long but not Z85 text") from None
        return text
    if not os.path.isfile(value):
        raise ValueError(
            f"zmq_server_key must be the server's CURVE public key (40 characters of Z85 text) or "
            f"the path of its server.key file; {os.fsdecode(value)!r} is neither"
        )
    public, _secret = zmq.auth.load_certificate(value)
    return public


def open_dealer(context: zmq.Context, endpoint: str, timeout_ms: int, curve: tuple[bytes, bytes, bytes] | None):
    """A DEALER socket of ``context`` (sync or asyncio), LINGER 0, with send and receive timeouts
    of ``timeout_ms`` (zmq.asyncio honours them too: a wait past them raises zmq.Again), a CURVE
    client of the server when ``curve`` is given, connecting to ``endpoint``."""
    sock = context.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, timeout_ms)
    sock.setsockopt(zmq.SNDTIMEO, timeout_ms)
    if curve is not None:
        sock.curve_serverkey, sock.curve_publickey, sock.curve_secretkey = curve
    sock.connect(endpoint)
    return sock


def zmq_frame_timeout_s(timeout_s: float, retry: RetryPolicy) -> float | None:
    """How long a ZeroMQ Frame waits for its reply before its node is taken as hung: the retry
    policy's ``frame_timeout_s`` when shorter than the client's ``timeout_s``; None: ``timeout_s``."""
    hang_s = retry.frame_timeout_s
    return hang_s if hang_s is not None and hang_s < timeout_s else None


def zmq_no_reply(rpc: bytes, endpoint: str, timeout_s: float, curve: bool, frame_timeout_s: float | None = None) -> DirectorError:
    """DEADLINE_EXCEEDED for a ZeroMQ request left unanswered; for a Frame that waited
    ``frame_timeout_s``, UNAVAILABLE (frame_error: a hung node, tried again). A CURVE server drops
    a client that does not know its key (or a plaintext one) without a word, so the message says
    what to check: a session is created first, so a wrong key shows there."""
    if frame_timeout_s is not None:
        return frame_error(DirectorError(grpc.StatusCode.DEADLINE_EXCEEDED, ""), frame_timeout_s)
    hint = (
        "is zmq_server_key the server's public key?"
        if curve
        else "a server with authentication on answers only clients given its CURVE key (zmq_server_key)"
    )
    return DirectorError(
        grpc.StatusCode.DEADLINE_EXCEEDED,
        f"no reply to {rpc.decode()} from {endpoint} within {timeout_s:g} s ({hint})",
    )


def grpc_channel_options(
    max_message_bytes: int, extra: Sequence[tuple[str, Any]] | None, retry: RetryPolicy = DEFAULT_RETRY
) -> list[tuple[str, Any]]:
    if max_message_bytes <= 0:
        raise ValueError(f"max_message_bytes must be > 0, got {max_message_bytes}")
    options: dict[str, Any] = {
        "grpc.max_send_message_length": max_message_bytes,
        "grpc.max_receive_message_length": max_message_bytes,
        # each client its own connections: with gRPC's process-wide pool a new client took over
        # another's connection to the same address while it waited to reconnect, and a server
        # started since on that port (a node restarted, a port given out again) was refused
        "grpc.use_local_subchannel_pool": 1,
        **retry.grpc_options(),
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
    """``request``, or one built from the keywords; TypeError when given both. Its
    ``client_protocol`` says this SDK's PROTOCOL where it was 0 (not said): set on the caller's
    message, which is not copied (a scene of meshes is large). ``level_id``: the level of a
    ``RIG_TRACKS`` or ``RIG_MATCH`` session; ``delay_s``: a ``RIG_MATCH`` session's broadcast
    delay, seconds."""
    if request is not None:
        if (
            objects is not None
            or targets is not None
            or lens is not None
            or style is not None
            or seed
            or record
            or level_id
            or delay_s
        ):
            raise TypeError("pass either a CreateSessionRequest or keywords, not both")
        if not request.client_protocol:
            request.client_protocol = PROTOCOL
        return request
    msg = pb.CreateSessionRequest(seed=seed, record=record, level_id=level_id, delay_s=delay_s, client_protocol=PROTOCOL)
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
    player_stats: Iterable[PlayerStatsLike] | None = None,
) -> pb.FrameUpdate:
    """One ``FrameUpdate``; ``states`` and ``packed`` may both be given; ``player_stats``: the
    ``RIG_MATCH`` players whose scoreboard values changed since the last frame."""
    msg = _frame_update_head(session_id, frame, time_s, states, player_stats)
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
    player_stats: Iterable[PlayerStatsLike] | None = None,
) -> bytes:
    """``frame_update(...).SerializeToString()``, cheaper: the packed transforms are copied as
    raw little-endian doubles (protobuf's packed encoding) instead of going through Python floats.

    Protobuf parsers merge fields in any order and concatenate the chunks of a packed repeated
    field, so the serialized head followed by field 6 parses as the one message.
    """
    msg = _frame_update_head(session_id, frame, time_s, states, player_stats)
    if packed is None:
        return msg.SerializeToString()
    ids, transforms = packed
    msg.packed_ids.extend(ids)
    body = _packed_doubles(len(msg.packed_ids), transforms).tobytes()
    if not body:
        return msg.SerializeToString()
    return b"".join((msg.SerializeToString(), _PACKED_TRANSFORMS_TAG, _varint(len(body)), body))


_PACKED_TRANSFORMS_TAG = bytes([6 << 3 | 2])  # FrameUpdate.packed_transforms, length-delimited
_ANSWERED_FRAME_TAG = bytes([9 << 3 | 0])  # FrameUpdate.answered_frame, varint


def with_answered_frame(payload: bytes, answered_frame: int) -> bytes:
    """A serialized FrameUpdate with ``answered_frame`` set: a scalar field given twice takes its
    last value, so the field is appended (nothing when 0, the default)."""
    return payload + _ANSWERED_FRAME_TAG + _varint(answered_frame) if answered_frame else payload


_LITTLE_ENDIAN_DOUBLE = np.dtype("<f8")


def _varint(value: int) -> bytes:
    out = bytearray()
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _frame_update_head(
    session_id: str, frame: int, time_s: float, states: States | None, player_stats: Iterable[PlayerStatsLike] | None = None
) -> pb.FrameUpdate:
    msg = pb.FrameUpdate(session_id=session_id, frame=frame, time_s=time_s)
    if player_stats is not None:
        msg.player_stats.extend(s if isinstance(s, pb.PlayerStats) else pb.PlayerStats(**s) for s in player_stats)
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
        The recording's name in the server's recordings folder (``<session id>.cdrec``, never a
        path on the server); empty unless ``record=True`` and it records.
    """

    __slots__ = (
        "_answered_seq",
        "_closed_frames",
        "_transport",
        "answered_frame",
        "history",
        "id",
        "recording_path",
        "retries",
        "retry",
        "route",
    )

    def __init__(
        self, transport, response: pb.CreateSessionResponse, route: str = "", retry: RetryPolicy = DEFAULT_RETRY
    ) -> None:
        self._transport = transport
        self.id: str = response.session_id
        self.recording_path: str = response.recording_path
        self.route = route  # the ROUTE_HEADER key of every call of this session (new_route_key)
        self.retry = retry
        self.retries = 0  # calls and streams tried again (UNAVAILABLE, CANCELLED, DATA_LOSS)
        self.history = SentHistory(retry.resend_history_frames)
        self.answered_frame = 0  # the frame of the newest answer given to the application
        self._answered_seq = 0  # the SentHistory sequence number of that answer's update
        self._closed_frames: int | None = None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(id={self.id!r}, closed={self._closed_frames is not None})"

    def _retry_after(self, error: DirectorError, backoff: Backoff | None) -> tuple[float, Backoff]:
        """How long to wait before trying again after ``error``, and the backoff of the call's
        tries (``backoff``, or one started now, at the first failure), the retry counted; raises
        ``error`` instead when it is not RETRYABLE nor a DATA_LOSS to resend, the retry window is
        spent, or the client is closed (its CANCELLED is its own)."""
        data_loss = resend_from(error) is not None
        if (error.code not in RETRYABLE and not data_loss) or self._transport.closed:
            raise error
        backoff = backoff or Backoff(self.retry)
        delay = backoff.next_delay_s(at_once=data_loss)
        if delay is None:
            raise error
        self.retries += 1
        log.info("session %s: %s; trying again in %.3f s", self.id, error, delay)
        return delay, backoff

    def _to_send(self, sent: Sent) -> int:
        """The answered_frame a sent update carries: the newest answer received, but never past
        the update sent before it (resent after DATA_LOSS, it says where the session stood when
        it was first sent)."""
        return min(self.answered_frame, sent.previous_frame)

    def _frame_request(self, sent: Sent) -> tuple[Callable[..., Any], Any]:
        """The transport's unary Frame method and its argument for ``sent``, answered_frame set."""
        answered = self._to_send(sent)
        if isinstance(sent.update, bytes):
            return self._transport.frame_encoded, with_answered_frame(sent.update, answered)
        sent.update.answered_frame = answered
        return self._transport.frame, sent.update

    def _resend(self, error: DirectorError, through_seq: int | None = None) -> list[Sent] | None:
        """After ``error``: the updates to send again from a DATA_LOSS's "resend from K", up to
        sequence number ``through_seq`` (the call's newest; None: all); None when it asks for none. Raises
        ``error`` when an update from K on is no longer kept."""
        frame = resend_from(error)
        return None if frame is None else self.history.since(frame, through_seq, error) or None

    def _take_answer(self, sent: Sent, reply: pb.CameraUpdate) -> bool:
        """Notes the answer to ``sent``; False when the application already had it (a resend
        after DATA_LOSS) and it is to be dropped."""
        if sent.seq <= self._answered_seq:
            return False
        self._answered_seq, self.answered_frame = sent.seq, reply.frame
        return True

    def frame_update(
        self,
        frame: int,
        time_s: float,
        *,
        states: States | None = None,
        packed: PackedStates | None = None,
        player_stats: Iterable[PlayerStatsLike] | None = None,
    ) -> pb.FrameUpdate:
        """A ``FrameUpdate`` for this session, e.g. to feed ``stream``; ``player_stats``: see
        :meth:`camdirector_client.Session.frame`."""
        return frame_update(self.id, frame, time_s, states, packed, player_stats)
