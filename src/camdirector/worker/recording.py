"""Session recordings: a length-delimited stream of camdirector.v1.RecordEntry (replay.py runs one again).

File layout: the 8-byte magic ``CDREC\\x00v1``, then entries, each a base-128 varint byte length
followed by one serialized RecordEntry (the same framing as protobuf's writeDelimitedTo). The
first entry is the CreateSessionRequest; then, in the order the server handled them, every
FrameUpdate followed by the CameraUpdate it was answered with, and every UpdateStyleRequest.
A file cut short by a crash reads up to its last whole entry.
"""

from __future__ import annotations

from collections.abc import Iterator
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
        yield pb.RecordEntry.FromString(data[pos : pos + length])
        pos += length
