"""The precomputed level: one versioned file that loads fast.

A level artifact is one uncompressed NumPy .npz archive: the member `header` holds UTF-8 JSON
(`format_version` first, then the scale, the agent, the settings used, stage timings and counts),
every other member is one array named after the `LevelArtifact` field it fills. Loading reads
the header first and refuses any other format version with `ArtifactVersionError`, so an old
artifact is never half-read; all arrays are read into memory at once (the file can then be
replaced or deleted under a reader). `save_artifact` writes a temporary file in the same folder
and renames it over the target, so a reader sees the old file or the new one, never a partial one.
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from camdirector.precompute.tracks.track_settings import TrackSettings
from camdirector.precompute.tracks.visibility_table import VisibilityTable

FORMAT_VERSION = 3


class ArtifactVersionError(ValueError):
    """An artifact written by another format version."""


@dataclass(frozen=True)
class LevelArtifact:
    """Everything the runtime director and the evaluation need about a level, metres, world frame.

    level_vertices (n, 3) float64 / level_faces (m, 3) int32: the level (for ray casting);
    navmesh_vertices / navmesh_faces: the navigation mesh used; skeleton_segments (k, 2, 3);
    track_start / track_end (t, 3): the filtered camera tracks; nodes_world (N, 3), edges (E, 2)
    int64, edge_is_link (E,) bool: the camera navigation graph; refined_vertices /
    refined_faces: the remeshed navmesh the visibility table refers to; visibility: the dual
    table; m_per_unit: the level file's scale; settings: those of the precompute; timings_ms: per
    pipeline stage; counts: sizes of the intermediate results.
    """

    level_vertices: np.ndarray
    level_faces: np.ndarray
    navmesh_vertices: np.ndarray
    navmesh_faces: np.ndarray
    skeleton_segments: np.ndarray
    track_start: np.ndarray
    track_end: np.ndarray
    nodes_world: np.ndarray
    edges: np.ndarray
    edge_is_link: np.ndarray
    refined_vertices: np.ndarray
    refined_faces: np.ndarray
    visibility: VisibilityTable
    m_per_unit: float
    settings: TrackSettings
    timings_ms: dict[str, float]
    counts: dict[str, int]

    @property
    def agent_height_m(self) -> float:
        return self.settings.agent_height_m


_ARRAYS = (
    "level_vertices",
    "level_faces",
    "navmesh_vertices",
    "navmesh_faces",
    "skeleton_segments",
    "track_start",
    "track_end",
    "nodes_world",
    "edges",
    "edge_is_link",
    "refined_vertices",
    "refined_faces",
)
_TABLE = tuple(f.name for f in dataclasses.fields(VisibilityTable))


def _settings_dict(settings: TrackSettings) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(settings).items()}


def header_of(artifact: LevelArtifact) -> dict:
    """The JSON header of an artifact (also what the registry indexes)."""
    return {
        "format_version": FORMAT_VERSION,
        "m_per_unit": artifact.m_per_unit,
        "settings": _settings_dict(artifact.settings),
        "timings_ms": artifact.timings_ms,
        "counts": artifact.counts,
    }


def save_artifact(artifact: LevelArtifact, path: Path) -> None:
    """Write atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    arrays = {name: getattr(artifact, name) for name in _ARRAYS}
    arrays.update({f"visibility_{name}": getattr(artifact.visibility, name) for name in _TABLE})
    header = np.frombuffer(json.dumps(header_of(artifact)).encode("utf-8"), dtype=np.uint8)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, header=header, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def read_header(path: Path) -> dict:
    """The header of an artifact file; raises ArtifactVersionError for another format version and
    ValueError for a file that is not an artifact."""
    with np.load(path, allow_pickle=False) as data:
        return _checked_header(data, path)


def _checked_header(data, path: Path) -> dict:
    if "header" not in data.files:
        raise ValueError(f"{path}: not a level artifact (no header)")
    header = json.loads(data["header"].tobytes().decode("utf-8"))
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise ArtifactVersionError(
            f"{path}: level artifact format version {version}, this build reads version {FORMAT_VERSION}; "
            "add the level again (camdirector level add) to rebuild it"
        )
    return header


def load_artifact(path: Path) -> LevelArtifact:
    """Read an artifact fully into memory (module docstring)."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: cannot read level artifact: {exc}") from None
    with data:
        header = _checked_header(data, path)
        arrays = {name: data[name] for name in _ARRAYS}
        table = VisibilityTable(**{name: data[f"visibility_{name}"] for name in _TABLE})
    fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in header["settings"].items()}  # JSON
    settings = TrackSettings(**fields)
    return LevelArtifact(
        **arrays,
        visibility=table,
        m_per_unit=float(header["m_per_unit"]),
        settings=settings,
        timings_ms=dict(header["timings_ms"]),
        counts=dict(header["counts"]),
    )
