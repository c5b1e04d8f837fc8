"""A job whose record store (PostgreSQL) goes away while it runs (issue 40): it runs on, its
outcome is recorded once the store is back, its attempt is counted once, it is not run again and
no `.tmp-*` folder is left. On a queue worker (Redis and PostgreSQL) and on a front's own runner
over PostgreSQL; the store stopped (connections refused) or paused (SIGSTOP: connections hang until
infra/postgres.py's deadline). A worker stopped during the outage hands its job back without
spending an attempt, and a worker cut off from Redis longer than the heartbeat timeout runs no job
twice.
Uses a PostgreSQL of its own, which it stops and starts."""

from __future__ import annotations

import logging
import signal
import uuid
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import psycopg
import pytest

from camdirector.deploy.services import PostgresServer, signal_tree
from camdirector.front.job_runner import JobRunner
from camdirector.jobs import Job, JobRegistry, JobSettings, JobState, JobStore, JobsUnavailable, QueueClient
from tests.conftest import service_or_skip
from tests.cuttable_proxy import CuttableProxy
from tests.jobs.test_queue import WorkerThread
from tests.jobs.toys import TOY_KINDS, alive, started_pids, wait_params, wait_until


@pytest.fixture(scope="module")
def own_postgres(tmp_path_factory) -> Iterator[PostgresServer]:
    server = service_or_skip(lambda: PostgresServer(tmp_path_factory.mktemp("faults-pg")).start())
    yield server
    server.stop()


@pytest.fixture
def store_url(own_postgres) -> str:
    """A new database on the module's PostgreSQL (left for the cluster's removal)."""
    name = f"faults_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(own_postgres.url, autocommit=True) as admin:
        admin.execute(f"CREATE DATABASE {name}")
    return own_postgres.url.rsplit("/", 1)[0] + "/" + name


@pytest.fixture(params=["stopped", "paused"])
def outage(request, own_postgres) -> Iterator[tuple[Callable[[], None], Callable[[], None]]]:
    """(take the store away, bring it back): a fast shutdown and a start on the same data, or
    SIGSTOP and SIGCONT of the server and its backends."""
    pid = own_postgres.postmaster_pid()
    if request.param == "stopped":
        yield lambda: own_postgres.stop(keep_data=True), own_postgres.start
        if own_postgres.postmaster_pid() is None:  # back whatever the test did
            own_postgres.start()
    else:
        yield lambda: signal_tree([pid], signal.SIGSTOP), lambda: signal_tree([pid], signal.SIGCONT)
        signal_tree([pid], signal.SIGCONT)


def record(store: JobStore, job_id: str) -> Job | None:
    """The job's record; None while the store does not answer (the test's own connection too)."""
    try:
        return store.get(job_id)
    except JobsUnavailable:
        return None


def run_through_outage(tmp_path: Path, store: JobStore, submit: Callable[[dict], str], outage, caplog) -> None:
    """A wait job started, the store taken away, the job released and its process ended, the
    executor told by the store that it is down (its log line), the store back: the job succeeds
    with one attempt, its result in place, no `.tmp-*` left."""
    params = wait_params(tmp_path, "a")
    job_id = submit(params)
    (pid,) = wait_until(lambda: started_pids(Path(params["started"])), what="the job to start")
    wait_until(lambda: store.get(job_id).progress > 0.0, what="progress")
    take_away, bring_back = outage
    take_away()
    try:
        Path(params["release"]).touch()
        wait_until(lambda: not alive(pid), 30.0, "the job process to end while the store is down")
        wait_until(lambda: "recorded when the store is back" in caplog.text, 30.0, "the executor to find the store down")
    finally:
        bring_back()
    done = wait_until(lambda: (j := record(store, job_id)) and j.state.finished and j, 60.0, "the job's outcome to be recorded")
    assert done.state is JobState.SUCCEEDED, done.error
    assert done.attempts == 1 and len(started_pids(Path(params["started"]))) == 1, "the job was run again"
    assert done.progress == 1.0 and (store.result_dir(job_id) / "done.txt").read_text() == "done"
    assert not list(store.root.glob(".tmp-*")), "a temp folder was left"


def test_a_queue_workers_job_outlives_a_store_outage(tmp_path, redis_url, store_url, outage, caplog):
    settings = JobSettings(job_queue=redis_url, job_store=store_url, worker_heartbeat_timeout_s=2.0, max_attempts=2)
    client = QueueClient(tmp_path, JobRegistry(TOY_KINDS), settings)
    worker = WorkerThread(tmp_path, settings)
    try:
        run_through_outage(tmp_path, client.store, lambda params: client.submit("wait", params, {}).id, outage, caplog)
    finally:
        worker.stop()
        client.close()


