"""The jobs' settings (jobs/job_settings.py), and a server's made from its ServerSettings
(server_settings.py knows no jobs: the dependency points from jobs/ down to it)."""
from __future__ import annotations

import pytest

from camdirector.jobs.job_settings import JobSettings
from camdirector.server_settings import ServerSettings


def test_a_servers_job_settings_carry_its_limits_and_with_keys_each_tenants_share():
    server = ServerSettings(max_concurrent_jobs=3, max_queued_jobs=7, max_upload_bytes=2048, job_retention_s=60.0,
                            job_store="postgresql://db/x", job_queue="redis://q/0", tenant_max_queued_jobs=5,
                            tenant_max_upload_bytes=4096)
    jobs = JobSettings.for_server(server)
    assert (jobs.max_concurrent_jobs, jobs.max_queued_jobs, jobs.max_upload_bytes, jobs.job_retention_s) == (3, 7, 2048, 60.0)
    assert (jobs.job_store, jobs.job_queue) == ("postgresql://db/x", "redis://q/0")
    assert jobs.submit_limits() == {"max_queued": 7, "tenant_max_queued_jobs": 5, "tenant_max_upload_bytes": 4096}
    open_server = ServerSettings(auth=False, tenant_max_queued_jobs=5)
    assert JobSettings.for_server(open_server).submit_limits()["tenant_max_queued_jobs"] is None  # one tenant


def test_the_jobs_limits_are_checked_where_the_jobs_settings_are_made():
    server = ServerSettings(max_concurrent_jobs=65)  # the server's own checks do not know this limit
    with pytest.raises(ValueError, match=r"max_concurrent_jobs must be in \[1, 64\]"):
        JobSettings.for_server(server)
