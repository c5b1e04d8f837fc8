"""The asyncio client: grpc.aio for ``grpc://host:port`` (``grpcs://`` over TLS), zmq.asyncio for
``tcp://host:port``.

    async with connect_async("tcp://127.0.0.1:5555", key=KEY, zmq_server_key=SERVER_KEY) as client:
        async with client.create_session(targets=[...]) as session:
            update = await session.frame(1, 0.016, packed=pack_states(ids, positions, rotations))

Same methods as the sync client (:mod:`camdirector_client.client`), awaited, with the same
behaviour when a node or worker is lost or hangs: every gRPC call of a session carries its route key
(``wire.ROUTE_HEADER``) and the client's key, and a call or stream answered UNAVAILABLE or
CANCELLED is tried again with the same session id (see :class:`AsyncSession`). Create and use
an :class:`AsyncClient` inside one running event loop. Over ZeroMQ each request borrows a DEALER
socket from a small pool (one request outstanding per socket), so concurrent tasks do not queue
behind one another.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from collections import deque
from collections.abc import AsyncIterable, AsyncIterator, Generator, Iterable, Mapping, Sequence
from types import TracebackType
from typing import Any, Protocol

import grpc
import grpc.aio
import zmq
import zmq.asyncio

from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc
from camdirector_client import wire
from camdirector_client.errors import DirectorError

__all__ = ["AsyncClient", "AsyncSession", "connect_async"]

_IDLE_SOCKETS = 8  # ZeroMQ sockets a client keeps open for reuse
_FRAME_METHOD = "/camdirector.v1.Director/Frame"

FrameUpdates = Iterable[pb.FrameUpdate] | AsyncIterable[pb.FrameUpdate]


class _AsyncTransport(Protocol):
    """Every call of a session carries its `route` key (wire.ROUTE_HEADER over gRPC; ZeroMQ
    talks to one node and needs none). ``closed``: after close(), whose CANCELLED answers are
    not the balancer's reset and are not tried again."""

    closed: bool

    async def create_session(self, request: pb.CreateSessionRequest, route: str) -> pb.CreateSessionResponse: ...
    async def frame(self, update: pb.FrameUpdate, route: str) -> pb.CameraUpdate: ...
    async def frame_encoded(self, update: bytes, route: str) -> pb.CameraUpdate: ...
    def stream(self, updates: AsyncIterable[pb.FrameUpdate], route: str) -> AsyncIterator[pb.CameraUpdate]: ...
    async def update_style(self, request: pb.UpdateStyleRequest, route: str) -> pb.UpdateStyleResponse: ...
    async def take_shot(self, request: pb.TakeShotRequest, route: str) -> pb.TakeShotResponse: ...
    async def close_session(self, request: pb.CloseSessionRequest, route: str) -> pb.CloseSessionResponse: ...
    async def close(self) -> None: ...


