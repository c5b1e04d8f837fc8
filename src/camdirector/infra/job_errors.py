"""What a job body may rely on, so the computations it runs need nothing of the server: the
exception that fails a job with a message of its own. The executor (jobs/executor.py) runs a body in
a job process as `body(params, input_dir, output_dir, progress) -> timings_ms`."""


class JobError(Exception):
    """Raised by a job function to fail its job with exactly this message."""