def test_a_local_runners_job_outlives_a_store_outage(tmp_path, store_url, outage, caplog):
    settings = JobSettings(job_store=store_url, max_attempts=2)
    with JobRunner(tmp_path, JobRegistry(TOY_KINDS), settings) as runner:
        run_through_outage(tmp_path, runner.store, lambda params: runner.submit("wait", params, {}).id, outage, caplog)
        echo = runner.submit("echo", {}, {"in.txt": b"x"})  # the runner claims jobs again
        assert runner.wait(echo.id, 30.0).state is JobState.SUCCEEDED


def test_a_worker_stopped_while_the_store_is_down_hands_its_job_back_uncounted(tmp_path, redis_url, store_url, outage, caplog):
    """SIGTERM's path while the store is away: the worker sends the job's message back with its
    claim token but cannot requeue the record, which stays `running`. The next worker takes it
    over by that token: the job succeeds as attempt 1 (run twice, as a stopped worker's job is),
    no `.tmp-*` left."""
    settings = JobSettings(
        job_queue=redis_url, job_store=store_url, worker_heartbeat_timeout_s=2.0, cancel_grace_s=1.0, max_attempts=2
    )
    client = QueueClient(tmp_path, JobRegistry(TOY_KINDS), settings)
    try:
        params = wait_params(tmp_path, "a")
        job_id = client.submit("wait", params, {}).id
        first = WorkerThread(tmp_path, settings)
        wait_until(lambda: started_pids(Path(params["started"])), what="the job to start")
        take_away, bring_back = outage
        take_away()
        try:
            first.stop()
            assert "not requeued" in caplog.text
        finally:
            bring_back()
        held = wait_until(lambda: record(client.store, job_id), 30.0, "the store to answer")
        assert held.state is JobState.RUNNING and held.attempts == 1, "the record was requeued after all"
        Path(params["release"]).touch()
        second = WorkerThread(tmp_path, settings)
        try:
            done = wait_until(lambda: (j := record(client.store, job_id)) and j.state.finished and j, 60.0, "the job to end")
        finally:
            second.stop()
        assert done.state is JobState.SUCCEEDED and done.attempts == 1, (done.state, done.attempts, done.error)
        assert len(started_pids(Path(params["started"]))) == 2
        assert not list(client.store.root.glob(".tmp-*")), "a temp folder was left"
    finally:
        client.close()


def test_a_job_outlives_its_worker_cut_off_from_redis_longer_than_the_heartbeat_timeout(
    tmp_path, redis_server, redis_url, store_url, caplog
):
    """The busy worker reaches Redis through a proxy that cuts it off (connections dropped and
    refused) for three heartbeat timeouts while its job runs; PostgreSQL it still reaches. The
    idle worker's maintenance takes it for dead and requeues its message; the duplicate finds
    the job's lease renewed meanwhile and waits: the job runs once, one attempt."""
    caplog.set_level(logging.INFO, "camdirector.jobs")
    settings = JobSettings(
        job_queue=redis_url, job_store=store_url, worker_heartbeat_timeout_s=2.0, cancel_grace_s=1.0, max_attempts=2
    )
    proxy = CuttableProxy(f"127.0.0.1:{redis_server.port}")
    client = QueueClient(tmp_path, JobRegistry(TOY_KINDS), settings)
    busy = WorkerThread(tmp_path, replace(settings, job_queue=f"redis://{proxy.address}/0"))
    idle = None
    try:
        params = wait_params(tmp_path, "a")
        job_id = client.submit("wait", params, {}).id
        (pid,) = wait_until(lambda: started_pids(Path(params["started"])), what="the job to start on the busy worker")
        idle = WorkerThread(tmp_path, settings)
        proxy.cut(refuse_s=3 * settings.worker_heartbeat_timeout_s)
        wait_until(
            lambda: "runs on another worker" in caplog.text or len(started_pids(Path(params["started"]))) > 1,
            30.0,
            "the requeued duplicate to be refused or run",
        )
        assert started_pids(Path(params["started"])) == [pid] and alive(pid), "the job was run again"
        Path(params["release"]).touch()
        done = wait_until(lambda: (j := client.store.get(job_id)).state.finished and j, 30.0, "the job to end")
        assert done.state is JobState.SUCCEEDED and done.attempts == 1, (done.state, done.attempts, done.error)
        assert started_pids(Path(params["started"])) == [pid]
    finally:
        for worker in (idle, busy):
            if worker is not None:
                worker.stop()
        client.close()
        proxy.close()
