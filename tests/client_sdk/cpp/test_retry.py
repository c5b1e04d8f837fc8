"""Issue 40 in the C/C++ SDK's I/O thread: a broken or hung stream's unanswered frames sent again on
the next one, DATA_LOSS "resend from K" answered by sending the kept frames again, and a session
given up once nothing answered for its retry window (SESSION_FAILED, UNAVAILABLE).

Against the Python SDK tests' grpc.aio Director (test_aio_failover.FlakyDirector,
test_retry.LosingDirector), which fails on demand as a real server cannot be made to; the
backoff's arithmetic is in the SDK's unit tests (tests/unit_tests.cpp, run by test_ctest.py).
`sdk_check retry` flushes every frame before the next, so each frame's answered_frame is known.
"""

from __future__ import annotations

import asyncio

import grpc

from tests.client_sdk.cpp.conftest import run_json
from tests.client_sdk.test_aio_failover import FlakyDirector
from tests.client_sdk.test_retry import LosingDirector, serving


def _kinds(report: dict) -> list[str]:
    return [e["kind"] for e in report["events"]]


def test_a_broken_stream_sends_its_unanswered_frame_again(sdk_bin):
    director = FlakyDirector()
    director.stream_faults = {20: grpc.StatusCode.UNAVAILABLE}  # the stream ends on frame 20, unanswered
    with serving(director) as url:
        report = run_json(sdk_bin / "sdk_check", "retry", url, "30", "30")
    session = report["first_session_id"]
    assert director.answered[session] == list(range(1, 31)), director.streamed  # frame 20 on the second stream
    assert report["pose_frames"] == list(range(1, 31))
    assert _kinds(report) == ["STREAMING", "DISCONNECTED", "RESUMED"], report["events"]
    assert report["stats"]["frames_lost"] == 0 and report["stats"]["streams_opened"] == 2, report["stats"]


def test_a_data_loss_sends_the_kept_frames_again_and_the_pose_does_not_go_back(sdk_bin):
    director = LosingDirector()
    director.losses = {30: 21}  # a restore that lost frames 21..29, all answered already
    with serving(director) as url:
        report = run_json(sdk_bin / "sdk_check", "retry", url, "40", "30")
    session = report["first_session_id"]
    assert director.answered[session] == list(range(1, 30)) + list(range(21, 41))
    # Each frame says the newest answer; sent again, never past the frame sent before it.
    assert director.seen[:30] == [(f, f - 1) for f in range(1, 31)]
    assert director.seen[30:] == [(f, f - 1) for f in range(21, 41)]
    assert report["pose_frames"] == list(range(1, 41))  # the resent frames' answers did not replace newer poses
    assert _kinds(report) == ["STREAMING", "DISCONNECTED", "RESUMED"], report["events"]
    assert report["events"][1]["status"] == "DATA_LOSS" and report["last_session_id"] == session
    assert report["close"] == "OK"


def test_a_data_loss_beyond_the_kept_frames_fails_the_session(sdk_bin):
    director = LosingDirector()
    director.losses = {650: 2}  # frame 2 is gone from the 600 frames kept by then: fail, do not go on
    with serving(director) as url:
        report = run_json(sdk_bin / "sdk_check", "retry", url, "660", "30", timeout_s=120.0)
    assert report["events"][-1]["kind"] == "SESSION_FAILED" and report["events"][-1]["status"] == "DATA_LOSS"
    assert "resend_history_frames" in report["events"][-1]["message"], report["events"]
    assert report["pose_frames"][-1] == 649 and report["stats"]["state"] == 5  # CD_STATE_FAILED


class _ArrivalDirector(FlakyDirector):
    """FlakyDirector whose streams pass each update to `arrived` before answering it."""

    async def arrived(self, update, context) -> None:
        raise NotImplementedError

    async def StreamFrames(self, request_iterator, context):
        async def watched():
            async for update in request_iterator:
                await self.arrived(update, context)
                yield update

        async for answer in super().StreamFrames(watched(), context):
            yield answer


class HangingDirector(_ArrivalDirector):
    """Leaves frame 10 unanswered on the first stream that receives it: a hung node."""

    def __init__(self) -> None:
        super().__init__()
        self.hung = False

    async def arrived(self, update, context) -> None:
        if update.frame == 10 and not self.hung:
            self.hung = True
            await asyncio.sleep(60)


def test_a_hung_stream_is_reopened_after_the_frame_timeout_and_the_frame_answered(sdk_bin):
    director = HangingDirector()
    with serving(director) as url:
        report = run_json(sdk_bin / "sdk_check", "retry", url, "12", "30")
    assert director.answered[report["first_session_id"]] == list(range(1, 13))
    assert _kinds(report) == ["STREAMING", "DISCONNECTED", "RESUMED"], report["events"]
    disconnected = report["events"][1]
    assert disconnected["status"] == "UNAVAILABLE" and "frame 10" in disconnected["message"], disconnected
    assert "frame_timeout_s" in disconnected["message"]


class DeadAfterDirector(_ArrivalDirector):
    """Every stream ends UNAVAILABLE on frame 5 and later: a node lost for good."""

    async def arrived(self, update, context) -> None:
        if update.frame >= 5:
            self.streamed.append([update.frame])
            await context.abort(grpc.StatusCode.UNAVAILABLE, "no node holds this session")


def test_a_session_unanswered_for_its_retry_window_fails(sdk_bin):
    director = DeadAfterDirector()
    with serving(director) as url:
        report = run_json(sdk_bin / "sdk_check", "retry", url, "10", "0.5")
    assert report["pose_frames"] == [1, 2, 3, 4, 4]
    failed = report["events"][-1]
    assert failed["kind"] == "SESSION_FAILED" and failed["status"] == "UNAVAILABLE", report["events"]
    assert "retry_window_s" in failed["message"]
    assert report["stats"]["state"] == 5 and report["stats"]["streams_opened"] >= 3, report["stats"]
