"""Session checkpoints (worker/checkpoint_stores.py, worker/checkpointing.py): the two stores held
to one contract, and sessions of every rig restored bit for bit by a session table that never saw
them (a new worker, another node), with the failures a store can have."""

from __future__ import annotations

import io
import pickle
import time

import numpy as np
import pytest

from camdirector.errors import DirectorError
from camdirector.geometry.meshes import box
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker import checkpoint_stores
from camdirector.worker.checkpoint_stores import (
    CheckpointError,
    DirectoryStore,
    RedisStore,
    decode_entry,
    dumps_state,
    encode_entry,
    loads_state,
)
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.replay import _comparable
from camdirector.worker.table import SessionTable
from tests.infra.test_host_address import ScriptedLookup
from tests.service.test_match_sessions import frames as match_frames
from tests.service.test_match_sessions import match_request
from tests.service.tracks_sessions import tracks_request
from tests.service.wire_client import two_target_request, walk


@pytest.fixture(params=["directory", "redis"])
def store_url(request, tmp_path):
    """The checkpoint_store setting of each implementation ("" is the data folder's DirectoryStore)."""
    return request.getfixturevalue("redis_url") if request.param == "redis" else ""


def _requests(
    tmp_path,
    store_url: str,
    owner: str,
    every: int = 20,
    defer_snapshots: bool = False,
    frame_path: str = "python",
    wait_ms: float = 1000.0,
) -> Dispatcher:
    """A session table that checkpoints, with the requests' dispatch a worker puts above it.
    wait_ms: its writes' budget; by default the longest allowed, so that a Redis write slowed by a
    busy machine (CI's two cores) is not taken for a store that does not answer: with the default
    10 ms, a late write left the checkpoint behind and the restored session answered otherwise."""
    table = SessionTable(
        ServerSettings(
            data_dir=str(tmp_path),
            checkpoint_store=store_url,
            checkpoint_every_frames=every,
            frame_path=frame_path,
            checkpoint_wait_ms=wait_ms,
        ),
        defer_snapshots=defer_snapshots,
    )
    table.checkpoints.owner = owner  # one process plays several: each table its own owner
    return Dispatcher(table)


def _reference(data_dir, frame_path: str = "python") -> Dispatcher:
    """A session table that keeps no checkpoints."""
    return Dispatcher(SessionTable(ServerSettings(data_dir=str(data_dir), checkpoint_store="off", frame_path=frame_path)))


def _store(tmp_path, store_url: str):
    return RedisStore(store_url, keep_s=60.0) if store_url else DirectoryStore(tmp_path / "checkpoints", keep_s=60.0)


def test_both_stores_keep_the_same_checkpoint_and_refuse_a_stale_owner(tmp_path, store_url):
    store = _store(tmp_path, store_url)
    assert store.load("s") is None
    store.begin("s", "node-a/1", b"create")
    assert store.append("s", "node-a/1", encode_entry(1, "frame", b"f1"))
    assert store.append("s", "node-a/1", encode_entry(2, "style", b"st"))
    loaded = store.load("s")
    assert (loaded.create, loaded.snapshot, loaded.seq) == (b"create", None, 0)
    assert loaded.entries == [(1, "frame", b"f1"), (2, "style", b"st")]
    assert store.snapshot("s", "node-a/1", 2, b"state")
    assert store.append("s", "node-a/1", encode_entry(3, "take", b"t3"))
    loaded = store.load("s")
    assert (loaded.snapshot, loaded.seq, loaded.entries) == (b"state", 2, [(3, "take", b"t3")])
    # Another process restores the session and claims it: the first one's writes are refused from then on.
    other = _store(tmp_path, store_url)
    assert other.snapshot("s", "node-b/2", 3, b"restored", claim=True)
    assert not store.append("s", "node-a/1", encode_entry(4, "frame", b"late"))
    assert not store.snapshot("s", "node-a/1", 4, b"late")
    store.delete("s", "node-a/1")  # not its owner any more: nothing happens
    assert other.load("s").snapshot == b"restored"
    other.delete("s", "node-b/2")
    assert other.load("s") is None


