"""The record store (jobs/records.py), every test on SQLite and on PostgreSQL: records,
files renamed into place, a full queue, recovery, retention, the compare-and-set of attempts
that lets a job succeed once when a redelivered message runs it twice, the claims' tokens and
leases (a duplicate waits while the holder lives; a lost reply and a hand-back count no attempt),
tenants and their shares, and a table from before tenants gaining them."""

from __future__ import annotations

import contextlib
import sqlite3
import time

import pytest

from camdirector.jobs import (
    IdempotencyConflict,
    JobHeldElsewhere,
    JobNotFound,
    JobState,
    JobsUnavailable,
    PostgresJobStore,
    QueueFull,
    SqliteJobStore,
    TenantLimitReached,
)


def job_dirs(store) -> set[str]:
    return {p.name for p in store.root.iterdir() if p.is_dir()}


def claim_as_dead(store, job_id: str, max_attempts: int, token: str = "w/1"):
    """A queue worker's claim that finds any holder dead (a lease timeout of 0 s)."""
    return store.claim(job_id, max_attempts, token=token, lease_timeout_s=0.0)


def test_submit_claim_finish_and_files(store):
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
    assert done.as_public() == {
        "id": a.id,
        "status": "succeeded",
        "progress": 1.0,
        "timings": {"x": 2.0},
        "created_unix_s": a.created_s,
        "started_unix_s": claimed.started_s,
        "finished_unix_s": done.finished_s,
    }
    assert store.cancel(b.id).state is JobState.CANCELLED
    assert store.cancel(a.id).state is JobState.SUCCEEDED  # finished: unchanged
    with pytest.raises(JobNotFound):
        store.get("nope")
    with pytest.raises(JobNotFound):
        store.job_dir("../etc")


def test_submit_answers_the_job_as_created_though_a_runner_claims_it_at_once(store, monkeypatch):
    """A runner woken by the commit may claim the job before the submitter reads it back: the
    POST's answer is still the job as created (a dashboard CI run read `running`)."""
    tx = store._tx

    @contextlib.contextmanager
    def tx_then_claim():
        with tx() as db:
            yield db
        monkeypatch.setattr(store, "_tx", tx)  # one claim, as by a runner, right after the commit
        store.claim_next()

    monkeypatch.setattr(store, "_tx", tx_then_claim)
    job = store.submit("echo", {"x": 1}, {})
    assert job.state is JobState.QUEUED and job.attempts == 0 and job.params == {"x": 1}
    assert store.get(job.id).state is JobState.RUNNING


def test_sqlite_keeps_a_wal_journal(tmp_path):
    store = SqliteJobStore(tmp_path)
    with store._read() as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    store.close()


def test_full_queue_and_bad_files_leave_nothing_behind(store):
    store.submit("echo", {}, {"in.txt": b"1"}, max_queued=1)
    before = job_dirs(store)
    with pytest.raises(QueueFull):
        store.submit("echo", {}, {"in.txt": b"2"}, max_queued=1)
    with pytest.raises(ValueError):
        store.submit("echo", {}, {"../evil": b"2"})
    assert job_dirs(store) == before and len(store.list()) == 1


def test_recover_requeues_then_fails_after_max_attempts(store):
    job = store.submit("echo", {}, {})
    (store.root / "orphan").mkdir()
    (store.root / ".tmp-leftover").mkdir()
    store.claim_next()  # attempt 1, then "the server died"
    assert store.recover(max_attempts=2) == ([job.id], [])
    assert store.get(job.id).state is JobState.QUEUED
    assert job_dirs(store) == {job.id}  # orphans removed
    store.claim_next()  # attempt 2, died again
    assert store.recover(max_attempts=2) == ([], [job.id])
    failed = store.get(job.id)
    assert failed.state is JobState.FAILED and "interrupted" in failed.error and "2 time" in failed.error


def test_orphans_are_removed_only_once_old_enough(store):
    (store.root / ".tmp-fresh").mkdir()
    assert store.remove_orphans(older_than_s=3600.0) == []
    assert store.remove_orphans(older_than_s=0.0) == [".tmp-fresh"]


def test_lists_by_kind_and_state_newest_first(store):
    a = store.submit("echo", {}, {})
    b = store.submit("wait", {}, {})
    c = store.submit("echo", {}, {})
    store.cancel(c.id)
    assert [j.id for j in store.list(kind="echo")] == [a.id, c.id]
    assert [j.id for j in store.list(kind="echo", newest_first=True)] == [c.id, a.id]
    assert [j.id for j in store.list(JobState.QUEUED, kind="echo")] == [a.id]
    assert [j.id for j in store.list(newest_first=True, limit=2)] == [c.id, b.id]
    assert store.list(JobState.RUNNING, kind="wait") == []
    assert store.count(JobState.QUEUED) == 2


