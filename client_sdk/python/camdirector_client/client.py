"""The synchronous client, over gRPC (``grpc://host:port``, ``grpcs://host:port`` over TLS) or
ZeroMQ (``tcp://host:port``).

    with connect("grpc://127.0.0.1:50051", key=KEY) as client:
        with client.create_session(targets=[...], style=...) as session:
            update = session.frame(1, 0.016, packed=pack_states(ids, positions, rotations))

A :class:`Client` is safe to share between threads. Over gRPC it holds one channel; over ZeroMQ
it holds a small pool of DEALER sockets, each with at most one request outstanding, so
concurrent calls from several threads each get a socket of their own.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator, Mapping, Sequence
from types import TracebackType
from typing import Any, Protocol

import grpc
import zmq

from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc
from camdirector_client import wire
from camdirector_client.errors import DirectorError

__all__ = ["Client", "Session", "connect"]

_IDLE_SOCKETS = 8  # ZeroMQ sockets a client keeps open for reuse
_FRAME_METHOD = "/camdirector.v1.Director/Frame"


class _Transport(Protocol):
    """Every call of a session carries its `route` key (wire.ROUTE_HEADER over gRPC; ZeroMQ
    talks to one node and needs none)."""

    def create_session(self, request: pb.CreateSessionRequest, route: str) -> pb.CreateSessionResponse: ...
    def frame(self, update: pb.FrameUpdate, route: str) -> pb.CameraUpdate: ...
    def frame_encoded(self, update: bytes, route: str) -> pb.CameraUpdate: ...
    def stream(self, updates: Iterable[pb.FrameUpdate], route: str) -> Iterator[pb.CameraUpdate]: ...
    def update_style(self, request: pb.UpdateStyleRequest, route: str) -> pb.UpdateStyleResponse: ...
    def close_session(self, request: pb.CloseSessionRequest, route: str) -> pb.CloseSessionResponse: ...
    def take_shot(self, request: pb.TakeShotRequest, route: str) -> pb.TakeShotResponse: ...
    @property
    def closed(self) -> bool: ...
    def close(self) -> None: ...


class _GrpcTransport:
    """Unary RPCs with a deadline of ``timeout_s``; StreamFrames without one. A unary frame left
    unanswered for ``retry.frame_timeout_s`` (when shorter), or a stream that answers none of its
    frames in flight for that long (wire.FrameDeadlines), ends its call with UNAVAILABLE: a hung
    node, to be tried again. Every call carries the session's route key and
    the client's key (``wire.Security.grpc_metadata``)."""

    def __init__(
        self,
        target: str,
        timeout_s: float,
        options: list[tuple[str, Any]],
        security: wire.Security,
        retry: wire.RetryPolicy = wire.DEFAULT_RETRY,
    ) -> None:
        if security.credentials is None:
            self._channel = grpc.insecure_channel(target, options=options)
        else:
            self._channel = grpc.secure_channel(target, security.credentials, options=options)
        self._security = security
        self._stub = director_pb2_grpc.DirectorStub(self._channel)
        # Frame again, taking a FrameUpdate already serialized (wire.encode_frame_update).
        self._frame_encoded = self._channel.unary_unary(
            _FRAME_METHOD, response_deserializer=pb.CameraUpdate.FromString, _registered_method=True
        )
        self._timeout_s = timeout_s
        self._frame_timeout_s = retry.frame_timeout_s

    def _unary(self, method, request, route: str):
        try:
            return method(request, timeout=self._timeout_s, metadata=self._security.grpc_metadata(route))
        except grpc.RpcError as error:
            raise self._security.grpc_error(error) from None

    def _frame(self, method, request, route: str) -> pb.CameraUpdate:
        hang_s = self._frame_timeout_s
        if hang_s is None or hang_s >= self._timeout_s:
            return self._unary(method, request, route)
        try:
            return method(request, timeout=hang_s, metadata=self._security.grpc_metadata(route))
        except grpc.RpcError as error:
            raise wire.frame_error(self._security.grpc_error(error), hang_s) from None

    def create_session(self, request: pb.CreateSessionRequest, route: str) -> pb.CreateSessionResponse:
        return self._unary(self._stub.CreateSession, request, route)

    def frame(self, update: pb.FrameUpdate, route: str) -> pb.CameraUpdate:
        return self._frame(self._stub.Frame, update, route)

    def frame_encoded(self, update: bytes, route: str) -> pb.CameraUpdate:
        return self._frame(self._frame_encoded, update, route)

    def stream(self, updates: Iterable[pb.FrameUpdate], route: str) -> Iterator[pb.CameraUpdate]:
        deadlines = None if self._frame_timeout_s is None else wire.FrameDeadlines(self._frame_timeout_s)
        pump = _RequestPump(updates, deadlines)
        call = self._stub.StreamFrames(iter(pump), metadata=self._security.grpc_metadata(route))
        watched = threading.Event()  # set: the stream is over, the watchdog stops
        if deadlines is not None:
            threading.Thread(target=_watch, args=(call, deadlines, watched), name="camdirector-frame-watch", daemon=True).start()
        try:
            for reply in call:
                if deadlines is not None:
                    deadlines.answered()
                yield reply
        except grpc.RpcError as error:
            if pump.error is not None:  # the caller's iterator failed: grpc only saw a cancel
                raise pump.error from None
            if deadlines is not None and deadlines.expired is not None:  # the watchdog cancelled it
                raise deadlines.expired from None
            raise self._security.grpc_error(error) from None
        finally:
            watched.set()
            call.cancel()
        if pump.error is not None:
            raise pump.error

    def update_style(self, request: pb.UpdateStyleRequest, route: str) -> pb.UpdateStyleResponse:
        return self._unary(self._stub.UpdateStyle, request, route)

    def close_session(self, request: pb.CloseSessionRequest, route: str) -> pb.CloseSessionResponse:
        return self._unary(self._stub.CloseSession, request, route)

    def take_shot(self, request: pb.TakeShotRequest, route: str) -> pb.TakeShotResponse:
        return self._unary(self._stub.TakeShot, request, route)

    @property
    def closed(self) -> bool:
        return isinstance(self._stub, wire.ClosedStub)

    def close(self) -> None:
        self._stub = self._frame_encoded = wire.ClosedStub()
        self._channel.close()


