"""Replay of a session recording (recording.py's `.cdrec` files): its inputs run through a fresh
session table in this process, every answer compared with the recorded one.

A session is deterministic (the same creation request and inputs give the same poses, bit for
bit), so a recording made on one machine kind replays identically on it (`camdirector replay`,
tests/data/recordings/). What must match is the answer less its timings and diagnostics
(`_comparable`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.recording import read_entries
from camdirector.worker.table import SessionTable


@dataclass
class ReplayReport:
    frames: int  # CameraUpdates recorded
    identical: int  # replayed poses equal to the recorded ones bit for bit
    first_mismatch: int | None  # frame number of the first difference

    @property
    def ok(self) -> bool:
        return self.frames == self.identical

    def as_dict(self) -> dict[str, int | bool | None]:
        return {"frames": self.frames, "identical": self.identical, "first_mismatch": self.first_mismatch, "ok": self.ok}


def _comparable(update: pb.CameraUpdate) -> bytes:
    """The part of a CameraUpdate that must replay bit for bit (not timings, not diagnostics)."""
    return pb.CameraUpdate(
        frame=update.frame,
        time_s=update.time_s,
        pose=update.pose,
        cut=update.cut,
        shot_id=update.shot_id,
        visibility=update.visibility,
        stale=update.stale,
        shot=update.shot,
        buffering=update.buffering,
    ).SerializeToString(deterministic=True)


def replay(
    path: Path,
    on_frame: Callable[[pb.CameraUpdate, pb.CameraUpdate | None], None] | None = None,
    data_dir: Path | None = None,
    frame_path: str = ServerSettings.frame_path,
) -> ReplayReport:
    """Runs a recording through a fresh in-process session and compares every answer.

    on_frame: called with each recorded answer and the replayed one (None: no frame was replayed
    before it). data_dir: where the recording's TRACKS level is registered; by default the data
    directory the recording lies in (`<data_dir>/recordings/<session>.cdrec`), else the server's default.
    frame_path: the server's (server_settings.py) that made the recording, which the file does not
    say: a recording replays bit for bit only on the path that made it (the paths agree within
    1e-9, not to the bit)."""
    if data_dir is None and Path(path).resolve().parent.name == "recordings":
        data_dir = Path(path).resolve().parent.parent
    # A replay keeps no checkpoints, and takes whatever scene the recording holds.
    settings = ServerSettings(max_objects=1_000_000, max_triangles=100_000_000, checkpoint_store="off", frame_path=frame_path)
    if data_dir is not None:
        settings = dataclasses.replace(settings, data_dir=str(data_dir))
    table = SessionTable(settings)
    session_id = "replay"
    report = ReplayReport(frames=0, identical=0, first_mismatch=None)
    replayed: pb.CameraUpdate | None = None
    for entry in read_entries(path):
        kind = entry.WhichOneof("entry")
        if kind == "create":
            # A replay answers the frames again, it does not broadcast them: no datagram goes to the
            # recorded pose outputs' addresses (which need not even resolve on this machine).
            entry.create.ClearField("pose_outputs")
            table.create(session_id, entry.create)
        elif kind == "frame":
            frame = pb.FrameUpdate()
            frame.CopyFrom(entry.frame)
            frame.session_id = session_id
            replayed = table.frame(frame)
        elif kind == "style":
            table.update_style(pb.UpdateStyleRequest(session_id=session_id, style=entry.style.style))
        elif kind == "take":
            take = pb.TakeShotRequest()
            take.CopyFrom(entry.take)
            take.session_id = session_id
            table.take_shot(take)
        elif kind == "camera":
            report.frames += 1
            if replayed is not None and _comparable(replayed) == _comparable(entry.camera):
                report.identical += 1
            elif report.first_mismatch is None:
                report.first_mismatch = entry.camera.frame
            if on_frame is not None:
                on_frame(entry.camera, replayed)
            replayed = None
    return report
