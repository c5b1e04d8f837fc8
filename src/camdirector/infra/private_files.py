"""The data folder is the node's user's alone (docs/security.md, "The data folder"): it holds the
keys' hashes and the dashboard's cookie secret (access.sqlite3 and its -wal), tenants' uploads,
results, checkpoints (their scenes), recordings and levels.

A server process (`camdirector serve`, `camdirector job-worker`) calls `make_private` first thing:
its umask becomes 077, so every folder it creates is 0700 and every file 0600, and so are those of
every process it starts (workers, render processes, the job forkserver and its jobs: the umask is
inherited across fork and exec). SQLite gives the -wal and -shm files the main file's mode,
whatever the umask, so a database file is made 0600 before SQLite opens it (infra/sqlite.py). A
data folder left open by an older version or an operator's copy is tightened once, at start.
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

log = logging.getLogger("camdirector.private_files")

PRIVATE_UMASK = 0o077  # group and other get nothing
OPEN_BITS = 0o077  # the mode bits a private path must not have


class NotPrivate(OSError):
    """A path in the data folder that is open to others and cannot be made private (another
    user's file): the server refuses to start rather than serve secrets others may read."""


def tighten(root: Path) -> int:
    """Takes group and other bits off `root` and everything under it (symbolic links are neither
    followed nor changed); returns how many paths it changed. NotPrivate when one cannot be."""
    changed = 0
    for folder, _, files in os.walk(root):
        for path in (folder, *(os.path.join(folder, name) for name in files)):
            try:
                mode = os.lstat(path).st_mode
                if stat.S_ISLNK(mode) or not stat.S_IMODE(mode) & OPEN_BITS:
                    continue
                os.chmod(path, stat.S_IMODE(mode) & ~OPEN_BITS)
            except FileNotFoundError:  # removed meanwhile (a job's retention, a finished upload)
                continue
            except PermissionError as exc:
                raise NotPrivate(f"{path} is open to others and cannot be made private: {exc.strerror}") from exc
            changed += 1
    return changed


def make_private(data_dir: str | Path) -> None:
    """Sets this process's umask to 077, creates `data_dir` (0700) when missing and tightens it and
    what is in it (tighten), saying so in one log line when anything was open. NotPrivate for a
    folder shared by design (the sticky bit: /tmp)."""
    os.umask(PRIVATE_UMASK)
    root = Path(data_dir)
    root.mkdir(parents=True, exist_ok=True)
    if root.stat().st_mode & stat.S_ISVTX:  # everyone's by design: tightening it would lock others out of theirs
        raise NotPrivate(f"data folder {root} is shared (sticky, as /tmp): give the server a folder of its own")
    changed = tighten(root)
    if changed:
        log.warning("data folder %s: %d paths were open to group or others; now the owner's only", root, changed)