class _AioGrpcTransport:
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
            self._channel = grpc.aio.insecure_channel(target, options=options)
        else:
            self._channel = grpc.aio.secure_channel(target, security.credentials, options=options)
        self._security = security
        self._stub = director_pb2_grpc.DirectorStub(self._channel)
        # Frame again, taking a FrameUpdate already serialized (wire.encode_frame_update).
        self._frame_encoded = self._channel.unary_unary(
            _FRAME_METHOD, response_deserializer=pb.CameraUpdate.FromString, _registered_method=True
        )
        self._timeout_s = timeout_s
        self._frame_timeout_s = retry.frame_timeout_s
        self.closed = False

    async def _unary(self, method, request, route: str):
        try:
            return await method(request, timeout=self._timeout_s, metadata=self._security.grpc_metadata(route))
        except grpc.RpcError as error:
            raise self._security.grpc_error(error) from None

    async def _frame(self, method, request, route: str) -> pb.CameraUpdate:
        hang_s = self._frame_timeout_s
        if hang_s is None or hang_s >= self._timeout_s:
            return await self._unary(method, request, route)
        try:
            return await method(request, timeout=hang_s, metadata=self._security.grpc_metadata(route))
        except grpc.RpcError as error:
            raise wire.frame_error(self._security.grpc_error(error), hang_s) from None

    async def create_session(self, request: pb.CreateSessionRequest, route: str) -> pb.CreateSessionResponse:
        return await self._unary(self._stub.CreateSession, request, route)

    async def frame(self, update: pb.FrameUpdate, route: str) -> pb.CameraUpdate:
        return await self._frame(self._stub.Frame, update, route)

    async def frame_encoded(self, update: bytes, route: str) -> pb.CameraUpdate:
        return await self._frame(self._frame_encoded, update, route)

    async def stream(self, updates: AsyncIterable[pb.FrameUpdate], route: str) -> AsyncIterator[pb.CameraUpdate]:
        deadlines = None if self._frame_timeout_s is None else wire.FrameDeadlines(self._frame_timeout_s)
        pump = _AsyncRequestPump(updates, deadlines)
        call = self._stub.StreamFrames(pump.iterate(), metadata=self._security.grpc_metadata(route))
        watchdog = None if deadlines is None else asyncio.ensure_future(_watch(call, deadlines))
        try:
            async for update in call:
                if deadlines is not None:
                    deadlines.answered()
                yield update
        except grpc.RpcError as error:
            if pump.error is not None:  # the caller's iterator failed: grpc only saw a cancel
                raise pump.error from None
            if deadlines is not None and deadlines.expired is not None:
                raise deadlines.expired from None
            raise _stream_error(error, self._security) from None
        except asyncio.CancelledError:
            if pump.error is not None:  # grpc.aio cancels the call when the request iterator fails
                raise pump.error from None
            if deadlines is not None and deadlines.expired is not None:  # the watchdog cancelled the call
                raise deadlines.expired from None
            raise
        finally:
            if watchdog is not None:
                watchdog.cancel()
            call.cancel()
        if pump.error is not None:
            raise pump.error

    async def update_style(self, request: pb.UpdateStyleRequest, route: str) -> pb.UpdateStyleResponse:
        return await self._unary(self._stub.UpdateStyle, request, route)

    async def take_shot(self, request: pb.TakeShotRequest, route: str) -> pb.TakeShotResponse:
        return await self._unary(self._stub.TakeShot, request, route)

    async def close_session(self, request: pb.CloseSessionRequest, route: str) -> pb.CloseSessionResponse:
        return await self._unary(self._stub.CloseSession, request, route)

    async def close(self) -> None:
        self.closed = True
        self._stub = self._frame_encoded = wire.ClosedStub()
        await self._channel.close()


_WRITE_FAILED = "Internal error from Core"  # grpc.aio's details when it could not write a request


def _stream_error(error: grpc.RpcError, security: wire.Security) -> DirectorError:
    """The error that ended a stream.

    A request written just as the peer ends the call (a node restoring the session answers
    UNAVAILABLE, a balancer resets the stream of a node that died) fails, and grpc.aio then sets
    the call's status to INTERNAL "Internal error from Core" in place of the peer's (grpc.aio's
    _call.py, ``_write``; about 3 breaks in 10 when the caller's updates come as fast as the
    stream takes them, tests/client_sdk/test_aio_failover.py). All that is known then is
    that the call ended under a write: it is reported UNAVAILABLE, so the stream is opened again
    and the next call shows what the server has to say."""
    if error.code() is grpc.StatusCode.INTERNAL and error.details() == _WRITE_FAILED:
        return DirectorError(grpc.StatusCode.UNAVAILABLE, f"the stream ended as a request was written ({_WRITE_FAILED})")
    return security.grpc_error(error)


async def _watch(call: grpc.aio.Call, deadlines: wire.FrameDeadlines) -> None:
    """Cancels ``call`` when a frame on it is left unanswered past its deadline (a hung node)."""
    while deadlines.expired is None:
        await asyncio.sleep(deadlines.wait_s())
    call.cancel()


