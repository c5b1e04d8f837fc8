"""The job queue (jobs/queue.py) on a real Redis and PostgreSQL, with toy job kinds: a
QueueWorker in a thread of the test runs them in real job processes. Jobs run and report
progress, a running job is cancelled, a worker that stops hands its job back (and another worker
finishes it), a message delivered twice runs its job once, and Redis or PostgreSQL down is one
clear line: at a worker's start (the `camdirector job-worker` command) and at a submit."""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from camdirector.deploy.services import free_port
from camdirector.jobs import JobRegistry, JobSettings, JobState, JobsUnavailable, QueueClient, QueueWorker
from tests.jobs.toys import TOY_KINDS, alive, started_pids, wait_params, wait_until

CAMDIRECTOR = [sys.executable, "-m", "camdirector.__main__"]


@pytest.fixture
def settings(redis_url, postgres_url) -> JobSettings:
    return JobSettings(
        job_queue=redis_url, job_store=postgres_url, worker_heartbeat_timeout_s=2.0, cancel_grace_s=1.0, max_attempts=3
    )


@pytest.fixture
def client(tmp_path, settings):
    client = QueueClient(tmp_path, JobRegistry(TOY_KINDS), settings)
    yield client
    client.close()


class WorkerThread:
    """A QueueWorker with the toy kinds, run in a thread of the test."""

    def __init__(self, data_dir: Path, settings: JobSettings):
        self.worker = QueueWorker(data_dir, settings, registry=JobRegistry(TOY_KINDS))
        ready = threading.Event()
        self.thread = threading.Thread(target=self.worker.run, args=(ready.set,), daemon=True)
        self.thread.start()
        assert ready.wait(30), "the queue worker did not start"

    def stop(self) -> None:
        self.worker.stop()
        self.thread.join(30)
        assert not self.thread.is_alive()


@pytest.fixture
def start_worker(tmp_path, settings):
    started = []

    def start(**changes) -> WorkerThread:
        from dataclasses import replace

        started.append(WorkerThread(tmp_path, replace(settings, **changes)))
        return started[-1]

    yield start
    for w in started:
        w.stop()


def test_jobs_run_on_a_queue_worker(client, start_worker):
    start_worker()
    job = client.submit("echo", {}, {"in.txt": b"hi"})
    done = wait_until(lambda: (j := client.get(job.id)).state.finished and j, what="the job to end")
    assert done.state is JobState.SUCCEEDED, done.error
    assert done.attempts == 1 and done.progress == 1.0
    assert (client.result_dir(job.id) / "echo.txt").read_bytes() == b"hihi"
    failed = client.submit("fail", {"how": "job_error"}, {})
    failed = wait_until(lambda: (j := client.get(failed.id)).state.finished and j, what="the failing job")
    assert failed.state is JobState.FAILED and failed.error == "the clip is upside down"
    with pytest.raises(KeyError):
        client.submit("no-such-kind", {}, {})


def test_a_running_job_is_cancelled(tmp_path, client, start_worker):
    start_worker()
    params = wait_params(tmp_path, "a")
    job = client.submit("wait", params, {})
    pid = wait_until(lambda: started_pids(Path(params["started"])), what="the job to start")[0]
    wait_until(lambda: client.get(job.id).progress > 0.0, what="progress")
    assert client.cancel(job.id).state is JobState.CANCELLED
    wait_until(lambda: not alive(pid), 10.0, "the cancelled job's process to end")
    assert client.get(job.id).state is JobState.CANCELLED and not client.result_dir(job.id).exists()
    queued = client.submit("echo", {}, {"in.txt": b"x"})
    assert wait_until(lambda: client.get(queued.id).state is JobState.SUCCEEDED, what="the next job")


def test_a_stopping_worker_hands_its_job_to_another(tmp_path, client, start_worker):
    params = wait_params(tmp_path, "a")
    first = start_worker()
    job = client.submit("wait", params, {})
    wait_until(lambda: started_pids(Path(params["started"])), what="the job to start")
    first.stop()  # SIGTERM's path: the job goes back, uncounted
    again = client.get(job.id)
    assert again.state is JobState.QUEUED and again.attempts == 0
    Path(params["release"]).touch()
    start_worker()
    done = wait_until(lambda: (j := client.get(job.id)).state.finished and j, what="the job to end")
    assert done.state is JobState.SUCCEEDED and done.attempts == 1


def test_a_message_delivered_twice_runs_its_job_once(tmp_path, client, start_worker, caplog):
    """The same job's message sent again (as when a worker is taken for dead while Redis was
    away, though it still runs the job): the second delivery finds the job held under a fresh
    lease and waits; the job runs once, one attempt, and the late duplicate then drops."""
    caplog.set_level(logging.INFO, "camdirector.jobs")
    params = wait_params(tmp_path, "a")
    start_worker(max_concurrent_jobs=2)
    job = client.submit("wait", params, {})
    (first_pid,) = wait_until(lambda: started_pids(Path(params["started"])), what="attempt 1")
    client._actor.send(job.id)  # the duplicate
    wait_until(lambda: "runs on another worker" in caplog.text, 10.0, "the duplicate to be refused")
    assert started_pids(Path(params["started"])) == [first_pid] and alive(first_pid)
    Path(params["release"]).touch()
    done = wait_until(lambda: (j := client.get(job.id)).state.finished and j, what="the job to end")
    assert done.state is JobState.SUCCEEDED and done.attempts == 1
    assert (client.result_dir(job.id) / "done.txt").read_text() == "done"


