"""The one list of job kinds (jobs/kinds.py): what the routes accept is what the runner and the
queue workers run, each body's module preloaded by the forkserver."""

from __future__ import annotations

import pytest

from camdirector.jobs import JobKind, JobRegistry, service_kinds
from camdirector.precompute.overview import job as overview_job
from camdirector.precompute.tracks import job as level_job


def test_the_service_kinds_are_the_routes_kinds_with_their_bodies():
    kinds = service_kinds()
    assert overview_job.KIND in kinds and level_job.KIND in kinds  # the names the routes submit
    assert kinds.get(overview_job.KIND).function is overview_job.run_overview_job
    assert kinds.get(level_job.KIND).function is level_job.run_level_job
    assert kinds.modules == (overview_job.__name__, level_job.__name__)


def test_a_kind_is_registered_once_and_an_unknown_one_is_named():
    kinds = JobRegistry((JobKind("overview", overview_job.run_overview_job),))
    with pytest.raises(ValueError, match="already registered"):
        kinds.register(JobKind("overview", level_job.run_level_job))
    with pytest.raises(KeyError, match="unknown job kind 'nope'"):
        kinds.get("nope")
