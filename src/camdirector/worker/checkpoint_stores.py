"""Session checkpoints as kept: their format and the stores that keep them. What writes them
and restores a session from one (the checkpoint protocol) is checkpointing.py's.

A checkpoint is the session's creation request, a snapshot of its state, and the inputs it took
since that snapshot (frames, style changes, takes), each with its sequence number
(`encode_entry`). The snapshot is the pickled session (pipeline state, RNG, style; `dumps_state`).
What the session was built from and never changes (meshes, the level, the clock:
`Session.creation_objects`) is pickled by name and taken from the freshly built session on restore
(`loads_state`), so a snapshot holds state, not geometry; classes that hold native handles (Embree
scenes, GL objects) pickle as what rebuilds them (geometry/raycast.py, geometry/toric_maps/). A
snapshot supersedes the inputs before it, and each store keeps a session's checkpoint bounded.

Every write names its owner (node and process); a store refuses a write by a process that is no
longer the owner, and `snapshot(..., claim=True)` makes a restoring process the owner: the fence
between nodes (checkpointing.py).

Two stores behind `CheckpointStore`, tested against each other (tests/worker/test_checkpoints.py):
- `DirectoryStore`, the embedded default: files under `<data_dir>/checkpoints/`, one folder per
  session. The page cache keeps what a killed worker wrote; the node's restart finds them too.
- `RedisStore`: Redis (`--checkpoint-store redis://...`), so any node can restore any session. Each
  write is one script call (the owner checked and the entry added in one round trip); the keys of
  one session share a hash tag, so they stay together on Redis Cluster.
"""

from __future__ import annotations

import io
import logging
import os
import pickle
import shutil
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import camdirector._native as native
from camdirector.infra.host_address import Lookup, lookup_stream_addresses, redis_pool
from camdirector.infra.redaction import redacted
from camdirector.pipeline.session import CreationName

log = logging.getLogger("camdirector.checkpoints")

OPS = ("frame", "style", "take")  # the inputs a checkpoint keeps, by code
OP_CODES = {name: code for code, name in enumerate(OPS)}
_ENTRY = struct.Struct("!QB")  # sequence number, op code; then the request's bytes
_LENGTH = struct.Struct("!I")  # DirectoryStore's log: each entry's length first
_SEQ = struct.Struct("!Q")  # DirectoryStore's snapshot file: its sequence number first
_SNAPSHOT_CODE = 255  # DirectoryStore's log: an entry with this op code is a snapshot (its bytes the state)
LOG_ROTATE_BYTES = 1 << 20  # DirectoryStore: a snapshot is appended to a log shorter than this, else starts a new one, bytes


class CheckpointError(RuntimeError):
    """The store cannot be reached or written (Redis down, disk full)."""


@dataclass
class Checkpoint:
    """One session's checkpoint as loaded: `entries` are (seq, op, request bytes) after `seq`."""

    create: bytes  # the serialized CreateSessionRequest
    snapshot: bytes | None  # the pickled state (dumps_state), None before the first
    seq: int  # inputs the snapshot includes
    entries: list[tuple[int, str, bytes]]


def encode_entry(seq: int, op: str, payload: bytes) -> bytes:
    return _ENTRY.pack(seq, OP_CODES[op]) + payload


def decode_entry(data: bytes) -> tuple[int, str, bytes]:
    seq, code = _ENTRY.unpack_from(data)
    return seq, OPS[code], data[_ENTRY.size :]


class CheckpointStore(Protocol):
    """Where checkpoints live. Writes name their `owner` (node/pid); False means another owner
    has claimed the session since (the caller's copy is stale). Errors: CheckpointError.
    `may_hang`: a call can wait on another machine (its writes are then made off the frame path,
    checkpoint_writer.py)."""

    may_hang: bool

    def begin(self, session_id: str, owner: str, create: bytes) -> None:
        """A new session: its creation request, no snapshot, an empty log; `owner` owns it."""

    def append(self, session_id: str, owner: str, entry: bytes) -> bool:
        """One input (encode_entry), if `owner` still owns the session."""

    def snapshot(self, session_id: str, owner: str, seq: int, state: bytes, claim: bool = False) -> bool:
        """Replaces the snapshot and empties the log, if `owner` owns the session; with `claim`,
        makes `owner` the owner first (a restore)."""

    def load(self, session_id: str) -> Checkpoint | None:
        """The session's checkpoint, None when there is none."""

    def delete(self, session_id: str, owner: str) -> None:
        """Removes the checkpoint, if `owner` owns it (a session closed or reclaimed)."""

    def forget(self, session_id: str) -> None:
        """Lets go of what this process keeps open for the session (files); the checkpoint stays."""

    def ping(self) -> bool:
        """Whether the store answers now (its cheapest call; never raises)."""

    def close(self) -> None: ...


