"""A job process's main loop: run one job's body and report to the executor over a pipe.

Started from a multiprocessing "forkserver" by executor.py (never forked from the front process
that runs gRPC and asyncio, nor from a queue worker's threads); it dies with its parent.
"""

from __future__ import annotations

import logging
import multiprocessing.connection
import time
import traceback
from pathlib import Path

from camdirector.infra.job_errors import JobError
from camdirector.infra.process_lifetime import die_with_parent
from camdirector.jobs.kinds import JobFunction

log = logging.getLogger("camdirector.jobs")


def job_main(
    function: JobFunction, params: dict, input_dir: str, output_dir: str, conn: multiprocessing.connection.Connection
) -> None:
    """Entry point of a job process: messages ("started", unix_s), ("progress", f), then
    ("ok", timings) or ("error", message): a JobError's own, or for any other exception its type."""
    conn.send(("started", time.time()))
    die_with_parent()  # a job does not outlive a killed server or queue worker
    last = [0.0, -1.0]

    def progress(fraction: float) -> None:
        now = time.monotonic()
        if now - last[0] >= 0.05 or fraction >= 1.0:  # at most 20 messages a second
            last[0] = now
            conn.send(("progress", float(fraction)))

    start = time.perf_counter()
    try:
        timings = {k: float(v) for k, v in (function(params, Path(input_dir), Path(output_dir), progress) or {}).items()}
        timings["job_function_total"] = (time.perf_counter() - start) * 1e3
        conn.send(("ok", timings))
    except JobError as exc:
        conn.send(("error", str(exc)))
    except BaseException as exc:  # report everything: the parent only sees the exit code otherwise
        log.error("job failed:\n%s", traceback.format_exc())
        # the job's error is its client's to read: an unexpected exception's words may name a path,
        # a database or a host, so they go to the log only (as errors.internal does for requests)
        conn.send(("error", f"internal error ({type(exc).__name__}) in the job; the server's log has the details"))
    finally:
        conn.close()
