"""The level registry as one worker process sees it.

Levels are loaded only through `LevelRegistry.load` and cached per worker process by tenant, name
and artifact file (every version of a level has its own file), so a level re-added under the same
name is picked up by the next session while running sessions keep theirs. Loading nav_test (1,848
nodes) reads its 15 MB artifact in about 15 ms; building the director and the level's Embree scene
take about 10 ms more per session; the cache leaves only those per-session costs in the worker
that also answers other sessions' frames. A session finds only its own tenant's levels (the
registry's namespaces): another tenant's name answers NOT_FOUND as an unknown one.
"""

from __future__ import annotations

import logging
from pathlib import Path

from camdirector.errors import DirectorError, not_found, precondition, unavailable
from camdirector.geometry.meshes import TriMesh
from camdirector.infra.tenants import DEFAULT_TENANT
from camdirector.pipeline.inputs import LoadedLevel
from camdirector.precompute.tracks.artifact import ArtifactVersionError
from camdirector.precompute.tracks.registry import LevelRegistry, LevelsUnavailable

log = logging.getLogger("camdirector.worker.level_cache")


class LevelCache:
    """The level registry at data_dir as one worker process sees it (module docstring).
    records_url: where its index lives ("" SQLite in data_dir; the node's postgresql:// job store)."""

    def __init__(self, data_dir: str | Path, records_url: str = ""):
        self.data_dir = Path(data_dir)
        self.records_url = records_url
        self._registry: LevelRegistry | None = None  # opened by the first TRACKS session
        # (tenant, name) -> (artifact file, level)
        self._levels: dict[tuple[str, str], tuple[str, LoadedLevel]] = {}

    def get(self, name: str, tenant: str = DEFAULT_TENANT) -> LoadedLevel:
        """The current version of `tenant`'s level `name`. Raises DirectorError: NOT_FOUND for a
        name the registry does not hold for that tenant, FAILED_PRECONDITION for an artifact of
        another format version, UNAVAILABLE while the index's database (PostgreSQL) is down."""
        key = (tenant, name)
        try:
            if self._registry is None:
                self._registry = LevelRegistry(self.data_dir, self.records_url)
            record = self._registry.get(name, tenant)
        except LevelsUnavailable as exc:
            raise _index_down(exc) from None
        if record is None:
            self._levels.pop(key, None)  # removed: sessions on it keep their own reference
            raise not_found(
                f"level_id {name!r} is not in this server's level registry; "
                "add it with `camdirector level add` or POST /v1/levels"
            )
        cached = self._levels.get(key)
        if cached is not None and cached[0] == record.artifact_path.name:
            return cached[1]
        try:
            artifact = self._registry.load(name, tenant)
        except KeyError:
            raise not_found(f"level_id {name!r} was removed from the level registry") from None
        except LevelsUnavailable as exc:
            raise _index_down(exc) from None
        except ArtifactVersionError as exc:
            log.warning("level %r of tenant %s: %s", name, tenant, exc)  # the message names the file: not the client's
            raise precondition(
                f"level_id {name!r} was built by another version of the precompute; add it again "
                "(`camdirector level add` or POST /v1/levels)"
            ) from None
        level = LoadedLevel(name, artifact, TriMesh(artifact.level_vertices, artifact.level_faces))
        self._levels[key] = (record.artifact_path.name, level)
        return level


def _index_down(exc: LevelsUnavailable) -> DirectorError:
    """UNAVAILABLE in words that name no database or host (any tenant's engine key reads them);
    the reason, the URL's secrets hidden, goes to the server's log."""
    log.warning("%s", exc)
    return unavailable("the level index is unreachable; retry later")
