"""The local job runner (front/job_runner.py): real job processes, results renamed into place,
bounded concurrency, cancellation, a full queue, retention, and restart survival (a runner process
killed with SIGKILL while one job runs and one is queued, then a new runner on the same folder, with
its records in SQLite and in PostgreSQL)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from camdirector.front.job_runner import JobRunner
from camdirector.jobs import JobNotFound, JobSettings, JobState, QueueFull, open_store
from tests.jobs.toys import KINDS, alive, started_pids, wait_params, wait_until

ROOT = Path(__file__).resolve().parents[2]


def job_dirs(store) -> set[str]:
    return {p.name for p in store.root.iterdir() if p.is_dir()}


def test_settings_are_validated():
    with pytest.raises(ValueError, match="max_concurrent_jobs"):
        JobSettings(max_concurrent_jobs=0)
    with pytest.raises(ValueError, match="max_upload_bytes"):
        JobSettings(max_upload_bytes=10)
    with pytest.raises(ValueError, match="job_retention_s"):
        JobSettings(job_retention_s=-1.0)
    with pytest.raises(ValueError, match="job_queue"):
        JobSettings(job_queue="amqp://x")
    with pytest.raises(ValueError, match="worker_heartbeat_timeout_s"):
        JobSettings(worker_heartbeat_timeout_s=0.1)


# -- runner -----------------------------------------------------------------------------------


def test_runner_runs_jobs_in_processes_and_renames_results(tmp_path):
    with JobRunner(tmp_path, KINDS) as runner:
        job = runner.submit("echo", {}, {"in.txt": b"hi"})
        done = runner.wait(job.id, 30.0)
        assert done.state is JobState.SUCCEEDED, done.error
        assert done.progress == 1.0 and done.attempts == 1
        assert (runner.result_dir(job.id) / "echo.txt").read_bytes() == b"hihi"
        assert {"echo", "queued", "job_process_total", "job_function_total"} <= set(done.timings_ms)
        assert not [p for p in runner.store.root.iterdir() if p.name.startswith(".tmp-")]
        with pytest.raises(KeyError):
            runner.submit("no-such-kind", {}, {})


def test_runner_removes_finished_jobs_after_their_retention(tmp_path):
    """Time is passed in: the runner's clock is moved past the retention instead of waited for."""
    now = [time.time()]
    settings = JobSettings(job_retention_s=3600.0)
    with JobRunner(tmp_path, KINDS, settings, clock=lambda: now[0]) as runner:
        job = runner.submit("echo", {}, {"in.txt": b"hi"})
        assert runner.wait(job.id, 30.0).state is JobState.SUCCEEDED
        assert runner.purge_expired() == []  # ended just now
        now[0] += 3599.0
        assert runner.purge_expired() == []
        now[0] += 2.0
        assert runner.purge_expired() == [job.id]
        with pytest.raises(JobNotFound):
            runner.get(job.id)
        assert job.id not in job_dirs(runner.store)
    kept = JobRunner(tmp_path / "kept", KINDS, JobSettings(job_retention_s=0.0), clock=lambda: now[0] + 1e9)
    with kept:
        job = kept.submit("echo", {}, {"in.txt": b"hi"})
        kept.wait(job.id, 30.0)
        assert kept.purge_expired() == [] and kept.get(job.id).state is JobState.SUCCEEDED


@pytest.mark.parametrize(
    "how, message",
    [
        ("job_error", "the clip is upside down"),
        ("exception", "internal error (ZeroDivisionError) in the job; the server's log has the details"),
        ("exit", "exited with code 3"),
    ],
)
def test_failed_jobs_report_why_and_keep_no_result(tmp_path, how, message):
    with JobRunner(tmp_path, KINDS) as runner:
        job = runner.wait(runner.submit("fail", {"how": how}, {}).id, 30.0)
        assert job.state is JobState.FAILED and message in job.error
        assert "division by zero" not in job.error  # an unexpected exception's words stay in the log
        assert not runner.result_dir(job.id).exists()
        assert not [p for p in runner.store.root.iterdir() if p.name.startswith(".tmp-")]