class _AsyncRequestPump:
    """Iterates the caller's updates for grpc.aio, noting when each is sent (``deadlines``), and
    keeps what they raised, if anything."""

    def __init__(self, updates: AsyncIterable[pb.FrameUpdate], deadlines: wire.FrameDeadlines | None = None) -> None:
        self._updates = updates
        self._deadlines = deadlines
        self.error: BaseException | None = None

    async def iterate(self) -> AsyncIterator[pb.FrameUpdate]:
        try:
            async for update in self._updates:
                if self._deadlines is not None:
                    self._deadlines.sent(update.frame)
                yield update
        except Exception as error:
            self.error = error
            raise


class _AioZmqTransport:
    """Request/reply over zmq.asyncio DEALER sockets: one request outstanding per socket, LINGER 0.

    A socket that timed out (or whose task was cancelled) while waiting is closed, never reused,
    so a late reply can not be taken for the answer to a later request. A frame waits
    ``retry.frame_timeout_s`` when shorter, then UNAVAILABLE: a hung node, tried again.
    """

    def __init__(
        self,
        endpoint: str,
        timeout_s: float,
        context: zmq.asyncio.Context | None,
        security: wire.Security,
        retry: wire.RetryPolicy = wire.DEFAULT_RETRY,
    ) -> None:
        self._endpoint = endpoint
        self._frame_timeout_s = wire.zmq_frame_timeout_s(timeout_s, retry)
        self._timeout_s = timeout_s
        self._timeout_ms = max(1, round(timeout_s * 1000.0))
        self._context = context if context is not None else zmq.asyncio.Context.instance()
        self._security = security
        self._idle: list[zmq.asyncio.Socket] = [self._open()]
        self.closed = False

    def _open(self) -> zmq.asyncio.Socket:
        return wire.open_dealer(self._context, self._endpoint, self._timeout_ms, self._security.curve)

    async def _request(self, rpc: bytes, payload: bytes) -> bytes:
        if self.closed:
            raise DirectorError(grpc.StatusCode.CANCELLED, "the client is closed")
        sock = self._idle.pop() if self._idle else self._open()
        hang_s = self._frame_timeout_s if rpc == wire.RPC_FRAME else None
        try:
            sock.rcvtimeo = self._timeout_ms if hang_s is None else max(1, round(hang_s * 1000.0))
            await sock.send_multipart(self._security.zmq_request(rpc, payload))
            reply = await sock.recv_multipart()
        except zmq.Again:
            sock.close(linger=0)
            if not self.closed:  # a fresh socket, already connecting, for the next call
                self._idle.append(self._open())
            raise wire.zmq_no_reply(rpc, self._endpoint, self._timeout_s, self._security.curve is not None, hang_s) from None
        except BaseException:
            sock.close(linger=0)
            raise
        if self.closed or len(self._idle) >= _IDLE_SOCKETS:
            sock.close(linger=0)
        else:
            self._idle.append(sock)
        return wire.zmq_reply_payload(reply)

    async def create_session(self, request: pb.CreateSessionRequest, route: str) -> pb.CreateSessionResponse:
        reply = await self._request(wire.RPC_CREATE_SESSION, request.SerializeToString())
        return pb.CreateSessionResponse.FromString(reply)

    async def frame(self, update: pb.FrameUpdate, route: str) -> pb.CameraUpdate:
        return pb.CameraUpdate.FromString(await self._request(wire.RPC_FRAME, update.SerializeToString()))

    async def frame_encoded(self, update: bytes, route: str) -> pb.CameraUpdate:
        return pb.CameraUpdate.FromString(await self._request(wire.RPC_FRAME, update))

    async def stream(self, updates: AsyncIterable[pb.FrameUpdate], route: str) -> AsyncIterator[pb.CameraUpdate]:
        async for update in updates:
            yield await self.frame(update, route)

    async def update_style(self, request: pb.UpdateStyleRequest, route: str) -> pb.UpdateStyleResponse:
        reply = await self._request(wire.RPC_UPDATE_STYLE, request.SerializeToString())
        return pb.UpdateStyleResponse.FromString(reply)

    async def take_shot(self, request: pb.TakeShotRequest, route: str) -> pb.TakeShotResponse:
        return pb.TakeShotResponse.FromString(await self._request(wire.RPC_TAKE_SHOT, request.SerializeToString()))

    async def close_session(self, request: pb.CloseSessionRequest, route: str) -> pb.CloseSessionResponse:
        reply = await self._request(wire.RPC_CLOSE_SESSION, request.SerializeToString())
        return pb.CloseSessionResponse.FromString(reply)

    async def close(self) -> None:
        self.closed = True
        idle, self._idle = self._idle, []
        for sock in idle:
            sock.close(linger=0)


