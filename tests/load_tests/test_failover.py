"""load_tests.failover at a small size, in `make test`: a worker SIGKILL on one node and a node
SIGKILL in a two-node cluster behind HAProxy lose no session and no frame, and every answer equals
the undisturbed session's. Its recovery times are printed, never asserted (a loaded CI machine)."""

from __future__ import annotations

import pytest

from load_tests.failover import run


@pytest.mark.parametrize("kill, nodes", [("worker", 1), ("node", 2)])
def test_no_session_and_no_frame_is_lost_and_every_pose_is_the_undisturbed_one(kill, nodes, redis_server):
    # redis_server: skips with the reason (CI fails) where Debian's cluster packages are missing
    report = run(kill, nodes, sessions=6, rate_hz=60.0, seconds=6.0, kill_after_s=2.5)
    print(report)
    assert report["sessions_lost"] == 0, report["errors"]
    assert report["frames_not_answered"] == 0, report["unanswered_per_session"]
    assert report["max_pose_difference"] == 0.0
    _tried_again_at_most_as_the_kill_needs(report)


def _tried_again_at_most_as_the_kill_needs(report: dict) -> None:
    """Each stream is cut once by the kill (CANCELLED) and never again: a live node answers its
    next try, or at worst the balancer refuses one try it had put on the dead node's connection
    before it saw it die (REFUSED_STREAM: UNAVAILABLE, nothing processed), and the live node asks
    once for a resend (DATA_LOSS "resend from K": the node's checkpoint was behind, e.g. its store
    slow on a loaded machine). A CI run before the SDK's fix for HAProxy's masked DATA_LOSS tried
    27 times for 6 sessions, each stream cut again and again."""
    codes = report["retries_by_code"]
    assert set(codes) <= {"CANCELLED", "UNAVAILABLE", "DATA_LOSS"}, report["retry_reasons"]
    assert codes.get("CANCELLED", 0) <= report["sessions"], report["retry_reasons"]
    assert max(report["retries_per_session"]) <= 3, report["retry_reasons"]


def test_a_node_lost_with_its_checkpoints_behind_costs_one_resend_per_session(redis_server):
    # The store stopped around the kill: the survivor restores each session from a checkpoint
    # behind its client and answers DATA_LOSS "resend from K". HAProxy 2.6 resets such a stream
    # (RST_STREAM CANCEL) right after the server's answer while the client still sends, and the
    # client read CANCELLED instead, resent the wrong frames, and was cut again, over and over
    # (8 tries for one session before the SDK sent its oldest update alone after a reset).
    report = run("node", 2, sessions=6, rate_hz=60.0, seconds=6.0, kill_after_s=2.5, store_paused_s=0.4)
    print(report)
    assert report["sessions_lost"] == 0, report["errors"]
    assert report["frames_not_answered"] == 0, report["unanswered_per_session"]
    assert report["max_pose_difference"] == 0.0
    assert report["retries_by_code"].get("DATA_LOSS", 0) >= 1, report["retry_reasons"]  # the case under test happened
    _tried_again_at_most_as_the_kill_needs(report)