def open_store(url: str, data_dir: str | Path, keep_s: float, check: bool = False) -> CheckpointStore | None:
    """The store a setting names: "" a DirectoryStore in data_dir, "redis://..." a RedisStore,
    "off" none. With `check`, raises CheckpointError when Redis does not answer (a node refuses
    to start); a worker's store connects on first use, so a worker started while Redis is down
    still answers frames (checkpointing.py's failed-write path)."""
    if url == "off":
        return None
    if url.startswith("redis://"):
        return RedisStore(url, keep_s, check=check)
    return DirectoryStore(Path(data_dir) / "checkpoints", keep_s)


# -- the state: pickled, with creation objects by name ----------------------------------------------


class _Pickler(pickle.Pickler):
    """Writes each creation object as a call of `_creation_object` with its name. Through
    `reducer_override`, which the pickler asks only about objects of classes of their own, not
    seen before in this pickle; a `persistent_id` (how snapshots were written before 2026-12-02)
    is a Python call for every object pickled, strings and numbers too (17,600 in a MATCH session
    of 4 players at 30 Hz): a third of a snapshot's time."""

    def __init__(self, file, names: dict[int, CreationName]):
        super().__init__(file, protocol=5)
        self._names = names

    def reducer_override(self, obj):
        name = self._names.get(id(obj))
        return NotImplemented if name is None else (_creation_object, (name,))


class _Unpickler(pickle.Unpickler):
    """Reads `_creation_object(name)` as the rebuilt session's object of that name; also a
    snapshot written before 2026-12-02, whose creation objects are persistent ids (names): a
    node of the new version restores checkpoints the old one wrote."""

    def __init__(self, file, objects: dict):
        super().__init__(file)
        self._objects = objects

    def find_class(self, module_name: str, global_name: str):
        if (module_name, global_name) == (__name__, _creation_object.__name__):
            return self._creation_object
        return super().find_class(module_name, global_name)

    def persistent_load(self, name):
        if isinstance(name, list):  # a tuple name comes back as a list from pickle's persistent ids
            name = tuple(name)
        return self._creation_object(name)

    def _creation_object(self, name: CreationName) -> object:
        try:
            return self._objects[name]
        except KeyError:
            raise pickle.UnpicklingError(f"the rebuilt session has no creation object {name!r}") from None


def _creation_object(name: CreationName) -> object:
    """What a snapshot calls for a creation object; only loads_state's unpickler answers it."""
    raise pickle.UnpicklingError(
        f"creation object {name!r}: a snapshot is read by loads_state, with the rebuilt session's objects"
    )


_PICKLED_AS_VALUES = (dict, list, tuple, set, frozenset, str, bytes, bytearray, int, float, bool, type(None))


def dumps_state(state, creation_objects: dict[CreationName, object]) -> bytes:
    """`state` pickled, each of `creation_objects` (name -> object) by its name. Each must be an
    object of a class of its own (a mesh, a level, a clock): a pickler writes a dict, a list, a
    string or a number without asking (_Pickler)."""
    values = [name for name, obj in creation_objects.items() if type(obj) in _PICKLED_AS_VALUES]
    if values:
        raise TypeError(f"creation objects {values} are builtin values: a snapshot would copy them")
    buffer = io.BytesIO()
    _Pickler(buffer, {id(obj): name for name, obj in creation_objects.items()}).dump(state)
    return buffer.getvalue()


def loads_state(data: bytes, creation_objects: dict):
    """The state of dumps_state, with the names taken from `creation_objects` (a session
    built from the same creation request)."""
    return _Unpickler(io.BytesIO(data), creation_objects).load()


# -- the embedded default: files --------------------------------------------------------------------