_END = object()  # what a pull answers when the caller's updates are over


class _AsyncResumable:
    """The caller's updates for a stream that may take several calls: a call that ended with a
    RETRYABLE code is followed by one that sends its unanswered updates again (after DATA_LOSS,
    the session's kept updates from the frame asked for), then goes on with the caller's.

    Each read of the caller's iterator is a task of its own (``_pull``), awaited through
    ``asyncio.shield``, for two reasons. grpc.aio reads a call's requests on a task of its own
    that outlives a failed call (it is not cancelled when the call is already over) and that is
    cancelled when a call is: a read made on it directly could be broken off by that
    cancellation, which would end the caller's generator, or a second read could start on the
    next call while the first is still in ``__anext__`` ("already running"). With the read in its
    own task, one read is under way at a time, whichever call waits on it, and the update it
    brings goes to the call current when it comes (``_call``, a count of calls): an ended call
    leaves it to the next one instead of losing it.
    """

    def __init__(self, updates: AsyncIterable[pb.FrameUpdate], session: AsyncSession) -> None:
        self._updates = updates.__aiter__()
        self._session = session
        self._pull: asyncio.Future[Any] | None = None  # the read under way, or done and not yet taken
        self._call = 0
        self._last_seq = 0  # the newest update this stream sent
        self.in_flight: deque[wire.Sent] = deque()  # sent on the current call and not answered, oldest first

    def requests(self) -> AsyncIterator[pb.FrameUpdate]:
        """A new call's requests; from now on the calls before it take no more updates."""
        self._call += 1
        return self._requests(self._call, list(self.in_flight))

    async def _requests(self, call: int, resend: list[wire.Sent]) -> AsyncIterator[pb.FrameUpdate]:
        for sent in resend:
            yield self._stamped(sent)
        while call == self._call:
            if self._pull is None:
                self._pull = asyncio.ensure_future(self._next_update())
            update = await asyncio.shield(self._pull)  # a cancelled call leaves the read going
            if update is _END or call != self._call:
                return  # over; or this call ended meanwhile and the update is the next call's
            self._pull = None
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
        resend = self._session._resend(error, self._last_seq)
        if resend is not None:
            self.in_flight = deque(resend)

    def oldest_alone(self) -> wire.Sent | None:
        """The oldest unanswered update, to go alone as a unary Frame before the next call (see
        Session.stream); the ended calls take no more updates from now on. None: all answered."""
        self._call += 1
        return self.in_flight[0] if self.in_flight else None

    async def _next_update(self) -> Any:
        try:
            return await self._updates.__anext__()
        except StopAsyncIteration:  # a future can not hold it
            return _END

    def close(self) -> None:
        """The stream is over: a read still under way is cancelled (it would be nobody's)."""
        if self._pull is not None and not self._pull.done():
            self._pull.cancel()


