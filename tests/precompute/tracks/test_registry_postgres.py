"""The level registry with its index in PostgreSQL, what only that case has: the database down,
and the level job's body (precompute/tracks/job.py) writing where its params' records_url says,
failing when another node's job took the name first. test_registry.py runs the rest on both
indexes."""

from __future__ import annotations

import socket

import pytest

from camdirector.infra.job_errors import JobError
from camdirector.precompute.tracks.job import run_level_job
from camdirector.precompute.tracks.registry import LevelRegistry, LevelsUnavailable

from .test_registry import obj_file
from .tiny_levels import corridor


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_postgres_down_is_one_clear_error(tmp_path):
    url = f"postgresql://camdirector:secret@127.0.0.1:{free_port()}/camdirector"
    with pytest.raises(
        LevelsUnavailable,
        match=r"level index postgresql://camdirector:\*\*\*@127.0.0.1:\d+/camdirector "
        "is unreachable",
    ) as caught:
        LevelRegistry(tmp_path, url)
    assert "secret" not in str(caught.value) and "\n" not in str(caught.value)


def test_a_bad_url_is_refused(tmp_path):
    with pytest.raises(ValueError, match="expected empty"):
        LevelRegistry(tmp_path, "mysql://x")


def test_a_dropped_connection_is_opened_again(tmp_path, postgres_url):
    import psycopg

    registry = LevelRegistry(tmp_path, postgres_url)
    assert registry.list() == []
    with psycopg.connect(postgres_url, autocommit=True) as admin:
        admin.execute(
            "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
            "WHERE datname = current_database() AND pid <> pg_backend_pid()"
        )
    with pytest.raises(LevelsUnavailable):
        registry.list()  # the call that finds it dropped fails ...
    assert registry.list() == []  # ... the next one connects again
    registry.close()


def job_params(tmp_path, url: str, **changes) -> dict:
    return {
        "name": "corridor",
        "level_file": "level.obj",
        "navmesh_file": None,
        "scale": 1.0,
        "agent_height_m": 2.0,
        "agent_radius_m": 0.6,
        "replace": False,
        "seed": 0,
        "data_dir": str(tmp_path / "shared"),
        "records_url": url,
        **changes,
    }


def test_the_level_job_writes_into_the_index_its_params_name(tmp_path, postgres_url):
    inputs = tmp_path / "input"
    inputs.mkdir()
    obj_file(inputs / "level.obj", corridor())
    seen = []
    timings = run_level_job(job_params(tmp_path, postgres_url), inputs, tmp_path / "out", seen.append)
    assert timings and seen[-1] == 1.0
    with LevelRegistry(tmp_path / "shared", postgres_url) as registry:  # what another node sees
        assert [r.name for r in registry.list()] == ["corridor"]
    assert not (tmp_path / "shared" / "levels" / "index.sqlite3").exists()
    assert LevelRegistry(tmp_path / "shared").list() == []  # not in SQLite
    with pytest.raises(JobError, match="'corridor' was added while this job waited"):
        run_level_job(job_params(tmp_path, postgres_url), inputs, tmp_path / "out", seen.append)
    run_level_job(job_params(tmp_path, postgres_url, replace=True), inputs, tmp_path / "out", seen.append)
    assert len(list((tmp_path / "shared" / "levels").glob("*.npz"))) == 1


def test_the_job_fails_when_another_node_took_the_name_while_it_ran(tmp_path, postgres_url, monkeypatch):
    """The job's early check passes; another node's job writes the name during this one's
    precompute; the index refuses this one's row, and the job fails with the same message."""
    inputs = tmp_path / "input"
    inputs.mkdir()
    obj_file(inputs / "level.obj", corridor())
    other = LevelRegistry(tmp_path / "shared", postgres_url)
    from camdirector.precompute.tracks import registry as registry_module

    real = registry_module.precompute_level

    def precompute_while_another_node_adds(*args, **kwargs):
        monkeypatch.setattr(registry_module, "precompute_level", real)
        other.add_level("corridor", inputs / "level.obj", replace=False)
        return real(*args, **kwargs)

    monkeypatch.setattr(registry_module, "precompute_level", precompute_while_another_node_adds)
    with pytest.raises(JobError, match="'corridor' was added while this job waited"):
        run_level_job(job_params(tmp_path, postgres_url), inputs, tmp_path / "out", lambda f: None)
    assert [p.name for p in (tmp_path / "shared" / "levels").glob("*.npz")] == [other.get("corridor").artifact_path.name]
    other.close()


def test_a_workers_level_cache_reads_the_shared_index(tmp_path, postgres_url):
    """worker/level_cache.py with the node's records URL: a level another node added is found;
    PostgreSQL gone answers UNAVAILABLE (retryable), not an internal error."""
    import grpc
    import psycopg

    from camdirector.errors import DirectorError
    from camdirector.worker.level_cache import LevelCache

    level_file = obj_file(tmp_path / "corridor.obj", corridor())
    with LevelRegistry(tmp_path / "shared", postgres_url) as other_node:
        other_node.add_level("corridor", level_file)
    cache = LevelCache(tmp_path / "shared", postgres_url)
    assert cache.get("corridor").artifact.agent_height_m == 2.0
    with pytest.raises(DirectorError) as err:
        LevelCache(tmp_path / "shared").get("corridor")  # SQLite in the folder holds none
    assert err.value.code == grpc.StatusCode.NOT_FOUND
    with psycopg.connect(postgres_url, autocommit=True) as admin:
        admin.execute(
            "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
            "WHERE datname = current_database() AND pid <> pg_backend_pid()"
        )
    with pytest.raises(DirectorError) as err:
        cache.get("corridor")
    assert err.value.code == grpc.StatusCode.UNAVAILABLE and "unreachable" in err.value.message
    with pytest.raises(DirectorError) as err:
        LevelCache(tmp_path, f"postgresql://camdirector@127.0.0.1:{free_port()}/x").get("corridor")
    assert err.value.code == grpc.StatusCode.UNAVAILABLE
