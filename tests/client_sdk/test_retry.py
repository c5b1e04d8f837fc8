"""Issue 40 in the Python SDK: retries within a window with jittered backoff, a hung node's
stream reopened, and DATA_LOSS "resend from K" answered by sending the kept updates again.

The backoff is checked with an injected clock and random source; the DATA_LOSS resend against
the tests' own grpc.aio Director (test_aio_failover.FlakyDirector), which a real server cannot be
made to answer on demand; the hung node is a real server process stopped with SIGSTOP.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
import signal
import threading
import time

import grpc
import grpc.aio
import pytest

import camdirector_client as cd
from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc as pb_grpc
from camdirector_client import wire
from tests.client_sdk.test_aio_failover import FlakyDirector
from tests.service.wire_client import two_target_request, walk


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


def test_backoff_doubles_from_0_1_s_with_equal_jitter_up_to_the_0_5_s_cap():
    draws = random.Random(7)
    policy = cd.RetryPolicy(random=random.Random(7).random)
    backoff = wire.Backoff(policy, FakeClock())
    delays = [backoff.next_delay_s() for _ in range(7)]
    caps = [0.1, 0.2, 0.4, 0.5, 0.5, 0.5, 0.5]
    assert delays == [cap * (0.5 + 0.5 * draws.random()) for cap in caps]
    assert all(cap / 2 <= d <= cap for d, cap in zip(delays, caps, strict=True))


def test_backoff_stops_when_the_window_since_the_first_failure_is_spent():
    clock = FakeClock()
    backoff = wire.Backoff(cd.RetryPolicy(retry_window_s=2.0, random=lambda: 1.0), clock)
    clock.now_s += 1.95
    assert backoff.next_delay_s() == pytest.approx(0.05)  # no wait past the window's end
    assert backoff.next_delay_s(at_once=True) == 0.0  # a DATA_LOSS resend: no wait, still counted
    clock.now_s += 0.05
    assert backoff.next_delay_s() is None and backoff.next_delay_s(at_once=True) is None


def test_a_bad_policy_is_refused():
    for bad in ({"retry_window_s": -1.0}, {"frame_timeout_s": 0.0}, {"resend_history_frames": -1}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            cd.RetryPolicy(**bad)


def test_resend_from_reads_the_frame_of_a_data_loss():
    loss = cd.DirectorError(grpc.StatusCode.DATA_LOSS, "state lost after frame 41: resend from 42")
    assert wire.resend_from(loss) == 42
    assert wire.resend_from(cd.DirectorError(grpc.StatusCode.UNAVAILABLE, "resend from 42")) is None
    assert wire.resend_from(cd.DirectorError(grpc.StatusCode.DATA_LOSS, "lost")) is None


def test_sent_history_keeps_the_last_updates_and_says_when_one_is_gone():
    history = wire.SentHistory(3)
    loss = cd.DirectorError(grpc.StatusCode.DATA_LOSS, "resend from 2")
    sent = [history.add(frame, f"u{frame}") for frame in (1, 2, 3)]
    assert [s.previous_frame for s in sent] == [0, 1, 2]
    assert history.since(2, None, loss) == sent[1:] and history.since(2, 2, loss) == sent[1:2]
    history.add(5, "u5")  # frame 1 is dropped
    assert [s.frame for s in history.since(2, None, loss)] == [2, 3, 5]
    with pytest.raises(cd.DirectorError, match="frame 1 is no longer among them") as gone:
        history.since(1, None, loss)
    assert gone.value.code is grpc.StatusCode.DATA_LOSS and "resend from 2" in gone.value.message
    with pytest.raises(cd.DirectorError, match="resend_history_frames"):
        nothing_kept = wire.SentHistory(0)
        nothing_kept.add(1, "u1")
        nothing_kept.since(1, None, loss)


class LosingDirector(FlakyDirector):
    """A FlakyDirector that also answers DATA_LOSS on demand, as a node whose session was restored
    from a checkpoint that ends at frame K - 1: ``losses``, frame -> K (the frame's call ends with
    "state lost after frame K-1: resend from K", and so does every call until frame K comes);
    records every update's (frame, answered_frame)."""

    def __init__(self) -> None:
        super().__init__()
        self.losses: dict[int, int] = {}
        self.awaiting: int | None = None  # the K of a loss until frame K comes
        self.seen: list[tuple[int, int]] = []

    def _lost(self, update: pb.FrameUpdate) -> str | None:
        self.seen.append((update.frame, update.answered_frame))
        self.awaiting = self.losses.pop(update.frame, self.awaiting)
        if self.awaiting is None or update.frame == self.awaiting:
            self.awaiting = None
            return None
        return f"state lost after frame {self.awaiting - 1}: resend from {self.awaiting}"

    async def Frame(self, request, context):
        lost = self._lost(request)
        if lost is not None:
            await context.abort(grpc.StatusCode.DATA_LOSS, lost)
        return await super().Frame(request, context)

    async def StreamFrames(self, request_iterator, context):
        async def checked():
            async for update in request_iterator:
                lost = self._lost(update)
                if lost is not None:
                    await context.abort(grpc.StatusCode.DATA_LOSS, lost)
                yield update

        async for answer in super().StreamFrames(checked(), context):
            yield answer


