"""The offline jobs' settings: one typed object, each default with its unit and limit, validated once."""
from __future__ import annotations

from dataclasses import dataclass

from camdirector.server_settings import ServerSettings


@dataclass(frozen=True)
class JobSettings:
    """Limits of the offline jobs (one per process; a server's come from its ServerSettings: for_server)."""

    max_concurrent_jobs: int = 1           # job processes running at once, per runner or queue worker. [1, 64]
    max_queued_jobs: int = 16              # jobs waiting to run; a submit beyond this is refused (HTTP 429). [0, 100000]
    max_upload_bytes: int = 64 * 1024 * 1024  # largest uploaded file of a job, bytes (HTTP 413 above). [1 KiB, 4 GiB]
    max_attempts: int = 2                  # times a job may be started; one found interrupted after that fails. [1, 100]
    job_timeout_s: float = 600.0           # a running job is ended and failed after this, s. [1, 86400]
    cancel_grace_s: float = 2.0            # SIGTERM to SIGKILL of a cancelled job's process, s. [0, 60]
    job_blas_threads: int = 1              # BLAS/OpenMP threads per job process (0: library default). [0, 64]
    job_retention_s: float = 7 * 86400.0   # a finished job's record and files go this long after it ends (0: kept), s. [0, 1e9]
    # Where records live: "" is SQLite in the data directory; postgresql://... is shared by many nodes.
    job_store: str = ""
    # Where jobs wait: "" is this process's own runner; redis://... is the queue of `camdirector job-worker`s.
    job_queue: str = ""
    # A queue worker silent this long is taken for dead and its jobs are run again elsewhere; it beats
    # every quarter of this. Every worker must use the same value, s. [1, 3600]
    worker_heartbeat_timeout_s: float = 30.0
    # Each tenant's share (records.py; HTTP 429 beyond it). None: no share, as without keys, where
    # everyone is one tenant (for_server sets them with authentication on).
    tenant_max_queued_jobs: int | None = None    # jobs a tenant has queued or running. [1, 100000]
    tenant_max_upload_bytes: int | None = None   # bytes of inputs a tenant's jobs keep. [1 KiB, 1 TiB]

    def __post_init__(self):
        checks = [
            (1 <= self.max_concurrent_jobs <= 64, "max_concurrent_jobs must be in [1, 64]"),
            (0 <= self.max_queued_jobs <= 100_000, "max_queued_jobs must be in [0, 100000]"),
            (1024 <= self.max_upload_bytes <= 4 << 30, "max_upload_bytes must be in [1 KiB, 4 GiB]"),
            (1 <= self.max_attempts <= 100, "max_attempts must be in [1, 100]"),
            (0.0 <= self.job_retention_s <= 1e9, "job_retention_s must be in [0, 1e9]"),
            (1.0 <= self.job_timeout_s <= 86_400.0, "job_timeout_s must be in [1, 86400]"),
            (0.0 <= self.cancel_grace_s <= 60.0, "cancel_grace_s must be in [0, 60]"),
            (0 <= self.job_blas_threads <= 64, "job_blas_threads must be in [0, 64]"),
            (not self.job_store or self.job_store.startswith(("postgresql://", "postgres://")),
             "job_store must be empty (SQLite in the data directory) or a postgresql:// URL"),
            (not self.job_queue or self.job_queue.startswith("redis://"),
             "job_queue must be empty (this process's runner) or a redis:// URL"),
            (1.0 <= self.worker_heartbeat_timeout_s <= 3600.0, "worker_heartbeat_timeout_s must be in [1, 3600]"),
            (self.tenant_max_queued_jobs is None or 1 <= self.tenant_max_queued_jobs <= 100_000,
             "tenant_max_queued_jobs must be in [1, 100000]"),
            (self.tenant_max_upload_bytes is None or 1024 <= self.tenant_max_upload_bytes <= 1 << 40,
             "tenant_max_upload_bytes must be in [1 KiB, 1 TiB]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)

    @classmethod
    def for_server(cls, settings: ServerSettings) -> JobSettings:
        """The jobs' settings of a server's (validated here, not in ServerSettings, which knows no jobs)."""
        shares = dict(tenant_max_queued_jobs=settings.tenant_max_queued_jobs,
                      tenant_max_upload_bytes=settings.tenant_max_upload_bytes) if settings.auth else {}
        return cls(max_concurrent_jobs=settings.max_concurrent_jobs, max_queued_jobs=settings.max_queued_jobs,
                   max_upload_bytes=settings.max_upload_bytes, job_retention_s=settings.job_retention_s,
                   job_store=settings.job_store, job_queue=settings.job_queue, **shares)

    def submit_limits(self) -> dict:
        """JobStore.submit's limits (keyword arguments): the queue's, and each tenant's share."""
        return {"max_queued": self.max_queued_jobs, "tenant_max_queued_jobs": self.tenant_max_queued_jobs,
                "tenant_max_upload_bytes": self.tenant_max_upload_bytes}