def _watch(call: grpc.Future, deadlines: wire.FrameDeadlines, over: threading.Event) -> None:
    """Cancels ``call`` when a frame on it is left unanswered past its deadline (a hung node)."""
    while not over.wait(deadlines.wait_s()):
        if deadlines.expired is not None:
            call.cancel()
            return


class _RequestPump:
    """Iterates the caller's updates on grpc's thread, noting when each is sent (``deadlines``),
    and keeps what they raised, if anything."""

    def __init__(self, updates: Iterable[pb.FrameUpdate], deadlines: wire.FrameDeadlines | None = None) -> None:
        self._updates = updates
        self._deadlines = deadlines
        self.error: BaseException | None = None

    def __iter__(self) -> Iterator[pb.FrameUpdate]:
        try:
            for update in self._updates:
                if self._deadlines is not None:
                    self._deadlines.sent(update.frame)
                yield update
        except Exception as error:
            self.error = error
            raise


class _ZmqTransport:
    """Request/reply over DEALER sockets: one request outstanding per socket, LINGER 0.

    A socket that timed out (or was interrupted) while waiting is closed, never reused, so a late
    reply can not be taken for the answer to a later request. A frame waits
    ``retry.frame_timeout_s`` when shorter, then UNAVAILABLE: a hung node, tried again.
    """

    def __init__(
        self,
        endpoint: str,
        timeout_s: float,
        context: zmq.Context | None,
        security: wire.Security,
        retry: wire.RetryPolicy = wire.DEFAULT_RETRY,
    ) -> None:
        self._endpoint = endpoint
        self._frame_timeout_s = wire.zmq_frame_timeout_s(timeout_s, retry)
        self._timeout_s = timeout_s
        self._timeout_ms = max(1, round(timeout_s * 1000.0))
        self._context = context if context is not None else zmq.Context.instance()
        self._security = security
        self._idle: list[zmq.Socket] = [self._open()]
        self._closed = False  # list.pop and list.append are atomic: the pool needs no lock

    def _open(self) -> zmq.Socket:
        return wire.open_dealer(self._context, self._endpoint, self._timeout_ms, self._security.curve)

    def _request(self, rpc: bytes, payload: bytes) -> bytes:
        if self._closed:
            raise DirectorError(grpc.StatusCode.CANCELLED, "the client is closed")
        try:
            sock = self._idle.pop()
        except IndexError:
            sock = self._open()
        hang_s = self._frame_timeout_s if rpc == wire.RPC_FRAME else None
        try:
            sock.rcvtimeo = self._timeout_ms if hang_s is None else max(1, round(hang_s * 1000.0))
            sock.send_multipart(self._security.zmq_request(rpc, payload))
            reply = sock.recv_multipart()
        except zmq.Again:
            sock.close(linger=0)
            if not self._closed:  # a fresh socket, already connecting, for the next call
                self._idle.append(self._open())
            raise wire.zmq_no_reply(rpc, self._endpoint, self._timeout_s, self._security.curve is not None, hang_s) from None
        except BaseException:
            sock.close(linger=0)
            raise
        if self._closed or len(self._idle) >= _IDLE_SOCKETS:
            sock.close(linger=0)
        else:
            self._idle.append(sock)
        return wire.zmq_reply_payload(reply)

    def create_session(self, request: pb.CreateSessionRequest, route: str) -> pb.CreateSessionResponse:
        reply = self._request(wire.RPC_CREATE_SESSION, request.SerializeToString())
        return pb.CreateSessionResponse.FromString(reply)

    def frame(self, update: pb.FrameUpdate, route: str) -> pb.CameraUpdate:
        return pb.CameraUpdate.FromString(self._request(wire.RPC_FRAME, update.SerializeToString()))

    def frame_encoded(self, update: bytes, route: str) -> pb.CameraUpdate:
        return pb.CameraUpdate.FromString(self._request(wire.RPC_FRAME, update))

    def stream(self, updates: Iterable[pb.FrameUpdate], route: str) -> Iterator[pb.CameraUpdate]:
        for update in updates:
            yield self.frame(update, route)

    def update_style(self, request: pb.UpdateStyleRequest, route: str) -> pb.UpdateStyleResponse:
        reply = self._request(wire.RPC_UPDATE_STYLE, request.SerializeToString())
        return pb.UpdateStyleResponse.FromString(reply)

    def close_session(self, request: pb.CloseSessionRequest, route: str) -> pb.CloseSessionResponse:
        reply = self._request(wire.RPC_CLOSE_SESSION, request.SerializeToString())
        return pb.CloseSessionResponse.FromString(reply)

    def take_shot(self, request: pb.TakeShotRequest, route: str) -> pb.TakeShotResponse:
        return pb.TakeShotResponse.FromString(self._request(wire.RPC_TAKE_SHOT, request.SerializeToString()))

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        self._closed = True
        idle, self._idle = self._idle, []
        for sock in idle:
            sock.close(linger=0)