def test_purges_only_jobs_that_ended_before_the_cutoff(store):
    old, recent, queued = (store.submit("echo", {}, {"in.txt": b"x"}) for _ in range(3))
    for job in (old, recent):
        store.claim_next()
        store.finish(job.id, JobState.SUCCEEDED)
    cutoff = store.get(recent.id).finished_s  # strictly before: `recent` stays
    assert store.purge_finished(cutoff) == [old.id]
    assert [j.id for j in store.list()] == [recent.id, queued.id]
    assert job_dirs(store) == {recent.id, queued.id}
    assert sorted(store.purge_finished(cutoff + 3600.0)) == [recent.id]  # a queued job is never purged
    assert [j.id for j in store.list()] == [queued.id]


def test_a_redelivered_job_succeeds_once_with_the_latest_attempt(store):
    """Worker 1 claims the job and is taken for dead; its message runs again on worker 2. Only
    worker 2's outcome is recorded, and only its result is renamed into place."""
    job = store.submit("echo", {}, {})
    first = claim_as_dead(store, job.id, 3, "w1/a")
    second = claim_as_dead(store, job.id, 3, "w2/b")  # the same message, delivered again
    assert (first.attempts, second.attempts) == (1, 2) and second.state is JobState.RUNNING
    published = []
    assert not store.finish(
        job.id, JobState.SUCCEEDED, attempt=first.attempts, only_if=JobState.RUNNING, publish=lambda: published.append(1)
    )
    store.set_progress(job.id, 0.9, attempt=first.attempts)  # a stale attempt's progress is ignored
    assert store.get(job.id).progress == 0.0 and published == []
    assert store.finish(
        job.id, JobState.SUCCEEDED, attempt=second.attempts, only_if=JobState.RUNNING, publish=lambda: published.append(2)
    )
    assert published == [2] and store.get(job.id).state is JobState.SUCCEEDED
    assert claim_as_dead(store, job.id, 3, "w3/c") is None  # a late duplicate runs nothing
    assert not store.finish(job.id, JobState.FAILED, attempt=second.attempts, only_if=JobState.RUNNING)


def test_claim_fails_a_job_interrupted_too_often_and_skips_cancelled_ones(store):
    job = store.submit("echo", {}, {})
    claim_as_dead(store, job.id, 1, "w1/a")
    assert claim_as_dead(store, job.id, 1, "w2/b") is None  # its worker died once: limit 1
    failed = store.get(job.id)
    assert failed.state is JobState.FAILED and "interrupted" in failed.error
    other = store.submit("echo", {}, {})
    store.cancel(other.id)
    assert claim_as_dead(store, other.id, 2) is None and store.get(other.id).attempts == 0
    assert claim_as_dead(store, "0" * 32, 2) is None  # purged meanwhile


def test_a_failed_publish_changes_nothing(store):
    job = store.submit("echo", {}, {})
    store.claim_next()

    def fail():
        raise OSError("disk full")

    with pytest.raises(OSError):
        store.finish(job.id, JobState.SUCCEEDED, only_if=JobState.RUNNING, publish=fail)
    assert store.get(job.id).state is JobState.RUNNING


def test_requeue_is_compare_and_set_on_the_attempt(store):
    job = store.submit("echo", {}, {})
    claim_as_dead(store, job.id, 3, "w1/a")
    claim_as_dead(store, job.id, 3, "w2/b")  # taken over: attempt 2
    store.requeue(job.id, uncount_attempt=True, attempt=1)  # the old attempt's stop: no effect
    assert store.get(job.id).state is JobState.RUNNING
    store.requeue(job.id, uncount_attempt=True, attempt=2)
    again = store.get(job.id)
    assert again.state is JobState.QUEUED and again.attempts == 1 and again.claimed_by is None


