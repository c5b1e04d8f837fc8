"""The job store and runner (server/jobs.py): SQLite rows, files renamed into place, real job
processes, bounded concurrency, cancellation, a full queue, and restart survival (a runner process
killed with SIGKILL while one job runs and one is queued, then a new runner on the same folder).

The toy job kinds below are module-level so that job processes import them by reference.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from camdirector.precompute.jobs import JobError
from camdirector.server.jobs import JobKind, JobNotFound, JobRegistry, JobRunner, JobSettings, JobState, JobStore, QueueFull

ROOT = Path(__file__).resolve().parents[2]


def echo_job(params, input_dir: Path, output_dir: Path, progress) -> dict:
    progress(0.5)
    (output_dir / "echo.txt").write_bytes((input_dir / "in.txt").read_bytes() * 2)
    return {"echo": 1.0}


def wait_job(params, input_dir: Path, output_dir: Path, progress) -> dict:
    """Runs until the file params["release"] exists (at most 60 s); marks params["started"]."""
    Path(params["started"]).with_suffix(f".{os.getpid()}").touch()
    deadline = time.monotonic() + 60.0
    while not Path(params["release"]).exists():
        if time.monotonic() > deadline:
            raise JobError("never released")
        progress(0.25)
        time.sleep(0.02)
    (output_dir / "done.txt").write_text("done")
    return {}


def failing_job(params, input_dir, output_dir, progress) -> dict:
    (output_dir / "partial.txt").write_text("half")
    if params["how"] == "job_error":
        raise JobError("the clip is upside down")
    if params["how"] == "exception":
        raise ZeroDivisionError("division by zero")
    os._exit(3)


KINDS = JobRegistry((JobKind("echo", echo_job), JobKind("wait", wait_job),
                     JobKind("fail", failing_job)))


def wait_until(predicate, timeout_s: float = 20.0, what: str = "condition"):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def started_pids(marker: Path) -> list[int]:
    return [int(p.suffix[1:]) for p in marker.parent.glob(marker.name + ".*")]


def job_dirs(store: JobStore) -> set[str]:
    return {p.name for p in store.root.iterdir() if p.is_dir()}


def wait_params(tmp_path: Path, name: str) -> dict:
    return {"started": str(tmp_path / f"{name}-started"), "release": str(tmp_path / f"{name}-release")}


# -- store ------------------------------------------------------------------------------------

def test_store_submit_claim_finish_and_files(tmp_path):
    store = JobStore(tmp_path / "jobs")
    a = store.submit("echo", {"x": 1}, {"in.txt": b"abc"})
    b = store.submit("echo", {"x": 2}, {})
    assert a.state is JobState.QUEUED and a.progress == 0.0 and a.attempts == 0
    assert (store.input_dir(a.id) / "in.txt").read_bytes() == b"abc"
    assert [j.id for j in store.list()] == [a.id, b.id]
    claimed = store.claim_next()
    assert claimed.id == a.id and claimed.state is JobState.RUNNING and claimed.attempts == 1
    store.set_progress(a.id, 0.4)
    assert store.get(a.id).progress == pytest.approx(0.4)
    assert store.finish(a.id, JobState.SUCCEEDED, timings_ms={"x": 2.0})
    done = store.get(a.id)
    assert done.progress == 1.0 and done.timings_ms == {"x": 2.0} and done.finished_s is not None
    assert done.as_public() == {"id": a.id, "status": "succeeded", "progress": 1.0,
                                "timings": {"x": 2.0}, "created_unix_s": a.created_s,
                                "started_unix_s": claimed.started_s, "finished_unix_s": done.finished_s}
    assert store.cancel(b.id).state is JobState.CANCELLED
    assert store.cancel(a.id).state is JobState.SUCCEEDED       # finished: unchanged
    with pytest.raises(JobNotFound):
        store.get("nope")
    with pytest.raises(JobNotFound):
        store.job_dir("../etc")
    assert store._db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_store_full_queue_and_bad_files_leave_nothing_behind(tmp_path):
    store = JobStore(tmp_path / "jobs")
    store.submit("echo", {}, {"in.txt": b"1"}, max_queued=1)
    before = job_dirs(store)
    with pytest.raises(QueueFull):
        store.submit("echo", {}, {"in.txt": b"2"}, max_queued=1)
    with pytest.raises(ValueError):
        store.submit("echo", {}, {"../evil": b"2"})
    assert job_dirs(store) == before and len(store.list()) == 1


def test_store_recover_requeues_then_fails_after_max_attempts(tmp_path):
    store = JobStore(tmp_path / "jobs")
    job = store.submit("echo", {}, {})
    (store.root / "orphan").mkdir()
    (store.root / ".tmp-leftover").mkdir()
    store.claim_next()                                     # attempt 1, then "the server died"
    assert store.recover(max_attempts=2) == ([job.id], [])
    assert store.get(job.id).state is JobState.QUEUED
    assert job_dirs(store) == {job.id}                     # orphans removed
    store.claim_next()                                     # attempt 2, died again
    assert store.recover(max_attempts=2) == ([], [job.id])
    failed = store.get(job.id)
    assert failed.state is JobState.FAILED and "interrupted" in failed.error and "2 time" in failed.error


def test_store_lists_by_kind_and_state_newest_first(tmp_path):
    store = JobStore(tmp_path / "jobs")
    a = store.submit("echo", {}, {})
    b = store.submit("wait", {}, {})
    c = store.submit("echo", {}, {})
    store.cancel(c.id)
    assert [j.id for j in store.list(kind="echo")] == [a.id, c.id]
    assert [j.id for j in store.list(kind="echo", newest_first=True)] == [c.id, a.id]
    assert [j.id for j in store.list(JobState.QUEUED, kind="echo")] == [a.id]
    assert [j.id for j in store.list(newest_first=True, limit=2)] == [c.id, b.id]
    assert store.list(JobState.RUNNING, kind="wait") == []


def test_store_purges_only_jobs_that_ended_before_the_cutoff(tmp_path):
    store = JobStore(tmp_path / "jobs")
    old, recent, queued = (store.submit("echo", {}, {"in.txt": b"x"}) for _ in range(3))
    for job in (old, recent):
        store.claim_next()
        store.finish(job.id, JobState.SUCCEEDED)
    cutoff = store.get(recent.id).finished_s            # strictly before: `recent` stays
    assert store.purge_finished(cutoff) == [old.id]
    assert [j.id for j in store.list()] == [recent.id, queued.id]
    assert job_dirs(store) == {recent.id, queued.id}
    assert sorted(store.purge_finished(cutoff + 3600.0)) == [recent.id]   # a queued job is never purged
    assert [j.id for j in store.list()] == [queued.id]


def test_settings_are_validated():
    with pytest.raises(ValueError, match="max_concurrent_jobs"):
        JobSettings(max_concurrent_jobs=0)
    with pytest.raises(ValueError, match="max_upload_bytes"):
        JobSettings(max_upload_bytes=10)
    with pytest.raises(ValueError, match="job_retention_s"):
        JobSettings(job_retention_s=-1.0)


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
        assert runner.purge_expired() == []                 # ended just now
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


@pytest.mark.parametrize("how, message", [
    ("job_error", "the clip is upside down"),
    ("exception", "ZeroDivisionError: division by zero"),
    ("exit", "exited with code 3"),
])
def test_failed_jobs_report_why_and_keep_no_result(tmp_path, how, message):
    with JobRunner(tmp_path, KINDS) as runner:
        job = runner.wait(runner.submit("fail", {"how": how}, {}).id, 30.0)
        assert job.state is JobState.FAILED and message in job.error
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
        assert runner.get(b.id).state is JobState.QUEUED          # one at a time
        # cancel the running job: its process is ended, the queued one starts
        assert runner.cancel(a.id).state is JobState.CANCELLED
        wait_until(lambda: not _alive(pid), 10.0, "the cancelled job's process to end")
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
    runner = JobRunner(tmp_path, KINDS, JobSettings(max_queued_jobs=2))   # not started
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
    again = JobStore(tmp_path / "jobs").get(job.id)
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
    from camdirector.server.jobs import JobRunner, JobSettings
    from tests.server.test_jobs import KINDS

    if __name__ == "__main__":
        runner = JobRunner(sys.argv[1], KINDS, JobSettings(max_concurrent_jobs=1))
        runner.start()
        print("ready", flush=True)
        time.sleep(120)
""")