class AsyncSession(wire.SessionBase):
    """One director session; closes itself at the end of an ``async with`` block (see wire.SessionBase).

    As in the sync client (:class:`camdirector_client.Session`): a call answered UNAVAILABLE (or
    reset by a balancer: CANCELLED), or a frame left unanswered for ``retry.frame_timeout_s`` over
    gRPC (a hung node), is tried again by itself after ``asyncio.sleep`` (jittered waits from
    0.1 s up, for up to ``retry.retry_window_s``), with the same session id, since the server
    restores the session from its checkpoint when its worker or node was lost; so is a stream,
    from its first unanswered update; a DATA_LOSS "resend from K" sends the kept updates from
    frame K again. ``retries`` counts the tries. CreateSession is not tried again (a second
    session could be made), nor is a call of a closed client, nor one whose key was refused
    (UNAUTHENTICATED, PERMISSION_DENIED)."""

    __slots__ = ()

    async def _retrying(self, call, *args):
        backoff = None
        while True:
            try:
                return await call(*args, self.route)
            except DirectorError as error:
                delay, backoff = self._retry_after(error, backoff)  # raises it when not to be tried again
                resend = self._resend(error)
                if resend:  # the frames the session lost first
                    await self._frame_call(resend[-1], resend)
            await asyncio.sleep(delay)

    async def _frame_call(self, sent: wire.Sent, pending: list[wire.Sent] | None = None) -> pb.CameraUpdate:
        """A unary Frame of ``sent`` (after those ``pending`` before it); see Session._frame_call."""
        pending = pending or [sent]
        backoff = None
        while True:
            try:
                method, request = self._frame_request(pending[0])
                reply = await method(request, self.route)
            except DirectorError as error:
                delay, backoff = self._retry_after(error, backoff)  # raises it when not to be tried again
                pending = self._resend(error, sent.seq) or pending
                await asyncio.sleep(delay)
                continue
            backoff = None
            if pending.pop(0) is sent:
                self._take_answer(sent, reply)
                return reply

    async def frame(
        self,
        frame: int,
        time_s: float,
        *,
        states: wire.States | None = None,
        packed: wire.PackedStates | None = None,
        player_stats: Iterable[wire.PlayerStatsLike] | None = None,
    ) -> pb.CameraUpdate:
        """Sends one frame and waits for its camera; see :meth:`camdirector_client.Session.frame`."""
        update = wire.encode_frame_update(self.id, frame, time_s, states, packed, player_stats)
        return await self._frame_call(self.history.add(frame, update))

    async def send(self, update: pb.FrameUpdate) -> pb.CameraUpdate:
        """Sends a prebuilt ``FrameUpdate``; see :meth:`camdirector_client.Session.send`."""
        if not update.session_id:
            update.session_id = self.id
        return await self._frame_call(self.history.add(update.frame, update))

    async def stream(self, frame_updates: FrameUpdates) -> AsyncIterator[pb.CameraUpdate]:
        """One ``CameraUpdate`` per update, in order: ``async for update in session.stream(...)``.

        ``frame_updates`` may be a sync or an async iterable. Over gRPC this is one StreamFrames
        call; over ZeroMQ, one Frame request per update. Updates with an empty session_id get this
        session's; each gets its answered_frame and is kept for a DATA_LOSS resend (do not reuse
        a message). Leaving the loop early cancels the stream (close the iterator with
        ``aclose()``). A stream ended by UNAVAILABLE, CANCELLED, an unanswered frame or DATA_LOSS
        is opened again (class docstring; _AsyncResumable).
        """
        feed = _AsyncResumable(wire.with_session_id_async(frame_updates, self.id), self)
        backoff = None
        alone = False
        try:
            while True:
                sent = feed.oldest_alone() if alone else None
                if sent is not None:  # after a break, as in Session.stream
                    fresh = sent.seq > self._answered_seq
                    reply = await self._frame_call(sent)
                    feed.in_flight.popleft()
                    if fresh:
                        yield reply
                try:
                    async with contextlib.aclosing(self._transport.stream(feed.requests(), self.route)) as replies:
                        async for reply in replies:
                            backoff = None  # answered again: a later loss gets a whole window anew
                            if self._take_answer(feed.in_flight.popleft(), reply):
                                yield reply
                    return
                except DirectorError as error:
                    delay, backoff = self._retry_after(error, backoff)  # raises it when not to be tried again
                    feed.resend_after(error)
                    alone = wire.resend_from(error) is None  # as in Session.stream
                await asyncio.sleep(delay)
        finally:
            feed.close()

    async def update_style(self, style: pb.Style | Mapping[str, Any]) -> None:
        """Replaces the whole style from the next frame on (unset fields take their defaults)."""
        request = pb.UpdateStyleRequest(session_id=self.id, style=wire.style_msg(style))
        await self._retrying(self._transport.update_style, request)

    async def take_shot(self, subject_ids: Iterable[str] = (), kind: int = 0, *, release: bool = False) -> pb.ShotInfo:
        """A human director's shot in a ``RIG_MATCH`` session: ``subject_ids`` (players) as ``kind``
        (a ``pb.ShotKind``; 0: a duel for two, a follow for one, a group for more), held until a call
        with ``release=True``; ``SHOT_REPLAY`` of two players shows their latest kill again and gives
        the program back at its end. Answers the shot now held (empty after a release). An update's
        ``shot.replay_frame`` (non-zero during a replay) names the game frame its picture shows."""
        return (await self._retrying(self._transport.take_shot, wire.take_shot_request(self.id, subject_ids, kind, release))).shot

    async def close(self) -> int:
        """Closes the session on the server; answers how many frames it answered. Idempotent."""
        if self._closed_frames is None:
            response = await self._retrying(self._transport.close_session, pb.CloseSessionRequest(session_id=self.id))
            self._closed_frames = response.frames
        return self._closed_frames

    async def __aenter__(self) -> AsyncSession:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if exc_type is None:
            await self.close()
            return
        try:  # best effort: do not hide the error that ended the block
            await self.close()
        except DirectorError:
            pass


