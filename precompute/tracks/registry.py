"""Level registry that survives restarts: an SQLite index plus one artifact file per level in
`<data_dir>/levels/`.

Safe for a server reading while the CLI writes: SQLite runs in WAL mode (readers never block on
the writer), artifacts are written to a temporary file and renamed into place
(artifact.save_artifact), each version gets a new file name so a reader holding the old row
still finds its file until it has loaded it (old files are removed after the index points at
the new one; a reader that raced the removal retries from the index). Names are 1-64 letters,
digits, '.', '_' or '-', starting with a letter or digit.
"""
from __future__ import annotations

import json
import os
import re
import secrets
import sqlite3
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from camdirector.precompute.tracks.artifact import FORMAT_VERSION, LevelArtifact, load_artifact, save_artifact
from camdirector.precompute.tracks.level import load_level_mesh
from camdirector.precompute.tracks.pipeline import precompute_level
from camdirector.precompute.tracks.settings import TrackSettings

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
_SCHEMA = """CREATE TABLE IF NOT EXISTS levels (
    name TEXT PRIMARY KEY, artifact_file TEXT NOT NULL, format_version INTEGER NOT NULL,
    source_path TEXT NOT NULL, navmesh_path TEXT, m_per_unit REAL NOT NULL, agent_height_m REAL NOT NULL,
    agent_radius_m REAL NOT NULL, created_unix_s REAL NOT NULL, counts_json TEXT NOT NULL, timings_json TEXT NOT NULL)"""


def check_level_name(name: str) -> None:
    """Raises ValueError unless name is 1-64 letters, digits, '.', '_' or '-', starting with a letter or digit."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(f"level name {name!r}: use 1-64 letters, digits, '.', '_' or '-', starting with a letter "
                         "or digit")


def default_data_dir() -> Path:
    """$XDG_DATA_HOME/camdirector, else ~/.local/share/camdirector (the server's default too)."""
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local", "share")
    return Path(base) / "camdirector"


@dataclass(frozen=True)
class LevelRecord:
    """One registry row; artifact_path is absolute."""

    name: str
    artifact_path: Path
    format_version: int
    source_path: str
    navmesh_path: str | None
    m_per_unit: float
    agent_height_m: float
    agent_radius_m: float
    created_unix_s: float
    counts: dict
    timings_ms: dict


class LevelRegistry:
    """The registry in data_dir (created if missing)."""

    def __init__(self, data_dir: Path | str | None = None):
        self.data_dir = Path(data_dir) if data_dir is not None else default_data_dir()
        self.levels_dir = self.data_dir / "levels"
        self.levels_dir.mkdir(parents=True, exist_ok=True)
        self._db_path = self.levels_dir / "index.sqlite3"
        with self._connect() as db:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute(_SCHEMA)

    def _connect(self) -> sqlite3.Connection:
        db = sqlite3.connect(self._db_path, timeout=30.0, isolation_level=None)
        db.execute("PRAGMA busy_timeout=30000")
        return db

    def _record(self, row) -> LevelRecord:
        return LevelRecord(name=row[0], artifact_path=self.levels_dir / row[1], format_version=row[2],
                           source_path=row[3], navmesh_path=row[4], m_per_unit=row[5], agent_height_m=row[6],
                           agent_radius_m=row[7], created_unix_s=row[8], counts=json.loads(row[9]),
                           timings_ms=json.loads(row[10]))

    def add_level(self, name: str, level_path: Path, navmesh_path: Path | None = None, *, scale: float = 1.0,
                  agent_height_m: float = 2.0, agent_radius_m: float = 0.6,
                  progress: Callable[[float], None] | None = None, seed: int = 0) -> LevelRecord:
        """Precompute a level file (OBJ/GLB, in units of `scale` metres) and index it under name,
        replacing a level of that name. Raises ValueError (MeshError) on a bad name or file."""
        check_level_name(name)
        settings = TrackSettings(agent_height_m=agent_height_m, agent_radius_m=agent_radius_m)
        mesh = load_level_mesh(Path(level_path), scale)
        navmesh = load_level_mesh(Path(navmesh_path), scale) if navmesh_path is not None else None
        artifact = precompute_level(mesh, settings, np.random.default_rng(seed), navmesh=navmesh, m_per_unit=scale,
                                    progress=progress)
        file_name = f"{name}.{secrets.token_hex(6)}.npz"
        save_artifact(artifact, self.levels_dir / file_name)
        with self._connect() as db:
            db.execute("BEGIN IMMEDIATE")
            old = db.execute("SELECT artifact_file FROM levels WHERE name = ?", (name,)).fetchone()
            db.execute("INSERT OR REPLACE INTO levels VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                       (name, file_name, FORMAT_VERSION, str(Path(level_path).resolve()),
                        str(Path(navmesh_path).resolve()) if navmesh_path is not None else None, scale,
                        agent_height_m, agent_radius_m, time.time(), json.dumps(artifact.counts),
                        json.dumps(artifact.timings_ms)))
            db.execute("COMMIT")
        if old is not None and old[0] != file_name:
            (self.levels_dir / old[0]).unlink(missing_ok=True)
        return self.get(name)

    def get(self, name: str) -> LevelRecord | None:
        with self._connect() as db:
            row = db.execute("SELECT * FROM levels WHERE name = ?", (name,)).fetchone()
        return self._record(row) if row else None

    def list(self) -> list[LevelRecord]:
        with self._connect() as db:
            rows = db.execute("SELECT * FROM levels ORDER BY name").fetchall()
        return [self._record(r) for r in rows]

    def load(self, name: str) -> LevelArtifact:
        """The level's artifact; KeyError when unknown, ArtifactVersionError when of another format."""
        for _ in range(3):
            record = self.get(name)
            if record is None:
                raise KeyError(f"no level named {name!r}")
            try:
                return load_artifact(record.artifact_path)
            except ValueError:
                if record.artifact_path.exists():
                    raise
        raise KeyError(f"level {name!r} keeps changing under the reader")

    def delete(self, name: str) -> bool:
        """Remove a level; False when there was none."""
        with self._connect() as db:
            db.execute("BEGIN IMMEDIATE")
            row = db.execute("SELECT artifact_file FROM levels WHERE name = ?", (name,)).fetchone()
            db.execute("DELETE FROM levels WHERE name = ?", (name,))
            db.execute("COMMIT")
        if row is None:
            return False
        (self.levels_dir / row[0]).unlink(missing_ok=True)
        return True
