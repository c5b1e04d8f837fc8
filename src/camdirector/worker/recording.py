"""Session recordings: a length-delimited stream of camdirector.v1.RecordEntry, and replay.

File layout: the 8-byte magic ``CDREC\\x00v1``, then entries, each a base-128 varint byte length
followed by one serialized RecordEntry (the same framing as protobuf's writeDelimitedTo). The
first entry is the CreateSessionRequest; then, in the order the server handled them, every
FrameUpdate followed by the CameraUpdate it was answered with, and every UpdateStyleRequest.
A file cut short by a crash reads up to its last whole entry.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from camdirector.v1 import director_pb2 as pb

MAGIC = b"CDREC\x00v1"
# RecordEntry's keys for its `frame` (2) and `camera` (4) fields, length-delimited (wire type 2).
_FRAME_TAG = bytes([2 << 3 | 2])
_CAMERA_TAG = bytes([4 << 3 | 2])


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        byte = n & 0x7F
        n >>= 7
        if n:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


class RecordingWriter:
    """Appends entries; flushes every `flush_every` entries so a crash loses little. With
    `append`, goes on with an existing recording (a session restored from its checkpoint)."""

    def __init__(self, path: Path, flush_every: int = 60, append: bool = False):
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        if append and path.exists():
            self._file: BinaryIO = open(path, "ab")
        else:
            self._file = open(path, "wb")
            self._file.write(MAGIC)
        self._flush_every = flush_every
        self._pending = 0

    def write(self, entry: pb.RecordEntry) -> None:
        self._append(entry.SerializeToString())

    def write_frame_and_camera(self, frame_bytes: bytes, camera_bytes: bytes) -> None:
        """A frame and its answer as they crossed the wire, serialized once: each is the one
        length-delimited field of its RecordEntry (`frame` = 2, `camera` = 4), written as such."""
        self._append(_FRAME_TAG + _varint(len(frame_bytes)) + frame_bytes)
        self._append(_CAMERA_TAG + _varint(len(camera_bytes)) + camera_bytes)

    def _append(self, data: bytes) -> None:
        self._file.write(_varint(len(data)))
        self._file.write(data)
        self._pending += 1
        if self._pending >= self._flush_every:
            self._file.flush()
            self._pending = 0

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


def read_entries(path: Path) -> Iterator[pb.RecordEntry]:
    data = Path(path).read_bytes()
    if not data.startswith(MAGIC):
        raise ValueError(f"{path} is not a camdirector recording (bad magic)")
    pos = len(MAGIC)
    while pos < len(data):
        length, shift = 0, 0
        while True:
            if pos >= len(data):
                return  # cut inside a length prefix
            byte = data[pos]
            pos += 1
            length |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                break
        if pos + length > len(data):
            return  # cut inside an entry
        yield pb.RecordEntry.FromString(data[pos:pos + length])
        pos += length


@dataclass
class ReplayReport:
    frames: int          # CameraUpdates recorded
    identical: int       # replayed poses equal to the recorded ones bit for bit
    first_mismatch: int | None  # frame number of the first difference

    @property
    def ok(self) -> bool:
        return self.frames == self.identical

    def as_dict(self) -> dict:
        return {"frames": self.frames, "identical": self.identical,
                "first_mismatch": self.first_mismatch, "ok": self.ok}


def _comparable(update: pb.CameraUpdate) -> bytes:
    """The part of a CameraUpdate that must replay bit for bit (not timings, not diagnostics)."""
    return pb.CameraUpdate(frame=update.frame, time_s=update.time_s, pose=update.pose, cut=update.cut,
                           shot_id=update.shot_id, visibility=update.visibility, stale=update.stale,
                           shot=update.shot, buffering=update.buffering).SerializeToString(deterministic=True)


def replay(path: Path, on_frame=None, data_dir: Path | None = None) -> ReplayReport:
    """Runs a recording through a fresh in-process session and compares every answer.

    data_dir: where the recording's TRACKS level is registered; by default the data directory the
    recording lies in (`<data_dir>/recordings/<session>.cdrec`), else the server's default."""
    from camdirector.server_settings import ServerSettings
    from camdirector.worker.table import SessionTable

    limits = dict(max_objects=1_000_000, max_triangles=100_000_000, checkpoint_store="off")  # a replay keeps no checkpoints
    if data_dir is None and Path(path).resolve().parent.name == "recordings":
        data_dir = Path(path).resolve().parent.parent
    if data_dir is not None:
        limits["data_dir"] = str(data_dir)
    table = SessionTable(ServerSettings(**limits))
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