def test_a_duplicate_waits_while_the_holder_renews_its_lease(store):
    """Worker 1 runs the job and renews its lease; a duplicate of the message (worker 1 taken
    for dead by the queue while Redis was away) is refused without an attempt; once worker 1's
    lease is older than the timeout (it died), the duplicate takes the job over, counted."""
    job = store.submit("echo", {}, {})
    first = store.claim(job.id, 3, token="w1/a", lease_timeout_s=30.0)
    assert first.attempts == 1 and first.claimed_by == "w1/a"
    assert store.renew(job.id, "w1/a")
    with pytest.raises(JobHeldElsewhere, match="runs on another worker"):
        store.claim(job.id, 3, token="w2/b", lease_timeout_s=30.0)
    assert store.get(job.id).attempts == 1 and store.get(job.id).claimed_by == "w1/a"
    time.sleep(0.05)
    second = store.claim(job.id, 3, token="w2/b", lease_timeout_s=0.01)  # the lease ran out
    assert second.attempts == 2 and second.claimed_by == "w2/b"
    assert not store.renew(job.id, "w1/a"), "a superseded holder renewed the lease"


def test_a_claim_whose_reply_was_lost_is_found_again_by_its_token(store):
    job = store.submit("echo", {}, {})
    store.claim(job.id, 3, token="w1/a", lease_timeout_s=30.0)  # committed, its answer never read
    again = store.claim(job.id, 3, token="w1/a", lease_timeout_s=30.0)
    assert again.state is JobState.RUNNING and again.attempts == 1 and again.claimed_by == "w1/a"


def test_a_job_handed_back_without_its_record_requeued_is_taken_over_uncounted(store):
    """Worker 1 stopped while the store was down: its message went back carrying its token, the
    record stayed `running` under that token. The message's next claim takes it over as attempt
    1 again; another delivery carrying the same old token then finds the new holder alive."""
    job = store.submit("echo", {}, {})
    store.claim(job.id, 3, token="w1/a", lease_timeout_s=30.0)
    taken = store.claim(job.id, 3, token="w2/b", lease_timeout_s=30.0, handed_back_from="w1/a")
    assert taken.attempts == 1 and taken.claimed_by == "w2/b" and taken.state is JobState.RUNNING
    with pytest.raises(JobHeldElsewhere):
        store.claim(job.id, 3, token="w3/c", lease_timeout_s=30.0, handed_back_from="w1/a")
    store.requeue(job.id, uncount_attempt=True, attempt=1)  # worker 1 had requeued it after all
    assert store.claim(job.id, 3, token="w3/c", lease_timeout_s=30.0, handed_back_from="w1/a").attempts == 1


def test_two_stores_on_one_folder_see_the_same_records(make_store):
    """Two nodes' stores (on SQLite: two connections to the one file)."""
    one, two = make_store(), make_store()
    job = one.submit("echo", {}, {"in.txt": b"x"})
    assert two.get(job.id) == one.get(job.id)
    assert claim_as_dead(two, job.id, 2).attempts == 1
    assert one.get(job.id).state is JobState.RUNNING


def test_records_survive_a_restart(make_store, records_url):
    first = make_store()
    job = first.submit("echo", {"k": [1, 2]}, {"in.txt": b"x"})
    first.close()
    again = make_store().get(job.id)
    assert again.params == {"k": [1, 2]} and again.state is JobState.QUEUED


def test_unreachable_postgres_is_one_clear_line(tmp_path):
    from camdirector.deploy.services import free_port

    url = f"postgresql://camdirector@127.0.0.1:{free_port()}/camdirector"
    with pytest.raises(JobsUnavailable) as caught:
        PostgresJobStore(url, tmp_path)
    message = str(caught.value)
    assert message.startswith(f"job store {url} is unreachable: ") and "\n" not in message


def test_jobs_are_their_tenants(store):
    a = store.submit("echo", {}, {}, tenant="acme")
    b = store.submit("echo", {}, {})
    assert (store.get(a.id).tenant, store.get(b.id).tenant) == ("acme", "default")
    assert [j.id for j in store.list(tenant="acme")] == [a.id]
    assert [j.id for j in store.list(JobState.QUEUED, kind="echo", tenant="default")] == [b.id]
    assert store.list(tenant="beta") == [] and len(store.list()) == 2


def test_a_tenants_share_of_jobs_and_of_stored_inputs(store):
    share = dict(tenant_max_queued_jobs=2, tenant_max_upload_bytes=10)

    def submit(tenant: str, size: int):
        return store.submit("echo", {}, {"in.txt": b"x" * size}, tenant=tenant, **share)

    first, second = submit("acme", 3), submit("acme", 3)
    store.claim_next()  # running counts as much as queued
    before = job_dirs(store)
    with pytest.raises(TenantLimitReached, match="tenant 'acme' has 2 jobs queued or running"):
        submit("acme", 1)
    assert job_dirs(store) == before and len(store.list()) == 2  # refused: nothing left behind
    assert submit("beta", 10).tenant == "beta"  # another tenant's share is its own
    store.finish(first.id, JobState.SUCCEEDED)
    third = submit("acme", 4)  # a place again: 10 bytes kept, the limit
    store.cancel(third.id)
    store.cancel(second.id)
    with pytest.raises(TenantLimitReached, match=r"keep 10 bytes of uploads; 1 more would pass its limit of 10"):
        submit("acme", 1)  # finished jobs keep their inputs until purged
    store.purge_finished(time.time() + 1)
    assert submit("acme", 10).tenant == "acme"