def test_an_entry_keeps_its_number_kind_and_bytes():
    assert decode_entry(encode_entry(2**40, "take", b"\x00\xff")) == (2**40, "take", b"\x00\xff")


def test_a_snapshot_refers_to_the_creation_objects_by_name_also_as_written_before():
    """dumps_state writes each creation object as a reference by its name, and loads_state gives
    the rebuilt session's object of that name (by identity, wherever the state holds it); a name
    the rebuilt session lacks is refused by name; a snapshot written with persistent ids (before
    2026-12-02) reads the same; a builtin value as a creation object is refused (a pickler would
    copy it without asking)."""
    mesh, other = box((1.0, 1.0, 1.0)), box((2.0, 1.0, 1.0))
    state = {"level": mesh, "again": [mesh, other], "x": np.arange(3.0)}
    written = {"level": mesh, ("target", 0): other}
    rebuilt = {"level": box((1.0, 1.0, 1.0)), ("target", 0): box((2.0, 1.0, 1.0))}

    def as_before() -> bytes:
        class Named(pickle.Pickler):
            def persistent_id(self, obj):
                return {id(mesh): "level", id(other): ("target", 0)}.get(id(obj))

        buffer = io.BytesIO()
        Named(buffer, protocol=5).dump(state)
        return buffer.getvalue()

    for data in (dumps_state(state, written), as_before()):
        back = loads_state(data, rebuilt)
        assert back["level"] is rebuilt["level"] and back["again"][0] is rebuilt["level"]
        assert back["again"][1] is rebuilt[("target", 0)] and np.array_equal(back["x"], state["x"])
        with pytest.raises(pickle.UnpicklingError, match=r"no creation object \('target', 0\)"):
            loads_state(data, {"level": rebuilt["level"]})
    assert len(dumps_state(state, written)) < len(pickle.dumps(state, protocol=5))  # the meshes not copied
    with pytest.raises(pickle.UnpicklingError, match="read by loads_state"):
        pickle.loads(dumps_state(state, written))
    with pytest.raises(TypeError, match=r"\['clock'\] are builtin values"):
        dumps_state(state, {"clock": [1.0]})


def test_a_torn_last_write_is_ignored(tmp_path):
    store = DirectoryStore(tmp_path, keep_s=60.0)
    store.begin("s", "n/1", b"c")
    store.append("s", "n/1", encode_entry(1, "frame", b"whole"))
    with open(tmp_path / "s" / "log", "ab") as log:
        log.write(b"\x00\x00\x00\x40torn")  # a length of 64, then 4 bytes: the process died mid-write
    assert store.load("s").entries == [(1, "frame", b"whole")]


def test_snapshots_go_in_the_log_until_it_is_long_then_start_a_new_one(tmp_path, monkeypatch):
    """DirectoryStore appends a snapshot to the log (one write) while the log is short, and only
    then writes the snapshot file and starts an empty log: the newest snapshot wins either way,
    with the inputs after it, and the log stays bounded."""
    monkeypatch.setattr(checkpoint_stores, "LOG_ROTATE_BYTES", 4096)
    store = DirectoryStore(tmp_path, keep_s=60.0)
    store.begin("s", "n/1", b"c")
    log = tmp_path / "s" / "log"
    seq, sizes, rotations = 0, [], 0
    for k in range(40):
        for _ in range(3):
            seq += 1
            assert store.append("s", "n/1", encode_entry(seq, "frame", b"f" * 100))
        before = log.stat().st_size
        assert store.snapshot("s", "n/1", seq, f"state {k}".encode() * 20)
        rotations += log.stat().st_size == 0
        if log.stat().st_size:
            assert log.stat().st_size > before  # appended: the log kept the inputs before it
        sizes.append(log.stat().st_size)
        seq += 1
        assert store.append("s", "n/1", encode_entry(seq, "style", b"after"))
        loaded = store.load("s")
        assert (loaded.snapshot, loaded.seq, loaded.entries) == (f"state {k}".encode() * 20, seq - 1, [(seq, "style", b"after")])
    assert rotations >= 3 and max(sizes) < 4096 + 1024  # started anew several times, never long
    assert (tmp_path / "s" / "snapshot").exists()  # where a new log's first snapshot went