class _SessionOpening:
    """What :meth:`AsyncClient.create_session` returns: await it for the session, or use it in
    ``async with`` to have the session closed at the end of the block."""

    __slots__ = ("_opening", "_session")

    def __init__(self, opening: Any) -> None:
        self._opening = opening
        self._session: AsyncSession | None = None

    def __await__(self) -> Generator[Any, None, AsyncSession]:
        return self._opening.__await__()

    async def __aenter__(self) -> AsyncSession:
        self._session = await self._opening
        return self._session

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        assert self._session is not None
        await self._session.__aexit__(exc_type, exc, tb)


class AsyncClient:
    """A connection to a director server; see :func:`connect_async`."""

    def __init__(self, transport: _AsyncTransport, url: str, retry: wire.RetryPolicy = wire.DEFAULT_RETRY) -> None:
        self._transport = transport
        self.url = url
        self.retry = retry

    def __repr__(self) -> str:
        return f"AsyncClient({self.url!r})"

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
    ) -> _SessionOpening:
        """Opens a session: ``session = await client.create_session(...)`` or
        ``async with client.create_session(...) as session``. Arguments as in the sync client.
        """
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
        return _SessionOpening(self._open_session(msg))

    async def _open_session(self, request: pb.CreateSessionRequest) -> AsyncSession:
        route = wire.new_route_key()  # before the session exists: CreateSession carries it too
        return AsyncSession(self._transport, await self._transport.create_session(request, route), route, self.retry)

    async def close(self) -> None:
        """Closes the channel or sockets. Sessions stay open on the server until their timeout."""
        await self._transport.close()

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        await self.close()


def connect_async(
    url: str,
    timeout_s: float = wire.DEFAULT_TIMEOUT_S,
    *,
    key: str | None = None,
    ca_file: str | os.PathLike[str] | None = None,
    zmq_server_key: str | bytes | os.PathLike[str] | None = None,
    max_message_bytes: int = wire.DEFAULT_MAX_MESSAGE_BYTES,
    grpc_options: Sequence[tuple[str, Any]] | None = None,
    zmq_context: zmq.asyncio.Context | None = None,
    retry: wire.RetryPolicy = wire.DEFAULT_RETRY,
) -> AsyncClient:
    """An :class:`AsyncClient` for ``grpc://host:port``, ``grpcs://host:port`` or
    ``tcp://host:port``; call it inside a running event loop. Arguments as in
    :func:`camdirector_client.connect` (``key`` defaults to the ``CAMDIRECTOR_KEY`` environment
    variable); ``zmq_context`` defaults to ``zmq.asyncio.Context.instance()``.
    """
    endpoint = wire.parse_url(url)
    timeout_s = wire.check_timeout(timeout_s)
    security = wire.security(endpoint, key, ca_file, zmq_server_key)
    transport: _AsyncTransport
    if endpoint.transport == "grpc":
        options = wire.grpc_channel_options(max_message_bytes, grpc_options, retry)
        transport = _AioGrpcTransport(endpoint.address, timeout_s, options, security, retry)
    else:
        transport = _AioZmqTransport(endpoint.address, timeout_s, zmq_context, security, retry)
    return AsyncClient(transport, url, retry)
