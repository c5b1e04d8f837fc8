"""Job kinds: what a job may be, and the one list of the kinds the service offers.

A kind is a name and a body: `function(params: dict, input_dir: Path, output_dir: Path,
progress: Callable[[float], None]) -> dict[str, float]` (timings in milliseconds), run in a job
process (main.py); it raises to fail the job (`infra.job_errors.JobError`'s message is shown as
is; other exceptions as "<Type>: message"). It must be a module-level function: it is pickled by
reference into the job process, and its module is what the forkserver preloads.

`service_kinds()` is the one registry of the kinds the REST API takes: the front's runner or queue
client, the routes (which read their kind's name from the body's module) and every queue worker
(`camdirector job-worker`) are given it. A new kind is one line there, its body beside the
computation it runs (precompute/<area>/job.py), and its routes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

JobFunction = Callable[[dict, Path, Path, Callable[[float], None]], dict]


@dataclass(frozen=True)
class JobKind:
    name: str
    function: JobFunction


class JobRegistry:
    """kind name -> job function."""

    def __init__(self, kinds: tuple[JobKind, ...] = ()) -> None:
        self._kinds: dict[str, JobKind] = {}
        for k in kinds:
            self.register(k)

    def register(self, kind: JobKind) -> None:
        if kind.name in self._kinds:
            raise ValueError(f"job kind {kind.name!r} is already registered")
        self._kinds[kind.name] = kind

    def get(self, name: str) -> JobKind:
        try:
            return self._kinds[name]
        except KeyError:
            raise KeyError(f"unknown job kind {name!r}") from None

    def __contains__(self, name: str) -> bool:
        return name in self._kinds

    @property
    def modules(self) -> tuple[str, ...]:
        """The kinds' modules, in registration order without repeats (what the forkserver preloads)."""
        return tuple(dict.fromkeys(k.function.__module__ for k in self._kinds.values()))


def service_kinds() -> JobRegistry:
    """Every job kind of the REST API: motion overviews and level precompute (module docstring).
    Imported lazily so that reading a job record needs no numpy, scipy or trimesh."""
    from camdirector.precompute.overview import job as overview_job
    from camdirector.precompute.tracks import job as level_job

    return JobRegistry(
        (JobKind(overview_job.KIND, overview_job.run_overview_job), JobKind(level_job.KIND, level_job.run_level_job))
    )