class DirectoryStore:
    """Under `root`, per session: `create` (the request), `snapshot` (sequence number, then the
    state), `log` (length-prefixed entries, appended with one write each: a killed process's
    whole writes are in the page cache, a torn last one is ignored) and `owner`.

    A snapshot is appended to the log as an entry of its own (op code _SNAPSHOT_CODE), one
    write like an input's, while the log is under LOG_ROTATE_BYTES; then, and for a claim, it
    is written to `snapshot` and the log replaced by an empty file (each written aside, renamed
    into place). The newest snapshot, in the log or the file, is the checkpoint's; a torn one
    leaves the one before and the inputs since. Appending rather than replacing files takes a
    snapshot from three files created and two renamed (on ext4 with `discard`, about 0.3 ms
    when idle, more under load) to one write: a FRAMING_ONLY worker spent about 10% less CPU a
    frame and its round trips' p99 fell by a third (docs/frame_path.md). A process whose open log
    file has been replaced (its link count is 0) no longer owns the session. A checkpoint whose
    owner process is gone and whose files are older than `keep_s` is removed when a store opens
    the folder. A camdirector from before this layout cannot restore from a log holding a snapshot
    (its reader knows only inputs); this one reads the older layout."""

    may_hang = False  # a local folder

    def __init__(self, root: Path, keep_s: float):
        self.root = Path(root)
        try:
            self.root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CheckpointError(f"cannot create the checkpoint folder {self.root}: {exc}") from None
        self._logs: dict[str, int] = {}  # session id -> the open log's descriptor
        self._sweep(keep_s)

    def _dir(self, session_id: str) -> Path:
        return self.root / session_id

    def _write_aside(self, path: Path, data: bytes) -> None:
        aside = path.with_name(f".{path.name}.{os.getpid()}")
        aside.write_bytes(data)
        os.replace(aside, path)

    def _new_log(self, session_id: str, owner: str | None) -> None:
        """An empty log in place of the old one; `owner` written too when it changes (begin, claim)."""
        folder = self._dir(session_id)
        if owner is not None:
            self._write_aside(folder / "owner", owner.encode())
        self._write_aside(folder / "log", b"")
        self.forget(session_id)
        self._logs[session_id] = os.open(folder / "log", os.O_WRONLY | os.O_APPEND)

    def _owns(self, session_id: str) -> bool:
        fd = self._logs.get(session_id)
        return fd is not None and os.fstat(fd).st_nlink > 0

    def begin(self, session_id: str, owner: str, create: bytes) -> None:
        try:
            folder = self._dir(session_id)
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            (folder / "create").write_bytes(create)
            self._new_log(session_id, owner)
        except OSError as exc:
            raise CheckpointError(f"cannot write the checkpoint of session {session_id}: {exc}") from None

    def append(self, session_id: str, owner: str, entry: bytes) -> bool:
        fd = self._logs.get(session_id)
        if fd is None:
            return False
        try:
            # _owns's test and a write of _LENGTH.pack(len(entry)) + entry, in one call (the frame's path)
            return bool(native.append_log(fd, entry))
        except OSError as exc:
            raise CheckpointError(f"cannot append to the checkpoint of session {session_id}: {exc}") from None

    def snapshot(self, session_id: str, owner: str, seq: int, state: bytes, claim: bool = False) -> bool:
        if not claim:
            fd = self._logs.get(session_id)
            if fd is None:
                return False
            try:
                if os.fstat(fd).st_size + len(state) < LOG_ROTATE_BYTES:
                    # the owner's test and the write in one call, as an input's (append)
                    return bool(native.append_log(fd, _ENTRY.pack(seq, _SNAPSHOT_CODE) + state))
            except OSError as exc:
                raise CheckpointError(f"cannot write the checkpoint of session {session_id}: {exc}") from None
            if not self._owns(session_id):
                return False
        try:
            folder = self._dir(session_id)
            self._write_aside(folder / "snapshot", _SEQ.pack(seq) + state)
            self._new_log(session_id, owner if claim else None)
        except OSError as exc:
            raise CheckpointError(f"cannot write the checkpoint of session {session_id}: {exc}") from None
        return True

    def load(self, session_id: str) -> Checkpoint | None:
        folder = self._dir(session_id)
        try:
            create = (folder / "create").read_bytes()
        except (FileNotFoundError, NotADirectoryError):
            return None
        except OSError as exc:
            raise CheckpointError(f"cannot read the checkpoint of session {session_id}: {exc}") from None
        try:
            data = (folder / "snapshot").read_bytes()
            seq, snapshot = _SEQ.unpack_from(data)[0], data[_SEQ.size :]
        except FileNotFoundError:
            seq, snapshot = 0, None
        try:
            logged = list(_read_log((folder / "log").read_bytes()))
        except FileNotFoundError:
            logged = []
        inputs = []
        for entry in logged:
            entry_seq, code = _ENTRY.unpack_from(entry)
            if code != _SNAPSHOT_CODE:
                inputs.append(entry)
            elif entry_seq >= seq:  # the newest snapshot so far
                seq, snapshot = entry_seq, entry[_ENTRY.size :]
        return Checkpoint(create, snapshot, seq, [e for e in map(decode_entry, inputs) if e[0] > seq])

    def delete(self, session_id: str, owner: str) -> None:
        if self._owns(session_id):
            self.forget(session_id)
            shutil.rmtree(self._dir(session_id), ignore_errors=True)

    def forget(self, session_id: str) -> None:
        fd = self._logs.pop(session_id, None)
        if fd is not None:
            os.close(fd)

    def ping(self) -> bool:
        return self.root.is_dir()

    def close(self) -> None:
        for session_id in list(self._logs):
            self.forget(session_id)

    def _sweep(self, keep_s: float) -> None:
        """Removes checkpoints no live process owns and none has written for keep_s."""
        now = time.time()
        for folder in self.root.iterdir():
            try:
                owner = (folder / "owner").read_text()
                newest = max(p.stat().st_mtime for p in folder.iterdir())
            except (OSError, ValueError):
                newest, owner = 0.0, ""
            if now - newest > keep_s and not _process_alive(owner):
                shutil.rmtree(folder, ignore_errors=True)