def test_a_claim_whose_reply_was_lost_runs_its_job_as_one_attempt(tmp_path, client, start_worker):
    """The store commits the claim but its answer never comes back (the connection cut after the
    commit: a fault injected in the worker's store, the one place a unit needs isolating): the
    worker asks again with the same token and runs the job as attempt 1."""
    worker = start_worker().worker
    real_claim, calls = worker.store.claim, []

    def claim_losing_the_first_reply(*args, **kwargs):
        job = real_claim(*args, **kwargs)
        calls.append(job.attempts if job else None)
        if len(calls) == 1:
            raise JobsUnavailable("job store: the connection was cut after the commit")
        return job

    worker.store.claim = claim_losing_the_first_reply
    job = client.submit("echo", {}, {"in.txt": b"hi"})
    done = wait_until(lambda: (j := client.get(job.id)).state.finished and j, what="the job to end")
    assert done.state is JobState.SUCCEEDED and done.attempts == 1 and calls == [1, 1]


def test_submit_with_redis_down_fails_the_job_and_says_why(tmp_path, settings, redis_server):
    client = QueueClient(tmp_path, JobRegistry(TOY_KINDS), settings)
    client._broker.client.connection_pool.disconnect()
    redis_port = redis_server.port
    redis_server.stop()
    try:
        with pytest.raises(JobsUnavailable, match=f"job queue redis://127.0.0.1:{redis_port}/0 is unreachable"):
            client.submit("echo", {}, {"in.txt": b"x"}, idempotency_key="k-1")
        (job,) = client.store.list()
        assert job.state is JobState.FAILED and job.error == "could not be queued: the job queue is unreachable"
    finally:
        redis_server.start()
    try:  # the client's retry with the same key makes a new job: the refused one freed its key
        again = client.submit("echo", {}, {"in.txt": b"x"}, idempotency_key="k-1")
        assert again.id != job.id and not again.replayed and again.state is JobState.QUEUED
    finally:
        client.close()


@pytest.mark.parametrize("down", ["redis", "postgres"])
def test_a_worker_or_front_refuses_to_start_when_a_service_is_down(tmp_path, redis_url, postgres_url, down):
    dead = (
        f"redis://127.0.0.1:{free_port()}/0"
        if down == "redis"
        else f"postgresql://camdirector@127.0.0.1:{free_port()}/camdirector"
    )
    queue, store = (dead, postgres_url) if down == "redis" else (redis_url, dead)
    done = subprocess.run(
        [*CAMDIRECTOR, "job-worker", "--job-queue", queue, "--job-store", store, "--data-dir", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    what = "job queue" if down == "redis" else "job store"
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith(f"camdirector job-worker: {what} {dead} is unreachable: ")
    assert done.stderr.count("\n") == 1, done.stderr
    with pytest.raises(JobsUnavailable, match=f"{what} {dead} is unreachable"):
        QueueClient(tmp_path, JobRegistry(TOY_KINDS), JobSettings(job_queue=queue, job_store=store))


def test_job_worker_needs_a_queue(tmp_path):
    done = subprocess.run(
        [*CAMDIRECTOR, "job-worker", "--data-dir", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
        env={"PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 2 and "--job-queue redis://HOST:PORT/DB is required" in done.stderr


@pytest.mark.parametrize("down", ["redis", "postgres"])
def test_serve_refuses_to_start_when_a_service_is_down(tmp_path, redis_url, postgres_url, down):
    dead = (
        f"redis://127.0.0.1:{free_port()}/0"
        if down == "redis"
        else f"postgresql://camdirector@127.0.0.1:{free_port()}/camdirector"
    )
    queue, store = (dead, postgres_url) if down == "redis" else (redis_url, dead)
    done = subprocess.run(
        [
            *CAMDIRECTOR,
            "serve",
            "--grpc",
            "",
            "--zmq",
            "",
            "--http",
            "127.0.0.1:0",
            "--workers",
            "0",
            "--data-dir",
            str(tmp_path),
            "--job-queue",
            queue,
            "--job-store",
            store,
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    what = "job queue" if down == "redis" else "records database (keys)"  # the first to reach PostgreSQL
    assert done.returncode != 0 and done.stdout == "", done.stdout
    assert done.stderr.splitlines()[-1].startswith(f"camdirector serve: {what} {dead} is unreachable: "), done.stderr


def test_a_submit_sent_again_with_its_idempotency_key_sends_no_second_message(client):
    from camdirector.jobs.queue import QUEUE_NAME

    first = client.submit("echo", {}, {"in.txt": b"hi"}, idempotency_key="k-1")
    again = client.submit("echo", {}, {"in.txt": b"hi"}, idempotency_key="k-1")
    assert again.id == first.id and again.replayed
    assert client._broker.do_qsize(QUEUE_NAME) == 1