def test_a_torn_snapshot_in_the_log_leaves_the_one_before_and_the_inputs_since(tmp_path):
    store = DirectoryStore(tmp_path, keep_s=60.0)
    store.begin("s", "n/1", b"c")
    store.append("s", "n/1", encode_entry(1, "frame", b"f1"))
    assert store.snapshot("s", "n/1", 1, b"first")
    store.append("s", "n/1", encode_entry(2, "frame", b"f2"))
    with open(tmp_path / "s" / "log", "ab") as log:  # the process died writing its next snapshot
        log.write(b"\x00\x00\x10\x00" + b"\x00" * 7 + b"\x02\xffpart")
    loaded = store.load("s")
    assert (loaded.snapshot, loaded.seq, loaded.entries) == (b"first", 1, [(2, "frame", b"f2")])


def _answers(dispatcher: Dispatcher, requests: list[tuple[str, str, bytes]]) -> list[bytes]:
    """The comparable part of each frame's answer (recording.py), in order."""
    out = []
    for op, session_id, payload in requests:
        body, _ = dispatcher.handle_bytes(op, session_id, payload)
        if op == "frame":
            out.append(_comparable(pb.CameraUpdate.FromString(body)))
    return out


def _toric_requests(visibility: int, n: int) -> tuple[pb.CreateSessionRequest, list]:
    requests = [("frame", "s", f.SerializeToString()) for f in walk("s", n)]
    # a style change half way, so the restored style and the logged one both count
    style = pb.UpdateStyleRequest(session_id="s", style=pb.Style(visibility=visibility, screen_a=pb.ScreenPoint(x=-0.2, y=0.0)))
    requests.insert(n // 2, ("style", "s", style.SerializeToString()))
    return two_target_request(style=pb.Style(visibility=visibility), seed=7), requests


def _match_requests(n: int) -> tuple[pb.CreateSessionRequest, list]:
    kills = {20: ("a0", "b0"), 55: ("b1", "a1")}
    requests = [("frame", "s", f.SerializeToString()) for f in match_frames("s", n, kill_at=kills)]
    take = pb.TakeShotRequest(session_id="s", subject_ids=["a1", "b1"])
    requests.insert(40, ("take", "s", take.SerializeToString()))
    return match_request(0.5), requests


def _tracks_requests(data_dir) -> tuple[pb.CreateSessionRequest, list]:
    from tests.precompute.tracks.tiny_levels import corridor
    from tests.service.tracks_sessions import actor_frames, cli_add_level, corridor_walk, obj_text

    level_file = data_dir / "corridor.obj"
    level_file.parent.mkdir(parents=True, exist_ok=True)
    level_file.write_text(obj_text(corridor()))
    cli_add_level(data_dir, "corridor", level_file)
    times, feet = corridor_walk(4.0)
    return tracks_request("corridor", feet[0]), [("frame", "s", f.SerializeToString()) for f in actor_frames("s", times, feet)]


@pytest.mark.parametrize(
    "kind, frame_path",
    [(kind, "python") for kind in ("FRAMING_ONLY", "REACTIVE", "RAYCAST", "ANTICIPATION", "MATCH", "TRACKS")]
    + [("FRAMING_ONLY", "compiled"), ("MATCH", "compiled"), ("TRACKS", "compiled")],
)
def test_a_session_restored_elsewhere_answers_as_if_nothing_happened(tmp_path, store_url, kind, frame_path):
    """A table that checkpoints answers part of the inputs; a second table (another worker or
    node) is asked the rest: it restores the session (creation, snapshot, inputs since) and every
    answer equals the one of a table that ran all the inputs without checkpoints, on either frame
    path (the compiled one decodes a replayed input from its bytes written again)."""
    create, requests = (
        _match_requests(120)
        if kind == "MATCH"
        else _tracks_requests(tmp_path)
        if kind == "TRACKS"
        else _toric_requests(getattr(pb, kind), 100)
    )
    # the reference reads the same level registry (TRACKS) but keeps no checkpoints
    reference = _reference(tmp_path, frame_path)
    reference.handle_bytes("create", "s", create.SerializeToString())
    expected = _answers(reference, requests)

    first = _requests(tmp_path, store_url, "node-a/1", frame_path=frame_path)
    first.handle_bytes("create", "s", create.SerializeToString())
    cut = 67  # past three snapshots (every 20 inputs) and seven inputs into the log
    answered = _answers(first, requests[:cut])
    # a write that missed its budget leaves the checkpoint behind: the restore would differ for that
    assert not first.table.held["s"].checkpoint.failed, "a checkpoint write missed its budget"
    second = _requests(tmp_path, store_url, "node-b/2", frame_path=frame_path)
    answered += _answers(second, requests[cut:])
    assert answered == expected
    # the first table is now a stale copy: its next frame restores the newer state before answering
    late = requests[-1][2]
    frame = pb.FrameUpdate.FromString(late)
    frame.frame += 1
    frame.time_s += 1 / 60
    body, _ = first.handle_bytes("frame", "s", frame.SerializeToString())
    reference_body, _ = reference.handle_bytes("frame", "s", frame.SerializeToString())
    assert _comparable(pb.CameraUpdate.FromString(body)) == _comparable(pb.CameraUpdate.FromString(reference_body))


def test_a_checkpoint_that_does_not_restore_is_unavailable_and_the_others_restore(tmp_path):
    first = _requests(tmp_path, "", "n/1", every=5)
    for session_id in ("bad", "good"):
        first.handle_bytes("create", session_id, two_target_request().SerializeToString())
        for update in walk(session_id, 12):
            first.handle_bytes("frame", session_id, update.SerializeToString())
    assert _store(tmp_path, "").snapshot("bad", "n/x", 12, b"not a pickle", claim=True)  # the snapshot kept is not one
    second = _requests(tmp_path, "", "n/2")
    nxt = {sid: list(walk(sid, 1, start_frame=13))[0].SerializeToString() for sid in ("bad", "good")}
    with pytest.raises(DirectorError) as err:
        second.handle_bytes("frame", "bad", nxt["bad"])
    assert err.value.code.name == "UNAVAILABLE" and "could not be restored" in err.value.message
    assert pb.CameraUpdate.FromString(second.handle_bytes("frame", "good", nxt["good"])[0]).frame == 13
    with pytest.raises(DirectorError) as err:
        second.handle_bytes("frame", "never-made", list(walk("never-made", 1))[0].SerializeToString())
    assert err.value.code.name == "NOT_FOUND"


def test_closing_removes_the_checkpoint_and_stopping_keeps_it(tmp_path, store_url):
    requests = _requests(tmp_path, store_url, "n/1")
    for session_id in ("closed", "kept"):
        requests.handle_bytes("create", session_id, two_target_request().SerializeToString())
    requests.handle_bytes("close", "closed", b"")
    requests.table.close_all()
    store = _store(tmp_path, store_url)
    assert store.load("closed") is None and store.load("kept") is not None


def test_with_redis_down_frames_are_still_answered_and_flagged_then_the_checkpoint_is_written_again(tmp_path):
    from camdirector.deploy.services import RedisServer

    redis_server = RedisServer(tmp_path / "redis").start()
    requests = _requests(tmp_path, redis_server.url, "n/1", every=1000)
    requests.handle_bytes("create", "s", two_target_request().SerializeToString())
    updates = [u.SerializeToString() for u in walk("s", 40)]
    for payload in updates[:10]:
        assert not requests.handle_bytes("frame", "s", payload)[1].checkpoint_failed
    redis_server.stop()
    flagged = [requests.handle_bytes("frame", "s", payload)[1].checkpoint_failed for payload in updates[10:20]]
    assert all(flagged)  # answered, and the front's metric counts each
    with pytest.raises(CheckpointError):
        RedisStore(redis_server.url, keep_s=60.0)  # a node started now refuses to (front/main.py)
    restarted = RedisServer(tmp_path / "redis", port=redis_server.port).start()
    try:
        _until(lambda: requests.table.checkpoints.writer.healthy)  # the writer's probe has seen Redis back
        requests.table.held["s"].checkpoint.retry_s = 0.0  # do not wait out the retry interval
        assert not requests.handle_bytes("frame", "s", updates[20])[1].checkpoint_failed
        for payload in updates[21:30]:
            requests.handle_bytes("frame", "s", payload)
        # the checkpoint written again whole (Redis came back empty) restores the session exactly
        other = _requests(tmp_path, restarted.url, "n/2")
        reference = _reference(tmp_path / "ref")
        reference.handle_bytes("create", "s", two_target_request().SerializeToString())
        for payload in updates[:30]:
            reference.handle_bytes("frame", "s", payload)
        assert _answers(other, [("frame", "s", p) for p in updates[30:]]) == _answers(
            reference, [("frame", "s", p) for p in updates[30:]]
        )
    finally:
        restarted.stop()


def _until(condition, timeout_s: float = 20.0) -> None:
    """Waits for `condition()` (another thread's doing), polling; fails after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "the condition never held"
        time.sleep(0.01)


def test_deferred_snapshots_wait_for_idle_work_but_never_past_twice_their_period(tmp_path):
    requests = _requests(tmp_path, "", "n/1", every=10, defer_snapshots=True)  # as a worker's: snapshots in its idle moments
    requests.handle_bytes("create", "s", two_target_request().SerializeToString())
    updates = [u.SerializeToString() for u in walk("s", 32)]
    for payload in updates[:12]:
        requests.handle_bytes("frame", "s", payload)
    store = DirectoryStore(tmp_path / "checkpoints", keep_s=60.0)
    assert store.load("s").snapshot is None and len(store.load("s").entries) == 12  # due, not yet taken
    assert requests.table.idle_work() is False  # taken now, none left
    assert (store.load("s").seq, len(store.load("s").entries)) == (12, 0)
    for payload in updates[12:]:  # never idle: at twice the period the snapshot is taken inline
        requests.handle_bytes("frame", "s", payload)
    assert store.load("s").seq == 12 + 2 * 10


def test_an_input_a_bypassed_table_computes_after_restoring_is_in_the_checkpoint(tmp_path, store_url):
    """Sessions move back and forth while a balancer's view of the nodes settles: A answers, B
    takes the session over, A is asked again (its write is refused: it restores B's newer state and
    computes the input), then C takes it over. C's answers are the undisturbed ones only if the
    input A computed after restoring is in the checkpoint too."""
    create, requests = _toric_requests(pb.FRAMING_ONLY, 100)
    reference = _reference(tmp_path)
    reference.handle_bytes("create", "s", create.SerializeToString())
    expected = _answers(reference, requests)

    a = _requests(tmp_path, store_url, "node-a/1")
    a.handle_bytes("create", "s", create.SerializeToString())
    answered = _answers(a, requests[:30])
    answered += _answers(_requests(tmp_path, store_url, "node-b/2"), requests[30:45])
    answered += _answers(a, requests[45:50])  # bypassed, then asked again
    answered += _answers(_requests(tmp_path, store_url, "node-c/3"), requests[50:])
    assert answered == expected


def test_a_session_restored_from_a_checkpoint_left_behind_says_what_was_lost_and_a_resend_makes_it_exact(tmp_path):
    """Node A answers while Redis is paused (its checkpoint behind), then is lost; B restores the
    older checkpoint. The client, answered up to frame 20, is told DATA_LOSS with the frame to
    resend from; its updates from there, sent again, give the answers it had and then the
    undisturbed ones."""
    import os
    import re
    import signal

    from camdirector.deploy.services import RedisServer

    redis_server = RedisServer(tmp_path / "redis").start()
    try:
        create = two_target_request(style=pb.Style(visibility=pb.FRAMING_ONLY), seed=7)
        updates = [("frame", "s", f.SerializeToString()) for f in walk("s", 40)]
        reference = _reference(tmp_path / "ref")
        reference.handle_bytes("create", "s", create.SerializeToString())
        expected = _answers(reference, updates)

        a = _requests(tmp_path, redis_server.url, "node-a/1", every=1000, wait_ms=ServerSettings().checkpoint_wait_ms)
        a.handle_bytes("create", "s", create.SerializeToString())
        assert _answers(a, updates[:10]) == expected[:10]
        os.kill(redis_server.proc.pid, signal.SIGSTOP)
        try:
            assert _answers(a, updates[10:20]) == expected[10:20]  # answered; the checkpoint stops at frame 10
        finally:
            os.kill(redis_server.proc.pid, signal.SIGCONT)
        a.table.checkpoints.writer.close()  # A is lost: what it had given the store is made, nothing more

        b = _requests(tmp_path, redis_server.url, "node-b/2")
        _, _, payload = updates[20]
        update = pb.FrameUpdate.FromString(payload)
        update.answered_frame = pb.FrameUpdate.FromString(updates[19][2]).frame
        with pytest.raises(DirectorError) as lost:
            b.handle_bytes("frame", "s", update.SerializeToString())
        assert lost.value.code.name == "DATA_LOSS"
        resend_from = int(re.search(r"resend from (\d+)", lost.value.message).group(1))
        first = next(i for i, (_, _, p) in enumerate(updates) if pb.FrameUpdate.FromString(p).frame == resend_from)
        assert 10 <= first <= 11  # frame 10's input was written; frame 11's, in flight at the pause, may have been
        resent = []
        for _, _, p in updates[first:]:
            again = pb.FrameUpdate.FromString(p)
            again.answered_frame = update.answered_frame
            resent.append(("frame", "s", again.SerializeToString()))
        assert _answers(b, resent) == expected[first:]
    finally:
        redis_server.stop()


def test_a_frame_sent_again_is_answered_stale_with_its_own_pose_here_and_after_a_restore(tmp_path, store_url):
    """A stream cut with frames in flight (a node slow to answer, then lost) sends them again: each
    is answered with the pose it had, not the newest one, by the table that answered it and by one
    that restored the session from its checkpoint."""
    a = _requests(tmp_path, store_url, "node-a/1")
    a.handle_bytes("create", "s", two_target_request().SerializeToString())
    updates = [u.SerializeToString() for u in walk("s", 12)]
    first = [pb.CameraUpdate.FromString(a.handle_bytes("frame", "s", p)[0]) for p in updates]
    assert first[8].pose != first[11].pose  # the camera moves: a wrong pose would show
    for table in (a, _requests(tmp_path, store_url, "node-b/2")):
        again = pb.CameraUpdate.FromString(table.handle_bytes("frame", "s", updates[8])[0])
        assert again.stale and again.frame == first[8].frame and again.pose == first[8].pose


def test_redis_connections_go_to_the_address_found_and_never_wait_on_a_lookup_again(redis_url):
    port = redis_url.rsplit(":", 1)[1].split("/")[0]
    lookup = ScriptedLookup(["127.0.0.1"])
    store = RedisStore(f"redis://checkpoints.test:{port}/0", keep_s=60.0, check=False, lookup=lookup)
    store.begin("s", "n/1", b"create")
    import redis

    admin = redis.from_url(redis_url)
    admin.client_kill_filter(_type="normal", skipme=True)  # the store's connection dropped (Redis restarted, say)
    store.address.refresh()  # a lookup is under way, and stalls (_Lookup has no answer to give)
    _until(lambda: lookup.calls == 2)
    assert store.append("s", "n/1", encode_entry(1, "frame", b"f"))  # connected again, to the address found
    assert store.load("s").entries == [(1, "frame", b"f")] and store.ping()
    lookup.give(["127.0.0.1"])
    admin.close()
    store.close()


def test_redis_calls_before_any_lookup_answered_fail_at_once_and_a_moved_store_is_found_again(redis_url):
    port = redis_url.rsplit(":", 1)[1].split("/")[0]
    lookup = ScriptedLookup()
    store = RedisStore(f"redis://checkpoints.test:{port}/0", keep_s=60.0, timeout_s=0.05, check=False, lookup=lookup)
    with pytest.raises(CheckpointError, match="no address of checkpoints.test is known"):
        store.begin("s", "n/1", b"create")
    assert not store.ping()
    lookup.give(["127.0.0.2"])  # nothing listens there: refused
    _until(lambda: store.address.current == "127.0.0.2")
    with pytest.raises(CheckpointError):
        store.begin("s", "n/1", b"create")
    lookup.give(["127.0.0.1"])  # the lookup that failure started finds where Redis is now
    _until(lambda: store.address.current == "127.0.0.1")
    store.begin("s", "n/1", b"create")
    assert store.load("s").create == b"create"
    store.close()