class _Resumable:
    """The caller's updates for a stream that may take several gRPC calls: a call that ended with
    a RETRYABLE code is followed by one that sends its unanswered updates again (after DATA_LOSS,
    the session's kept updates from the frame asked for), then goes on with the caller's. The
    caller's iterator is read by one call at a time (a lock): an ended call that was waiting in
    it for the next update hands that update to the next call."""

    def __init__(self, updates: Iterable[pb.FrameUpdate], session: Session) -> None:
        self._updates = iter(updates)
        self._session = session
        self._lock = threading.Lock()
        self._handoff: deque[pb.FrameUpdate] = deque()
        self._call = 0
        self._last_seq = 0  # the newest update this stream sent
        self.in_flight: deque[wire.Sent] = deque()  # sent on the current call and not answered, oldest first

    def requests(self) -> Iterator[pb.FrameUpdate]:
        """A new call's requests."""
        with self._lock:  # after the ended call's last read of the caller's iterator, if it was in one
            self._call += 1
            call, resend = self._call, list(self.in_flight)
        for sent in resend:
            yield self._stamped(sent)
        while True:
            with self._lock:
                if self._handoff:
                    update = self._handoff.popleft()
                else:
                    update = next(self._updates, None)
                    if update is None:
                        return
                if call != self._call:
                    self._handoff.appendleft(update)
                    return
                sent = self._session.history.add(update.frame, update)
                self._last_seq = sent.seq
                self.in_flight.append(sent)
            yield self._stamped(sent)

    def _stamped(self, sent: wire.Sent) -> pb.FrameUpdate:
        sent.update.answered_frame = self._session._to_send(sent)
        return sent.update

    def resend_after(self, error: DirectorError) -> None:
        """After the call ended with ``error``: a DATA_LOSS's updates to send again are the next
        call's first (raises ``error`` when they are no longer kept)."""
        with self._lock:
            resend = self._session._resend(error, self._last_seq)
            if resend is not None:
                self.in_flight = deque(resend)

    def oldest_alone(self) -> wire.Sent | None:
        """The oldest unanswered update, to go alone as a unary Frame before the next call (see
        Session.stream); the ended calls take no more updates from now on. None: all answered."""
        with self._lock:
            self._call += 1
            return self.in_flight[0] if self.in_flight else None

    def answered_oldest(self) -> None:
        with self._lock:
            self.in_flight.popleft()