@contextlib.contextmanager
def serving(director: FlakyDirector):
    """``director`` on a grpc.aio server in a thread of its own (for the sync client); its URL."""
    loop = asyncio.new_event_loop()
    started = threading.Event()
    server: list[grpc.aio.Server] = []

    async def start() -> int:
        server.append(grpc.aio.server())
        pb_grpc.add_DirectorServicer_to_server(director, server[0])
        port = server[0].add_insecure_port("127.0.0.1:0")
        await server[0].start()
        return port

    thread = threading.Thread(target=lambda: (started.set(), loop.run_forever()), daemon=True)
    thread.start()
    started.wait()
    port = asyncio.run_coroutine_threadsafe(start(), loop).result(10)
    try:
        yield f"grpc://127.0.0.1:{port}"
    finally:
        asyncio.run_coroutine_threadsafe(server[0].stop(None), loop).result(10)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)


def test_a_stream_answered_data_loss_resends_its_kept_updates_sync():
    director = LosingDirector()
    director.losses = {30: 21}  # a restore that lost frames 21..29, all answered already
    with serving(director) as url, cd.connect(url) as client:
        session = client.create_session(targets=[pb.Target(id="a")])
        answers = [a.frame for a in session.stream(pb.FrameUpdate(frame=f) for f in range(1, 41))]
        assert answers == list(range(1, 41))  # each once, in order: the resent ones' answers dropped
        assert director.answered[session.id] == list(range(1, 30)) + list(range(21, 41))
        assert session.answered_frame == 40 and session.retries >= 1
        # every update says the newest answer the client had when it was sent, never past its predecessor
        assert all(answered < frame for frame, answered in director.seen) and director.seen[0] == (1, 0)
        lost_at = next(i for i, (frame, _) in enumerate(director.seen) if frame == 30)
        resent = director.seen[lost_at + 1 : lost_at + 10]
        assert [frame for frame, _ in resent] == list(range(21, 30)) and [a for _, a in resent] == list(range(20, 29))


def test_a_unary_frame_answered_data_loss_resends_its_kept_updates_sync():
    director = LosingDirector()
    with serving(director) as url, cd.connect(url) as client:
        session = client.create_session(targets=[pb.Target(id="a")])
        for frame in range(1, 6):
            session.frame(frame, frame / 60)
        director.losses = {6: 3}
        assert session.send(pb.FrameUpdate(frame=6)).frame == 6
        assert director.answered[session.id] == [1, 2, 3, 4, 5, 3, 4, 5, 6]
        assert [a for f, a in director.seen if f == 6] == [5, 5] and session.answered_frame == 6


def test_a_data_loss_beyond_the_kept_updates_is_raised_not_skipped():
    director = LosingDirector()
    director.losses = {30: 5}
    with serving(director) as url, cd.connect(url, retry=cd.RetryPolicy(resend_history_frames=10)) as client:
        session = client.create_session(targets=[pb.Target(id="a")])
        with pytest.raises(cd.DirectorError, match="resend from 5 .*frame 5 is no longer among them") as lost:
            list(session.stream(pb.FrameUpdate(frame=f) for f in range(1, 41)))
        assert lost.value.code is grpc.StatusCode.DATA_LOSS


