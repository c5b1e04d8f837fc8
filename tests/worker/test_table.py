"""What a session table keeps of each answered frame (worker/table.py, worker/timeline.py)."""

from __future__ import annotations

import gc

import pytest

from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.table import ANSWERS_KEPT, SessionTable
from camdirector.worker.timeline import TIMELINE_FRAMES
from tests.service.wire_client import two_target_request, walk


@pytest.mark.parametrize("frame_path", ["compiled", "python"])
def test_answered_frames_add_nothing_the_collector_walks(tmp_path, frame_path):
    """A TORIC session's timeline and kept answers hold its last frames as objects the collector
    does not track, so a worker's full collection does not grow with them (timeline.py's
    TimelineFrame: 38,400 such frames made a 64-session worker's 13-25 ms); a frame sent again is
    still answered with its own kept answer."""
    table = SessionTable(ServerSettings(data_dir=str(tmp_path), checkpoint_store="off", frame_path=frame_path))
    requests = Dispatcher(table)
    requests.handle_bytes("create", "s", two_target_request(seed=3).SerializeToString())
    frames = [f.SerializeToString() for f in walk("s", 300)]
    answers = {}

    def tracked_after(first: int, last: int) -> int:
        for i in range(first, last):
            answers[i + 1] = requests.handle_bytes("frame", "s", frames[i])[0]  # bytes: untracked
        gc.collect()
        return len(gc.get_objects())

    before = tracked_after(0, 50)
    after = tracked_after(50, 300)  # 250 frames more in the timeline, ANSWERS_KEPT answers replaced
    assert ANSWERS_KEPT < 250 < TIMELINE_FRAMES
    assert after - before < 25  # before: one tracked TimelineFrame a frame and one tracked answer a kept one
    resent = pb.CameraUpdate.FromString(requests.handle_bytes("frame", "s", frames[289])[0])
    assert resent.stale and resent.frame == 290 and resent.pose == pb.CameraUpdate.FromString(answers[290]).pose
    table.close_all()
