"""`camdirector level add|list|remove` (precompute/tracks/cli.py) in child processes on one data directory."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.precompute.tracks.tiny_levels import l_room
from tests.service.tracks_sessions import ROOT, cli_add_level, obj_text


def _level(data_dir, *args) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "camdirector.__main__", "level", *args, "--data-dir", str(data_dir)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )


def test_add_list_remove(tmp_path):
    level_file = tmp_path / "room.obj"
    level_file.write_text(obj_text(l_room()))
    record = cli_add_level(tmp_path / "data", "room", level_file)
    assert record["name"] == "room" and record["counts"]["nodes"] > 0
    listed = _level(tmp_path / "data", "list")
    assert listed.returncode == 0 and [json.loads(line)["name"] for line in listed.stdout.splitlines()] == ["room"]
    assert _level(tmp_path / "data", "remove", "room").returncode == 0
    assert _level(tmp_path / "data", "list").stdout == ""
    assert not list((tmp_path / "data" / "levels").glob("room.*.npz"))
    again = _level(tmp_path / "data", "remove", "room")
    assert again.returncode == 2 and "no level named 'room'" in again.stderr


def test_a_tenants_levels(tmp_path):
    """--tenant: a level of its own namespace, beside the `default` one of the same name."""
    level_file = tmp_path / "room.obj"
    level_file.write_text(obj_text(l_room()))
    data = tmp_path / "data"
    added = _level(data, "add", "room", str(level_file), "--tenant", "acme")
    assert added.returncode == 0, added.stderr
    assert json.loads(added.stdout)["tenant"] == "acme"
    assert _level(data, "list").stdout == ""
    listed = _level(data, "list", "--tenant", "acme")
    assert [(r["name"], r["tenant"]) for r in map(json.loads, listed.stdout.splitlines())] == [("room", "acme")]
    assert _level(data, "remove", "room").returncode == 2  # not `default`'s
    assert _level(data, "remove", "room", "--tenant", "acme").returncode == 0
    bad = _level(data, "list", "--tenant", "ACME!")
    assert bad.returncode == 2 and "tenant 'ACME!'" in bad.stderr
