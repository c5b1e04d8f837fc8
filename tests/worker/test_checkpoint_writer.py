"""The checkpoint writer (worker/checkpoint_writer.py): a store that hangs holds up no frame, and
the calls given to it are made in order once it answers."""

from __future__ import annotations

import threading

import pytest

from camdirector.server_settings import ServerSettings
from camdirector.worker.checkpoint_stores import CheckpointError, DirectoryStore
from camdirector.worker.checkpoint_writer import CheckpointWriter
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.table import SessionTable
from tests.service.wire_client import two_target_request, walk
from tests.worker.test_checkpoints import _until


class _HangingStore(DirectoryStore):
    """A DirectoryStore whose appends wait for `released` once `hang` is set: a store that stops
    answering (the only stand-in here: it isolates the frame path from the store's calls)."""

    may_hang = True  # as a store on another machine: written off the frame path

    def __init__(self, root, keep_s):
        super().__init__(root, keep_s)
        self.hang = threading.Event()
        self.released = threading.Event()

    def append(self, session_id, owner, entry):
        if self.hang.is_set():
            self.released.wait()
        return super().append(session_id, owner, entry)


def test_a_store_that_stops_answering_holds_up_no_frame_and_catches_up_when_it_answers(tmp_path):
    store = _HangingStore(tmp_path / "checkpoints", keep_s=60.0)
    # 100 ms, not the default 10: a write to a folder that answers must never be taken for a hung
    # store on a busy machine (CI's two cores); a hung one still holds up only the first frame
    settings = ServerSettings(data_dir=str(tmp_path), checkpoint_every_frames=1000, checkpoint_wait_ms=100.0)
    requests = Dispatcher(SessionTable(settings, store=store))
    requests.handle_bytes("create", "s", two_target_request().SerializeToString())
    updates = [u.SerializeToString() for u in walk("s", 30)]
    for payload in updates[:5]:
        assert not requests.handle_bytes("frame", "s", payload)[1].checkpoint_failed
    store.hang.set()
    try:
        _stream_while_hung(requests, updates[5:15], store)
    finally:
        store.released.set()  # never leave the writer, or a thread of this test, waiting
    writer = requests.table.checkpoints.writer
    _until(lambda: not writer.stuck(0.0) and writer.healthy)
    requests.table.held["s"].checkpoint.retry_s = 0.0  # do not wait out the retry interval
    assert not requests.handle_bytes("frame", "s", updates[15])[1].checkpoint_failed  # written again whole
    loaded = DirectoryStore(tmp_path / "checkpoints", keep_s=60.0).load("s")
    assert loaded.seq == 16 and loaded.snapshot is not None


def _stream_while_hung(requests: Dispatcher, updates: list[bytes], store: _HangingStore) -> None:
    """Streams `updates` on a thread while the store hangs: each is answered, flagged (the
    checkpoint is behind), without the store having answered."""
    answered: list[bool] = []
    streaming = threading.Thread(
        target=lambda: answered.extend(requests.handle_bytes("frame", "s", p)[1].checkpoint_failed for p in updates)
    )
    streaming.start()
    streaming.join(60.0)  # writes made inline would wait for the store for ever
    assert not streaming.is_alive() and not store.released.is_set()
    assert answered == [True] * len(updates)


def test_calls_are_made_in_order_and_a_failure_is_the_callers_error():
    made: list[int] = []
    writer = CheckpointWriter(probe=lambda: True)

    def fail():
        raise CheckpointError("down")

    pendings = [writer.call(made.append, n) for n in range(50)]
    failed = writer.call(fail)
    last = writer.call(made.append, 50)
    assert [p.result(30.0) for p in pendings] == [None] * 50
    with pytest.raises(CheckpointError, match="down"):
        failed.result(30.0)
    last.result(30.0)
    assert made == list(range(51)) and writer.healthy  # the call after the failure reached the store
    writer.close()