def test_bounded_concurrency_and_cancellation(tmp_path):
    settings = JobSettings(max_concurrent_jobs=1, cancel_grace_s=1.0)
    first, second = wait_params(tmp_path, "a"), wait_params(tmp_path, "b")
    with JobRunner(tmp_path, KINDS, settings) as runner:
        a = runner.submit("wait", first, {})
        b = runner.submit("wait", second, {})
        pid = wait_until(lambda: started_pids(Path(first["started"])), what="job a to start")[0]
        wait_until(lambda: runner.get(a.id).progress > 0.0, what="progress")
        time.sleep(0.3)
        assert runner.get(b.id).state is JobState.QUEUED  # one at a time
        # cancel the running job: its process is ended, the queued one starts
        assert runner.cancel(a.id).state is JobState.CANCELLED
        wait_until(lambda: not alive(pid), 10.0, "the cancelled job's process to end")
        wait_until(lambda: started_pids(Path(second["started"])), what="job b to start")
        assert runner.get(a.id).state is JobState.CANCELLED and not runner.result_dir(a.id).exists()
        # cancel a queued job: it never runs
        c = runner.submit("echo", {}, {"in.txt": b"x"})
        assert runner.cancel(c.id).state is JobState.CANCELLED
        Path(second["release"]).touch()
        assert runner.wait(b.id, 30.0).state is JobState.SUCCEEDED
        time.sleep(0.3)
        assert runner.get(c.id).state is JobState.CANCELLED and runner.get(c.id).attempts == 0


def test_full_queue_refuses_and_leaves_nothing(tmp_path):
    runner = JobRunner(tmp_path, KINDS, JobSettings(max_queued_jobs=2))  # not started
    runner.submit("echo", {}, {"in.txt": b"1"})
    runner.submit("echo", {}, {"in.txt": b"2"})
    with pytest.raises(QueueFull):
        runner.submit("echo", {}, {"in.txt": b"3"})
    assert len(runner.store.list()) == 2 and len(job_dirs(runner.store)) == 2
    runner.close()


def test_clean_stop_requeues_the_running_job_without_counting_it(tmp_path):
    params = wait_params(tmp_path, "a")
    runner = JobRunner(tmp_path, KINDS)
    runner.start()
    job = runner.submit("wait", params, {})
    wait_until(lambda: started_pids(Path(params["started"])), what="the job to start")
    runner.close()
    again = open_store("", tmp_path / "jobs").get(job.id)
    assert again.state is JobState.QUEUED and again.attempts == 0
    Path(params["release"]).touch()
    with JobRunner(tmp_path, KINDS) as second:
        assert second.wait(job.id, 30.0).state is JobState.SUCCEEDED


def test_one_runner_per_folder(tmp_path):
    with JobRunner(tmp_path, KINDS):
        with pytest.raises(RuntimeError, match="another job runner"):
            JobRunner(tmp_path, KINDS).start()


_CRASHING_FRONT = textwrap.dedent("""
    import sys, time
    from camdirector.front.job_runner import JobRunner
    from camdirector.jobs import JobSettings
    from tests.jobs.toys import KINDS

    if __name__ == "__main__":
        runner = JobRunner(sys.argv[1], KINDS, JobSettings(max_concurrent_jobs=1, job_store=sys.argv[2]))
        runner.start()
        print("ready", flush=True)
        time.sleep(120)
""")


def test_restart_survival_with_a_job_running_and_a_job_queued(tmp_path, records_url):
    """A front process with a runner is killed (SIGKILL) while job A runs and job B waits; its
    job process dies with it. A new runner on the same folder and records reruns A and runs B."""
    data_dir = tmp_path / "data"
    store = open_store(records_url, data_dir / "jobs")
    a_params, b_params = wait_params(tmp_path, "a"), wait_params(tmp_path, "b")
    a = store.submit("wait", a_params, {})
    b = store.submit("wait", b_params, {})
    script = tmp_path / "front.py"
    script.write_text(_CRASHING_FRONT)
    front = subprocess.Popen(
        [sys.executable, str(script), str(data_dir), records_url],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT.parent) + os.pathsep + str(ROOT)},
    )
    try:
        assert front.stdout.readline().strip() == "ready"
        pid = wait_until(lambda: started_pids(Path(a_params["started"])), 30.0, "job A to start")[0]
        assert store.get(a.id).state is JobState.RUNNING and store.get(b.id).state is JobState.QUEUED
    finally:
        front.send_signal(signal.SIGKILL)
        front.wait(10)
    wait_until(lambda: not alive(pid), 10.0, "job A's process to die with the front")
    assert store.get(a.id).state is JobState.RUNNING  # as the crash left it
    Path(a_params["release"]).touch()
    Path(b_params["release"]).touch()
    with JobRunner(data_dir, KINDS, JobSettings(job_store=records_url)) as runner:
        done_a, done_b = runner.wait(a.id, 30.0), runner.wait(b.id, 30.0)
    assert done_a.state is JobState.SUCCEEDED and done_a.attempts == 2  # rerun
    assert done_b.state is JobState.SUCCEEDED and done_b.attempts == 1
    assert (runner.result_dir(a.id) / "done.txt").read_text() == "done"