class Session(wire.SessionBase):
    """One director session; closes itself at the end of a ``with`` block (see wire.SessionBase).

    A call answered UNAVAILABLE (or reset by a balancer: CANCELLED), or a frame left unanswered
    for ``retry.frame_timeout_s`` over gRPC (a hung node), is tried again by itself with the same
    session id (the server restores the session from its checkpoint when its worker or node was
    lost), after jittered waits from 0.1 s up, for up to ``retry.retry_window_s`` since the first
    failure (wire.RetryPolicy); so is a stream, from its first unanswered update. A DATA_LOSS
    "resend from K" (a restore whose checkpoint was behind) sends the kept updates from frame K
    again, their answers not given twice. ``retries`` counts the tries. A refused key
    (UNAUTHENTICATED: none, unknown or revoked; PERMISSION_DENIED: its role lacks the call) is
    raised at once: trying again would be refused the same."""

    __slots__ = ()

    def _retrying(self, call, *args):
        backoff = None
        while True:
            try:
                return call(*args, self.route)
            except DirectorError as error:
                delay, backoff = self._retry_after(error, backoff)  # raises it when not to be tried again
                resend = self._resend(error)
                if resend:  # the frames the session lost first
                    self._frame_call(resend[-1], resend)
            time.sleep(delay)

    def _frame_call(self, sent: wire.Sent, pending: list[wire.Sent] | None = None) -> pb.CameraUpdate:
        """A unary Frame of ``sent`` (after those ``pending`` before it), tried again as
        ``_retrying``; after DATA_LOSS the kept updates from the frame asked for are sent first,
        their answers dropped."""
        pending = pending or [sent]
        backoff = None
        while True:
            try:
                method, request = self._frame_request(pending[0])
                reply = method(request, self.route)
            except DirectorError as error:
                delay, backoff = self._retry_after(error, backoff)  # raises it when not to be tried again
                pending = self._resend(error, sent.seq) or pending
                time.sleep(delay)
                continue
            backoff = None
            if pending.pop(0) is sent:
                self._take_answer(sent, reply)
                return reply

    def frame(
        self,
        frame: int,
        time_s: float,
        *,
        states: wire.States | None = None,
        packed: wire.PackedStates | None = None,
        player_stats: Iterable[wire.PlayerStatsLike] | None = None,
    ) -> pb.CameraUpdate:
        """Sends one frame and waits for its camera (the unary ``Frame`` RPC).

        Parameters
        ----------
        frame : int
            Frame number, strictly increasing (an older one is answered ``stale``).
        time_s : float
            Game time of the frame, seconds, non-decreasing.
        states : iterable of ObjectState, or mapping of id to Transform, optional
            What moved this frame.
        packed : (ids, transforms), optional
            The bulk form of ``states``, as :func:`~camdirector_client.convert.pack_states` builds it.
        player_stats : iterable of PlayerStats, or of mappings of its fields, optional
            ``RIG_MATCH``: the players whose scoreboard values (``health``, ``armor``, ``items``,
            ``frags``) changed since the last frame; a player's last values sent hold.
            ``MATCH_DIRECTOR_AUTOTRACK`` ranks players by them.
        """
        update = wire.encode_frame_update(self.id, frame, time_s, states, packed, player_stats)
        return self._frame_call(self.history.add(frame, update))

    def send(self, update: pb.FrameUpdate) -> pb.CameraUpdate:
        """Sends a prebuilt ``FrameUpdate`` (its session_id filled in when empty, its
        answered_frame set); waits for its camera. The message is kept for a DATA_LOSS resend:
        do not change it afterwards."""
        if not update.session_id:
            update.session_id = self.id
        return self._frame_call(self.history.add(update.frame, update))

    def stream(self, frame_updates: Iterable[pb.FrameUpdate]) -> Iterator[pb.CameraUpdate]:
        """One ``CameraUpdate`` per update, in order, as they come.

        Over gRPC this is one StreamFrames call (the updates are read on grpc's thread as the
        stream has room); over ZeroMQ, one Frame request per update. Updates with an empty
        session_id get this session's; each gets its answered_frame, and is kept for a DATA_LOSS
        resend (do not reuse a message). Stopping the iteration early cancels the stream. A
        stream ended by UNAVAILABLE, CANCELLED, an unanswered frame or DATA_LOSS is opened again
        (class docstring).
        """
        feed = _Resumable(wire.with_session_id(frame_updates, self.id), self)
        backoff = None
        alone = False
        while True:
            sent = feed.oldest_alone() if alone else None
            if sent is not None:
                fresh = sent.seq > self._answered_seq  # not one a DATA_LOSS resend answered already
                reply = self._frame_call(sent)  # tried again as a unary call; raises when spent
                feed.answered_oldest()
                if fresh:
                    yield reply
            try:
                for reply in self._transport.stream(feed.requests(), self.route):
                    backoff = None  # answered again: a later loss gets a whole window anew
                    if self._take_answer(feed.in_flight.popleft(), reply):
                        yield reply
                return
            except DirectorError as error:
                delay, backoff = self._retry_after(error, backoff)  # raises it when not to be tried again
                feed.resend_after(error)
                # How a stream ended may hide the server's answer: HAProxy before 3.2 resets a
                # stream (RST_STREAM CANCEL) right after the server ended it while the client
                # still sends, so the client reports CANCELLED, not the server's status (a
                # DATA_LOSS "resend from K", a revoked key: docs/scaling.md); grpc.aio reports an
                # end that meets a write as INTERNAL. So after any break but a DATA_LOSS (which
                # names its resend) the oldest unanswered update goes alone first: a unary
                # call's status arrives whole.
                alone = wire.resend_from(error) is None
            time.sleep(delay)

    def update_style(self, style: pb.Style | Mapping[str, Any]) -> None:
        """Replaces the whole style from the next frame on (unset fields take their defaults)."""
        self._retrying(self._transport.update_style, pb.UpdateStyleRequest(session_id=self.id, style=wire.style_msg(style)))

    def take_shot(self, subject_ids: Iterable[str] = (), kind: int = 0, *, release: bool = False) -> pb.ShotInfo:
        """A human director's shot in a ``RIG_MATCH`` session: ``subject_ids`` (players) as ``kind``
        (a ``pb.ShotKind``; 0: a duel for two, a follow for one, a group for more), held until a call
        with ``release=True``; ``SHOT_REPLAY`` of two players shows their latest kill again and gives
        the program back at its end. Answers the shot now held (empty after a release). An update's
        ``shot.replay_frame`` (non-zero during a replay) names the game frame its picture shows."""
        return self._retrying(self._transport.take_shot, wire.take_shot_request(self.id, subject_ids, kind, release)).shot

    def close(self) -> int:
        """Closes the session on the server; answers how many frames it answered. Idempotent."""
        if self._closed_frames is None:
            response = self._retrying(self._transport.close_session, pb.CloseSessionRequest(session_id=self.id))
            self._closed_frames = response.frames
        return self._closed_frames

    def __enter__(self) -> Session:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if exc_type is None:
            self.close()
            return
        try:  # best effort: do not hide the error that ended the block
            self.close()
        except DirectorError:
            pass


