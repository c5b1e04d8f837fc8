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
    assert report["retries"] <= report["sessions"]  # at most one per stream
