"""The "level" job kind's body (runs in a job process): precompute an uploaded level into the
level registry (registry.py), which writes it only when the precompute has succeeded."""

from __future__ import annotations

from pathlib import Path

from camdirector.infra.job_errors import JobError
from camdirector.infra.tenants import DEFAULT_TENANT
from camdirector.precompute.tracks.registry import LevelExists, LevelRegistry

KIND = "level"


def run_level_job(params: dict, input_dir: Path, output_dir: Path, progress) -> dict[str, float]:
    """The "level" job kind (runs in a job process): precompute into the registry at
    params["data_dir"], its index where params["records_url"] says ("" or absent: SQLite there;
    the nodes' shared PostgreSQL), in the namespace of params["tenant"] (absent in a job queued
    before tenants: `default`); returns the pipeline's stage timings (ms). A name taken meanwhile
    without params["replace"] fails the job, also when another node's job took it while this one
    ran (the index's primary key refuses the second)."""
    taken = f"level {params['name']!r} was added while this job waited; submit with replace=true to replace it"
    tenant = params.get("tenant", DEFAULT_TENANT)
    with LevelRegistry(params["data_dir"], params.get("records_url", "")) as registry:
        if not params["replace"] and registry.get(params["name"], tenant) is not None:
            raise JobError(taken)
        navmesh = input_dir / params["navmesh_file"] if params.get("navmesh_file") else None
        try:
            record = registry.add_level(
                params["name"],
                input_dir / params["level_file"],
                navmesh,
                scale=params["scale"],
                agent_height_m=params["agent_height_m"],
                agent_radius_m=params["agent_radius_m"],
                progress=progress,
                seed=params["seed"],
                replace=params["replace"],
                tenant=tenant,
            )
        except LevelExists:
            raise JobError(taken) from None
        except ValueError as exc:  # MeshError included: no walkable surface, no tracks, ...
            raise JobError(f"cannot precompute level {params['name']!r}: {exc}") from None
    progress(1.0)
    return dict(record.timings_ms)