class Client:
    """A connection to a director server; see :func:`connect`."""

    def __init__(self, transport: _Transport, url: str, retry: wire.RetryPolicy = wire.DEFAULT_RETRY) -> None:
        self._transport = transport
        self.url = url
        self.retry = retry

    def __repr__(self) -> str:
        return f"Client({self.url!r})"

    def create_session(
        self,
        request: pb.CreateSessionRequest | None = None,
        *,
        objects: Iterable[pb.SceneObject] | None = None,
        targets: Iterable[pb.Target] | None = None,
        lens: pb.Lens | None = None,
        style: pb.Style | Mapping[str, Any] | None = None,
        seed: int = 0,
        record: bool = False,
        level_id: str = "",
        delay_s: float = 0.0,
    ) -> Session:
        """Opens a session from a ``CreateSessionRequest`` or from its fields as keywords."""
        msg = wire.create_session_request(
            request,
            objects=objects,
            targets=targets,
            lens=lens,
            style=style,
            seed=seed,
            record=record,
            level_id=level_id,
            delay_s=delay_s,
        )
        route = wire.new_route_key()
        return Session(self._transport, self._transport.create_session(msg, route), route, self.retry)

    def close(self) -> None:
        """Closes the channel or sockets. Sessions stay open on the server until their timeout."""
        self._transport.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()


