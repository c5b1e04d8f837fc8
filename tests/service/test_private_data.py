"""The data folder is the node's user's alone (docs/security.md, "The data folder"): after a real
server ran a session of every rig, a level added over REST, an overview job, a recording and a
checkpoint, nothing in it is open to group or others (SQLite's -wal and -shm, the admin key, the
CURVE secret included); a folder left open beforehand is tightened at start, with one log line."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import httpx

from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from tests.precompute.tracks.tiny_levels import corridor
from tests.served_checks import Served, add_level_over_rest, assert_overview_done, post_overview_job, session_of_rig
from tests.service.wire_client import two_target_request, walk

OPEN_BITS = stat.S_IRWXG | stat.S_IRWXO

# What the walk must have seen, so that a clean walk says something: every kind of file a server
# writes in its data folder (globs, relative to it).
WRITTEN = (
    "access.sqlite3-wal",  # keys' hashes and the cookie secret, in clear until checkpointed
    "access.sqlite3-shm",
    "admin.key",
    "zmq/server.key_secret",
    "checkpoints/*/log",  # a session's inputs and, past 60 of them, its snapshot (checkpoint_stores.py)
    "jobs/jobs.sqlite3-wal",
    "jobs/*/input/clip.bvh",  # an upload
    "jobs/*/result/preview.mp4",  # a result
    "levels/index.sqlite3",
    "levels/corridor.*.npz",
    "recordings/*.cdrec",
)


def open_paths(root: Path) -> list[str]:
    """Every path under root (root included) with a group or other bit, with its mode (a symbolic
    link's own mode is always 0777 and means nothing)."""
    found = []
    for folder, _, files in os.walk(root):
        for path in (folder, *(os.path.join(folder, name) for name in files)):
            mode = os.lstat(path).st_mode
            if not stat.S_ISLNK(mode) and stat.S_IMODE(mode) & OPEN_BITS:
                found.append(f"{os.path.relpath(path, root)} {stat.S_IMODE(mode):o}")
    return found


def test_nothing_a_server_writes_is_open_to_others(tmp_path, run_bvh):
    data_dir = tmp_path / "data"  # the server makes it
    with ServerProcess("--workers", "1", "--data-dir", str(data_dir), auth=True) as server:
        client = httpx.Client(base_url=f"http://{server.http}", headers={"Authorization": f"Bearer {server.admin_key}"})
        served = Served(server.grpc, server.zmq, client, server.log_tail, key=server.admin_key)
        job_id = post_overview_job(served, run_bvh)
        add_level_over_rest(served, "corridor", corridor())
        for rig in ("toric", "match", "tracks"):
            session_of_rig(served, rig, "grpc")
        raw = served.grpc_raw()  # a session left open: its checkpoint and its recording stay
        session_id = raw.call("CreateSession", two_target_request(seed=2, record=True)).session_id
        raw.stream(list(walk(session_id, 70)))  # past the 60 inputs after which a snapshot is taken
        assert_overview_done(served, job_id)
        try:  # while the server runs: SQLite removes the -wal and -shm files when it closes
            assert [pattern for pattern in WRITTEN if not any(data_dir.glob(pattern))] == []
            assert open_paths(data_dir) == []
        finally:
            raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
            raw.close()
            client.close()


def test_a_data_folder_left_open_is_tightened_at_start_with_one_log_line(tmp_path):
    data_dir = tmp_path / "data"
    (data_dir / "recordings").mkdir(parents=True)
    old = data_dir / "recordings" / "old.cdrec"
    old.write_bytes(b"a recording from before")
    outside = tmp_path / "outside.txt"  # reached through a link: neither followed nor changed
    outside.write_text("not the server's")
    (data_dir / "link").symlink_to(outside)
    for path, mode in ((data_dir, 0o755), (data_dir / "recordings", 0o777), (old, 0o644), (outside, 0o644)):
        path.chmod(mode)
    with ServerProcess("--workers", "0", "--data-dir", str(data_dir), transports=("http",)) as server:
        assert open_paths(data_dir) == []
        assert stat.S_IMODE(old.stat().st_mode) == 0o600 and stat.S_IMODE(outside.stat().st_mode) == 0o644
        lines = [line for line in server.log_tail().splitlines() if "open to group or others" in line]
        assert len(lines) == 1 and f"data folder {data_dir}: 3 paths" in lines[0], server.log_tail()
    with ServerProcess("--workers", "0", "--data-dir", str(data_dir), transports=("http",)) as again:
        assert "open to group or others" not in again.log_tail()  # nothing left to say
