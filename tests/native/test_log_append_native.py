"""camdirector._native.append_log (native/src/log_append_py.rs), DirectoryStore.append's write,
against the Python it replaced on identical inputs: _owns's test (the log file still linked) and
os.write(fd, _LENGTH.pack(len(entry)) + entry): the same bytes in the file, entry after entry,
and nothing written to a log that a restore elsewhere has replaced."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest

from camdirector._native import append_log
from camdirector.worker.checkpoint_stores import DirectoryStore, decode_entry, encode_entry

LENGTH = struct.Struct("!I")  # checkpoint_stores._LENGTH, written out: the format is the contract


def _reference_append(fd: int, entry: bytes) -> bool:
    """What DirectoryStore.append wrote before (its _owns, then one os.write)."""
    if os.fstat(fd).st_nlink == 0:
        return False
    os.write(fd, LENGTH.pack(len(entry)) + entry)
    return True


def test_the_same_bytes_as_the_python_append(tmp_path):
    rng = np.random.default_rng(3)
    ops = ["frame"] * 40 + ["style", "take"]
    entries = [encode_entry(seq, op, rng.bytes(int(rng.integers(0, 3000)))) for seq, op in enumerate(ops)]
    entries.append(b"")  # an empty entry is written as its length alone
    files = []
    for name, append in (("native", append_log), ("python", _reference_append)):
        path = tmp_path / name
        path.touch()
        fd = os.open(path, os.O_WRONLY | os.O_APPEND)
        try:
            assert all(append(fd, entry) for entry in entries)
        finally:
            os.close(fd)
        files.append(path.read_bytes())
    assert files[0] == files[1]
    assert len(files[0]) == sum(LENGTH.size + len(e) for e in entries)


def test_an_unlinked_log_is_not_written(tmp_path):
    path = tmp_path / "log"
    path.write_bytes(b"kept")
    fd = os.open(path, os.O_WRONLY | os.O_APPEND)
    try:
        os.unlink(path)  # another process restored the session: a new log in its place
        assert append_log(fd, b"late") is False
        assert os.fstat(fd).st_size == 4
    finally:
        os.close(fd)


def test_a_closed_descriptor_is_an_os_error(tmp_path):
    path = tmp_path / "log"
    path.touch()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND)
    os.close(fd)
    with pytest.raises(OSError):
        append_log(fd, b"entry")


def test_the_store_reads_back_what_it_appended(tmp_path):
    store = DirectoryStore(tmp_path, keep_s=60.0)
    store.begin("s", "n/1", b"create")
    entries = [encode_entry(seq, "frame", bytes([seq]) * seq) for seq in range(1, 30)]
    assert all(store.append("s", "n/1", entry) for entry in entries)
    checkpoint = store.load("s")
    assert checkpoint is not None
    assert [(seq, op, payload) for seq, op, payload in checkpoint.entries] == [decode_entry(e) for e in entries]
    store.close()