# The jobs table as the first release made it: no tenant, no input sizes.
_OLD_SQLITE_TABLE = """CREATE TABLE jobs (id TEXT PRIMARY KEY, kind TEXT NOT NULL, params TEXT NOT NULL,
    state TEXT NOT NULL, progress REAL NOT NULL DEFAULT 0, error TEXT, attempts INTEGER NOT NULL DEFAULT 0,
    created_s REAL NOT NULL, started_s REAL, finished_s REAL, timings TEXT NOT NULL DEFAULT '{}', seq INTEGER NOT NULL)"""
_OLD_POSTGRES_TABLE = """CREATE TABLE jobs (id TEXT PRIMARY KEY, kind TEXT NOT NULL, params TEXT NOT NULL,
    state TEXT NOT NULL, progress DOUBLE PRECISION NOT NULL DEFAULT 0, error TEXT, attempts INTEGER NOT NULL DEFAULT 0,
    created_s DOUBLE PRECISION NOT NULL, started_s DOUBLE PRECISION, finished_s DOUBLE PRECISION,
    timings TEXT NOT NULL DEFAULT '{}', seq BIGSERIAL NOT NULL)"""
_OLD_ROW = "INSERT INTO jobs (id, kind, params, state, created_s, seq) VALUES ('0ld', 'echo', '{}', 'queued', 1.0, 1)"


def test_a_table_from_before_tenants_gains_them(make_store, records_url, tmp_path):
    """A data directory or database of the first release: its jobs are tenant `default`'s, with
    inputs counted as 0 bytes, and new jobs go in beside them."""
    if records_url:
        import psycopg

        with psycopg.connect(records_url, autocommit=True) as db:
            db.execute(_OLD_POSTGRES_TABLE)
            db.execute(_OLD_ROW)
    else:
        (tmp_path / "jobs").mkdir()
        with contextlib.closing(sqlite3.connect(tmp_path / "jobs" / SqliteJobStore.DB_NAME)) as db:
            db.execute(_OLD_SQLITE_TABLE)
            db.execute(_OLD_ROW)
            db.commit()
    store = make_store()
    old = store.get("0ld")
    assert old.tenant == "default" and old.state is JobState.QUEUED
    new = store.submit("echo", {}, {"in.txt": b"abc"}, tenant="acme", tenant_max_upload_bytes=3)
    assert [j.id for j in store.list()] == ["0ld", new.id] and store.list(tenant="acme") == [store.get(new.id)]
    assert make_store().get("0ld") == old  # opened again: migrated once


def test_a_submit_sent_again_with_its_idempotency_key_answers_the_first_job(store):
    """A client that lost a submit's answer sends it again with the same key: the first job is
    answered, marked replayed, and nothing new is created; another request with that key is
    refused; another tenant's key is its own."""
    first = store.submit("echo", {"x": 1}, {"in.txt": b"abc"}, idempotency_key="k-1")
    again = store.submit("echo", {"x": 1}, {"in.txt": b"abc"}, idempotency_key="k-1", max_queued=1)  # full: still the replay
    assert again.id == first.id and again.replayed and not first.replayed
    assert [j.id for j in store.list()] == [first.id] and job_dirs(store) == {first.id}
    with pytest.raises(IdempotencyConflict, match="k-1"):
        store.submit("echo", {"x": 2}, {"in.txt": b"abc"}, idempotency_key="k-1")
    with pytest.raises(IdempotencyConflict):
        store.submit("echo", {"x": 1}, {"in.txt": b"abd"}, idempotency_key="k-1")
    assert store.earlier_submit("default", "k-1", "echo", {"x": 1}, {"in.txt": b"abc"}).id == first.id
    assert store.earlier_submit("default", "k-2", "echo", {"x": 1}, {"in.txt": b"abc"}) is None
    other = store.submit("echo", {"x": 1}, {"in.txt": b"abc"}, idempotency_key="k-1", tenant="studio-b")
    assert other.id != first.id and not other.replayed
    assert not list(store.root.glob(".tmp-*"))