def test_a_stream_answered_data_loss_resends_its_kept_updates_async():
    async def main():
        director = LosingDirector()
        director.losses = {12: 4, 30: 25}
        server = grpc.aio.server()
        pb_grpc.add_DirectorServicer_to_server(director, server)
        port = server.add_insecure_port("127.0.0.1:0")
        await server.start()
        try:
            async with cd.connect_async(f"grpc://127.0.0.1:{port}") as client:
                session = await client.create_session(targets=[pb.Target(id="a")])
                answers = [a.frame async for a in session.stream(pb.FrameUpdate(frame=f) for f in range(1, 41))]
                await session.frame(41, 0.7)
                return director, session, answers
        finally:
            await server.stop(None)

    director, session, answers = asyncio.run(asyncio.wait_for(main(), 20.0))
    # a DATA_LOSS abort that meets a request being written reaches grpc.aio as INTERNAL (see
    # aio._stream_error): tried again as UNAVAILABLE, answered DATA_LOSS then
    assert answers == list(range(1, 41)) and session.answered_frame == 41 and session.retries >= 2
    assert director.answered[session.id] == list(range(1, 12)) + list(range(4, 30)) + list(range(25, 42))
    assert director.seen[-1] == (41, 40)


class MaskingDirector(LosingDirector):
    """A LosingDirector behind HAProxy 2.6: a stream it ends with DATA_LOSS while the client
    still sends reaches the client as CANCELLED (the balancer's RST_STREAM(CANCEL) after the
    node's trailers, haproxy/haproxy#1219; docs/scaling.md); a unary Frame's status arrives whole."""

    async def StreamFrames(self, request_iterator, context):
        async def checked():
            async for update in request_iterator:
                if self._lost(update) is not None:
                    await context.abort(grpc.StatusCode.CANCELLED, "Received RST_STREAM with error code 8")
                yield update

        async for answer in FlakyDirector.StreamFrames(self, checked(), context):
            yield answer


def test_a_data_loss_a_balancer_masks_as_cancelled_is_resent_after_one_unary_try_sync():
    # before: each new stream resent its unanswered updates, was answered DATA_LOSS again and cut
    # again as CANCELLED, until the retry window ran out
    director = MaskingDirector()
    director.losses = {30: 21}
    with serving(director) as url, cd.connect(url, retry=cd.RetryPolicy(retry_window_s=5.0)) as client:
        session = client.create_session(targets=[pb.Target(id="a")])
        answers = [a.frame for a in session.stream(pb.FrameUpdate(frame=f) for f in range(1, 41))]
        assert answers == list(range(1, 41))
        # the stream cut at 30 (CANCELLED); 30 alone as a unary Frame, answered DATA_LOSS whole;
        # 21..29 resent (their answers dropped), then 30, then the stream from 31 on
        assert director.answered[session.id] == list(range(1, 30)) + list(range(21, 41))
        assert session.retries == 2
        assert [frame for frame, _ in director.seen] == [*range(1, 31), 30, *range(21, 31), *range(31, 41)]
        methods = [m for m, s, _ in director.calls if s == session.id]  # a call refused is not recorded
        assert methods == ["CreateSession", "StreamFrames", *["Frame"] * 10, "StreamFrames"]


def test_a_data_loss_a_balancer_masks_as_cancelled_is_resent_after_one_unary_try_async():
    async def main():
        director = MaskingDirector()
        director.losses = {30: 21}
        server = grpc.aio.server()
        pb_grpc.add_DirectorServicer_to_server(director, server)
        port = server.add_insecure_port("127.0.0.1:0")
        await server.start()
        try:
            async with cd.connect_async(f"grpc://127.0.0.1:{port}", retry=cd.RetryPolicy(retry_window_s=5.0)) as client:
                session = await client.create_session(targets=[pb.Target(id="a")])
                return director, session, [a.frame async for a in session.stream(pb.FrameUpdate(frame=f) for f in range(1, 41))]
        finally:
            await server.stop(None)

    director, session, answers = asyncio.run(asyncio.wait_for(main(), 20.0))
    assert answers == list(range(1, 41)) and session.retries == 2
    assert director.answered[session.id] == list(range(1, 30)) + list(range(21, 41))