def _read_log(data: bytes) -> Iterator[bytes]:
    at = 0
    while at + _LENGTH.size <= len(data):
        (length,) = _LENGTH.unpack_from(data, at)
        if at + _LENGTH.size + length > len(data):
            return  # the last write was torn
        yield data[at + _LENGTH.size : at + _LENGTH.size + length]
        at += _LENGTH.size + length


def _process_alive(owner: str) -> bool:
    """Whether an owner "node/pid" names a live process of this machine (False if unreadable)."""
    try:
        os.kill(int(owner.rsplit("/", 1)[1]), 0)
    except (IndexError, ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    return True


# -- many nodes: Redis ------------------------------------------------------------------------------

# KEYS[1] the session's hash (create, owner, snapshot, seq), KEYS[2] its log (a list of entries).
_APPEND = """
if redis.call('HGET', KEYS[1], 'owner') ~= ARGV[1] then return 0 end
redis.call('RPUSH', KEYS[2], ARGV[2])
redis.call('PEXPIRE', KEYS[1], ARGV[3]); redis.call('PEXPIRE', KEYS[2], ARGV[3])
return 1
"""
_SNAPSHOT = """
if ARGV[5] ~= '1' and redis.call('HGET', KEYS[1], 'owner') ~= ARGV[1] then return 0 end
if redis.call('EXISTS', KEYS[1]) == 0 then return 0 end
redis.call('HSET', KEYS[1], 'owner', ARGV[1], 'snapshot', ARGV[2], 'seq', ARGV[3])
redis.call('DEL', KEYS[2])
redis.call('PEXPIRE', KEYS[1], ARGV[4])
return 1
"""
_BEGIN = """
redis.call('DEL', KEYS[1], KEYS[2])
redis.call('HSET', KEYS[1], 'owner', ARGV[1], 'create', ARGV[2])
redis.call('PEXPIRE', KEYS[1], ARGV[3])
return 1
"""
_DELETE = """
if redis.call('HGET', KEYS[1], 'owner') == ARGV[1] then redis.call('DEL', KEYS[1], KEYS[2]) end
return 1
"""


class RedisStore:
    """Checkpoints in Redis, under `camdirector:ck:{<session id>}:meta` and `...:log` (module
    docstring). Keys expire `keep_s` after their session's last write. Calls time out after
    `timeout_s`; they are made by the writer's thread (checkpoint_writer.py), so a Redis that
    hangs delays no frame by more than `checkpoint_wait_ms`.

    A `redis://` URL's host name is looked up off the calls' path (infra/host_address.py's
    `redis_pool`, which says why): its connections go to the address last found, a call made
    before any lookup answered waits for one up to `timeout_s` and then fails (the session's
    checkpoint is then behind, and repaired once the writer's probe reaches Redis), and a failed
    connection looks the name up again. With `check` (a node starting) the first lookup is waited
    for. `rediss://` (TLS checks the name) and `unix://` connect as redis-py does."""

    may_hang = True

    def __init__(
        self, url: str, keep_s: float, timeout_s: float = 0.5, check: bool = True, lookup: Lookup = lookup_stream_addresses
    ):
        """lookup: how the host name is looked up (tests stall it); socket.getaddrinfo's by default."""
        import redis  # only a node given a redis:// URL needs the client

        self._errors = (redis.RedisError, OSError)
        self.url = url
        self._timeout_s = timeout_s
        # Keepalives notice a vanished host; the timeouts bound a Redis that hangs (paused). Off the
        # frame path either way (checkpoint_writer.py).
        pool, self.address = redis_pool(
            url,
            lookup,
            socket_timeout=timeout_s,
            socket_connect_timeout=timeout_s,
            socket_keepalive=True,
            health_check_interval=0,
        )
        self._client = redis.Redis(connection_pool=pool)
        self._keep_ms = str(int(keep_s * 1000))
        if check:
            try:
                if self.address is not None:
                    self.address.look_up_now()
                self._client.ping()
            except self._errors as exc:
                raise CheckpointError(f"the checkpoint store {redacted(url)} does not answer: {exc}") from None
        self._append = self._client.register_script(_APPEND)
        self._snapshot = self._client.register_script(_SNAPSHOT)
        self._begin = self._client.register_script(_BEGIN)
        self._delete = self._client.register_script(_DELETE)

    def _address_known(self, what: str) -> None:
        """Raises CheckpointError when no lookup of the host name has answered, after waiting for
        one up to the calls' timeout."""
        if self.address is None:
            return
        try:
            self.address.known(self._timeout_s)
        except OSError as exc:
            raise CheckpointError(f"{what} in {redacted(self.url)} failed: {exc}") from None

    @staticmethod
    def _keys(session_id: str) -> list[str]:
        return [f"camdirector:ck:{{{session_id}}}:meta", f"camdirector:ck:{{{session_id}}}:log"]

    def _call(self, what: str, session_id: str, script, args: list):
        self._address_known(f"{what} of session {session_id}'s checkpoint")
        try:
            return script(keys=self._keys(session_id), args=args)
        except self._errors as exc:
            raise CheckpointError(f"{what} of session {session_id}'s checkpoint in {redacted(self.url)} failed: {exc}") from None

    def begin(self, session_id: str, owner: str, create: bytes) -> None:
        self._call("the start", session_id, self._begin, [owner, create, self._keep_ms])

    def append(self, session_id: str, owner: str, entry: bytes) -> bool:
        return self._call("an append", session_id, self._append, [owner, entry, self._keep_ms]) == 1

    def snapshot(self, session_id: str, owner: str, seq: int, state: bytes, claim: bool = False) -> bool:
        args = [owner, state, str(seq), self._keep_ms, "1" if claim else "0"]
        return self._call("a snapshot", session_id, self._snapshot, args) == 1

    def load(self, session_id: str) -> Checkpoint | None:
        meta_key, log_key = self._keys(session_id)
        self._address_known(f"reading session {session_id}'s checkpoint")
        try:
            with self._client.pipeline(transaction=True) as pipe:
                pipe.hgetall(meta_key)
                pipe.lrange(log_key, 0, -1)
                meta, log_entries = pipe.execute()
        except self._errors as exc:
            raise CheckpointError(f"reading session {session_id}'s checkpoint in {redacted(self.url)} failed: {exc}") from None
        if b"create" not in meta:
            return None
        seq = int(meta.get(b"seq", 0))
        entries = [e for e in map(decode_entry, log_entries) if e[0] > seq]
        return Checkpoint(meta[b"create"], meta.get(b"snapshot"), seq, entries)

    def delete(self, session_id: str, owner: str) -> None:
        self._call("the removal", session_id, self._delete, [owner])

    def forget(self, session_id: str) -> None:
        pass  # nothing held per session

    def ping(self) -> bool:
        try:
            self._address_known("a ping")
            return bool(self._client.ping())
        except (CheckpointError, *self._errors):
            return False

    def close(self) -> None:
        self._client.close()
