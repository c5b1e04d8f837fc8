"""Private files (infra/private_files.py, infra/sqlite.py): a node's SQLite database and the -wal
and -shm files SQLite makes beside it are 0600 whatever the umask; tightening a folder takes group
and other bits off everything in it, links left alone."""

from __future__ import annotations

import os
import stat

import pytest

from camdirector.infra.private_files import NotPrivate, make_private, tighten
from camdirector.infra.sqlite import SqliteDatabase


def _modes(folder) -> dict[str, int]:
    return {path.name: stat.S_IMODE(path.lstat().st_mode) for path in folder.iterdir() if not path.is_symlink()}


def test_a_database_and_its_wal_and_shm_are_0600_whatever_the_umask(tmp_path):
    umask = os.umask(0o022)  # a command run from an ordinary shell (`camdirector keys`)
    try:
        db = SqliteDatabase(tmp_path / "records.sqlite3", "CREATE TABLE secrets (value TEXT);")
        with db.transaction() as c:
            c.execute("INSERT INTO secrets VALUES ('in the WAL in clear until checkpointed')")
        modes = _modes(tmp_path)  # while open: SQLite removes the -wal and -shm when it closes
        db.close()
    finally:
        os.umask(umask)
    assert modes == {"records.sqlite3": 0o600, "records.sqlite3-wal": 0o600, "records.sqlite3-shm": 0o600}


def test_tighten_takes_group_and_other_bits_off_everything_below_and_counts_them(tmp_path):
    (tmp_path / "a" / "b").mkdir(parents=True)
    (tmp_path / "a" / "b" / "open").write_text("x")
    (tmp_path / "a" / "closed").write_text("x")
    outside = tmp_path.parent / f"{tmp_path.name}-outside"
    outside.write_text("not under the folder")
    (tmp_path / "a" / "link").symlink_to(outside)
    for path, mode in ((tmp_path / "a", 0o755), (tmp_path / "a" / "b", 0o770), (tmp_path / "a" / "b" / "open", 0o664)):
        path.chmod(mode)
    (tmp_path / "a" / "closed").chmod(0o600)
    outside.chmod(0o644)
    assert tighten(tmp_path / "a") == 3
    assert _modes(tmp_path / "a") == {"b": 0o700, "closed": 0o600}
    assert _modes(tmp_path / "a" / "b") == {"open": 0o600}
    assert stat.S_IMODE(outside.stat().st_mode) == 0o644  # the link was not followed
    assert tighten(tmp_path / "a") == 0


def test_a_shared_folder_is_refused_not_tightened(tmp_path):
    shared = tmp_path / "tmp"
    shared.mkdir()
    shared.chmod(0o1777)  # as /tmp: everyone's files, not the server's
    umask = os.umask(0o022)
    try:
        with pytest.raises(NotPrivate, match="shared"):
            make_private(shared)
    finally:
        os.umask(umask)
    assert stat.S_IMODE(shared.stat().st_mode) == 0o1777