def test_restart_survival_with_a_job_running_and_a_job_queued(tmp_path):
    """A front process with a runner is killed (SIGKILL) while job A runs and job B waits; its
    job process dies with it. A new runner on the same folder reruns A and runs B."""
    data_dir = tmp_path / "data"
    store = JobStore(data_dir / "jobs")
    a_params, b_params = wait_params(tmp_path, "a"), wait_params(tmp_path, "b")
    a = store.submit("wait", a_params, {})
    b = store.submit("wait", b_params, {})
    script = tmp_path / "front.py"
    script.write_text(_CRASHING_FRONT)
    front = subprocess.Popen([sys.executable, str(script), str(data_dir)], cwd=ROOT,
                             stdout=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONPATH": str(ROOT.parent) + os.pathsep + str(ROOT)})
    try:
        assert front.stdout.readline().strip() == "ready"
        pid = wait_until(lambda: started_pids(Path(a_params["started"])), 30.0, "job A to start")[0]
        assert store.get(a.id).state is JobState.RUNNING and store.get(b.id).state is JobState.QUEUED
    finally:
        front.send_signal(signal.SIGKILL)
        front.wait(10)
    wait_until(lambda: not _alive(pid), 10.0, "job A's process to die with the front")
    assert store.get(a.id).state is JobState.RUNNING               # as the crash left it
    Path(a_params["release"]).touch()
    Path(b_params["release"]).touch()
    with JobRunner(data_dir, KINDS) as runner:
        done_a, done_b = runner.wait(a.id, 30.0), runner.wait(b.id, 30.0)
    assert done_a.state is JobState.SUCCEEDED and done_a.attempts == 2     # rerun
    assert done_b.state is JobState.SUCCEEDED and done_b.attempts == 1
    assert (runner.result_dir(a.id) / "done.txt").read_text() == "done"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:   # a zombie counts as dead
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except OSError:
        return False