def connect(
    url: str,
    timeout_s: float = wire.DEFAULT_TIMEOUT_S,
    *,
    key: str | None = None,
    ca_file: str | os.PathLike[str] | None = None,
    zmq_server_key: str | bytes | os.PathLike[str] | None = None,
    max_message_bytes: int = wire.DEFAULT_MAX_MESSAGE_BYTES,
    grpc_options: Sequence[tuple[str, Any]] | None = None,
    zmq_context: zmq.Context | None = None,
    retry: wire.RetryPolicy = wire.DEFAULT_RETRY,
) -> Client:
    """A :class:`Client` for ``grpc://host:port`` (gRPC), ``grpcs://host:port`` (gRPC over TLS)
    or ``tcp://host:port`` (ZeroMQ).

    Parameters
    ----------
    url : str
        Server address; the scheme picks the transport.
    timeout_s : float
        Seconds a unary call waits for its reply before DirectorError(DEADLINE_EXCEEDED).
    key : str, optional
        The API key (``camdirector keys create``), sent with every call: gRPC metadata
        ``authorization: Bearer KEY``, or the ZeroMQ request's third frame. Default: the
        ``CAMDIRECTOR_KEY`` environment variable, else none. Never logged nor shown in a repr.
    ca_file : path, optional
        ``grpcs://`` only: PEM certificates of the authorities to trust for the server's
        certificate (a studio's own CA); default the system's roots.
    zmq_server_key : str, bytes or path, optional
        ``tcp://`` only: the server's CURVE public key (40 characters of Z85 text, its ready line's
        ``zmq_server_key``) or the path of its ``DIR/zmq/server.key`` file. Given, the sockets are
        CURVE clients (encrypted, with a key pair made for this client); a server with
        authentication on answers no other.
    max_message_bytes : int
        gRPC send and receive limit, bytes.
    grpc_options : sequence of (str, value), optional
        More gRPC channel arguments; they override the ones above.
    zmq_context : zmq.Context, optional
        Context for the ZeroMQ sockets; default the process-wide ``zmq.Context.instance()``.
    retry : RetryPolicy
        How long failed calls are tried again (``retry_window_s``, 30 s), how long a frame may go
        unanswered before its node is taken as hung (``frame_timeout_s``, 3 s) and how many
        sent updates are kept for a DATA_LOSS resend (``resend_history_frames``, 600).

    Connecting is lazy: an unreachable server shows at the first call (UNAVAILABLE over gRPC,
    DEADLINE_EXCEEDED over ZeroMQ), and so does a refused key (UNAUTHENTICATED, PERMISSION_DENIED).
    """
    endpoint = wire.parse_url(url)
    timeout_s = wire.check_timeout(timeout_s)
    security = wire.security(endpoint, key, ca_file, zmq_server_key)
    transport: _Transport
    if endpoint.transport == "grpc":
        options = wire.grpc_channel_options(max_message_bytes, grpc_options, retry)
        transport = _GrpcTransport(endpoint.address, timeout_s, options, security, retry)
    else:
        transport = _ZmqTransport(endpoint.address, timeout_s, zmq_context, security, retry)
    return Client(transport, url, retry)