def test_a_refusal_behind_a_balancers_reset_is_raised_at_once():
    # a revoked key: the node ends the stream UNAUTHENTICATED, the balancer shows CANCELLED; the
    # oldest unanswered update alone gets the refusal itself, raised without further tries
    director = FlakyDirector()
    director.stream_faults = {5: grpc.StatusCode.CANCELLED}
    director.frame_faults = [grpc.StatusCode.UNAUTHENTICATED]
    with serving(director) as url, cd.connect(url) as client:
        session = client.create_session(targets=[pb.Target(id="a")])
        answers: list[int] = []
        with pytest.raises(cd.DirectorError) as refused:
            for answer in session.stream(pb.FrameUpdate(frame=f) for f in range(1, 41)):
                answers.append(answer.frame)
        assert refused.value.code is grpc.StatusCode.UNAUTHENTICATED
        assert answers == [1, 2, 3, 4] and session.retries == 1


def test_every_failure_is_tried_again_until_the_window_is_spent():
    director = FlakyDirector()
    retry = cd.RetryPolicy(retry_window_s=1.5, max_backoff_s=0.1)  # waits of 0.05 to 0.1 s: 15 or more tries
    with serving(director) as url, cd.connect(url, retry=retry) as client:
        session = client.create_session(targets=[pb.Target(id="a")])
        director.frame_faults = [grpc.StatusCode.UNAVAILABLE] * 1000
        with pytest.raises(cd.DirectorError) as caught:
            session.frame(1, 0.0)
        tries = 1000 - len(director.frame_faults)
        # more than the 7 retries of the fixed sequence this replaced
        assert caught.value.code is grpc.StatusCode.UNAVAILABLE and session.retries == tries - 1 > 7
        director.frame_faults = [grpc.StatusCode.UNAVAILABLE] * 3
        assert session.frame(2, 0.0).frame == 2 and session.retries == tries + 2  # a new window


def _stopped(server, stop_s: float) -> None:
    """The server's process and its workers stopped (SIGSTOP) for ``stop_s``: a hung node."""
    pids = [server.proc.pid, *server.worker_pids()]
    for pid in pids:
        os.kill(pid, signal.SIGSTOP)
    time.sleep(stop_s)
    for pid in pids:
        os.kill(pid, signal.SIGCONT)


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
@pytest.mark.parametrize("flavour", ["sync", "async"])
def test_a_stream_of_a_hung_server_is_reopened_and_answers_every_frame_once(server_factory, flavour, transport):
    """A server stopped for 3 s mid-stream: the frame in flight goes unanswered for
    frame_timeout_s, the stream is cancelled and opened again (over ZeroMQ: the frame is sent
    again on a new socket), again while the server stays stopped, and after SIGCONT every update
    is answered once, in order, none lost."""
    server = server_factory("--workers", "1")
    quick = cd.RetryPolicy(frame_timeout_s=1.0)  # shorter than the stop (the default, 3 s, is not)
    frames, stop_at = 120, 40
    create = two_target_request(style=pb.Style(visibility=pb.FRAMING_ONLY), seed=5)
    errors: list[str] = []
    original = wire.SessionBase._retry_after

    def noted(self, error, backoff):
        errors.append(error.message)
        return original(self, error, backoff)

    stopper = threading.Timer(0, lambda: None)

    def paced(session_id):
        for i, update in enumerate(walk(session_id, frames)):
            if i == stop_at:
                stopper.start()
            time.sleep(0.01)
            yield update

    wire.SessionBase._retry_after = noted
    try:
        stopper = threading.Timer(0.0, _stopped, (server, 3.0))
        if flavour == "sync":
            with cd.connect(server.url(transport), retry=quick) as client:
                session = client.create_session(create)
                answers = [a.frame for a in session.stream(paced(session.id))]
                closed = session.close()
        else:

            async def main():
                async with cd.connect_async(server.url(transport), retry=quick) as client:
                    session = await client.create_session(create)
                    answers = [a.frame async for a in session.stream(paced(session.id))]
                    return session, answers, await session.close()

            session, answers, closed = asyncio.run(asyncio.wait_for(main(), 60.0))
    finally:
        wire.SessionBase._retry_after = original
        stopper.join()
    assert answers == list(range(1, frames + 1))
    assert closed == frames  # each frame computed once: no resent one counted twice
    assert errors and all("frame_timeout_s" in e or e.startswith("failed to connect") for e in errors), errors
