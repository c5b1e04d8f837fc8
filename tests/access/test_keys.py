"""The access store on both backends (SQLite and PostgreSQL: tests/conftest.py's records_url), and
the guard over it: keys made, checked, revoked; the first admin key; session owners; the audit."""

from __future__ import annotations

import asyncio
import os
import stat
import threading
import time

import grpc
import pytest

from camdirector.access.guard import OPEN, Guard, bearer
from camdirector.access.keys import (
    ADMIN_KEY_FILE,
    LOGIN_SECRET,
    KeyNotFound,
    PostgresAccessStore,
    SqliteAccessStore,
    ensure_admin_key,
    secret_hash,
    split_key,
)
from camdirector.access.roles import Verb
from camdirector.errors import DirectorError


@pytest.fixture
def make_store(tmp_path, records_url):
    opened = []

    def make():
        store = PostgresAccessStore(records_url) if records_url else SqliteAccessStore(tmp_path)
        opened.append(store)
        return store

    yield make
    for store in opened:
        store.close()


def _code(call) -> str:
    with pytest.raises(DirectorError) as caught:
        call()
    return caught.value.code.name


def test_a_key_is_shown_once_and_stored_hashed(make_store):
    store = make_store()
    record, text = store.create_key("engine", "studio-a", "match PC 3")
    key_id, secret = split_key(text)
    assert key_id == record.key_id and len(secret) >= 43
    found, stored = store.lookup(key_id)
    assert found == record and stored == secret_hash(secret) and secret not in stored
    assert [k.key_id for k in store.list_keys("studio-a")] == [key_id] and store.list_keys("other") == []


@pytest.mark.parametrize(
    "role, tenant, name",
    [("root", "default", ""), ("admin", "Big Studio", ""), ("admin", "", ""), ("viewer", "default", "x" * 201)],
)
def test_bad_roles_tenants_and_names_are_refused(make_store, role, tenant, name):
    with pytest.raises(ValueError):
        make_store().create_key(role, tenant, name)


def test_the_guard_answers_unauthenticated_and_permission_denied_apart(make_store):
    store = make_store()
    guard = Guard(store)
    _, viewer = store.create_key("viewer", "alpha")
    assert guard.authorize(f"Bearer {viewer}", Verb.SESSION_READ).tenant == "alpha"
    assert _code(lambda: guard.authorize(f"Bearer {viewer}", Verb.SESSION_TAKE)) == "PERMISSION_DENIED"
    for authorization in (
        None,
        "",
        "Bearer",
        "Basic abc",
        "Bearer cdk_nothing",
        f"Bearer {viewer}x",
        f"Bearer {viewer[:-1]}",
        "Bearer cdk_000000000000_secret",
        "Bearer cdk_" + "\x00" * 12 + "_secret",  # PostgreSQL would refuse it with an error: never asked
        "Bearer cdk_00000000000é_secret",
        "Bearer cdk_ABCDEF012345_secret",
    ):
        assert _code(lambda a=authorization: guard.identify(a)) == "UNAUTHENTICATED", authorization


def test_a_revoked_key_is_refused_at_once_by_every_call_but_a_frame(make_store):
    store, other_node = make_store(), make_store()
    guard = Guard(store)
    record, key = other_node.create_key("engine")
    guard.identify(f"Bearer {key}", fresh=False)  # cached by this node now
    other_node.revoke(record.key_id)  # through another node
    assert guard.identify(f"Bearer {key}", fresh=False).key_id == record.key_id  # a frame: until the poll
    assert _code(lambda: guard.identify(f"Bearer {key}")) == "UNAUTHENTICATED"  # any other call: at once
    assert _code(lambda: guard.identify(f"Bearer {key}", fresh=False)) == "UNAUTHENTICATED"  # the cache learnt it


def test_a_stream_learns_of_a_revocation_from_the_poll(make_store):
    store, other_node = make_store(), make_store()
    guard = Guard(store)
    record, key = other_node.create_key("engine")
    identity = guard.identify(f"Bearer {key}", fresh=False)
    guard.still_valid(identity)
    other_node.revoke(record.key_id)
    guard.still_valid(identity)  # the cache has not heard yet
    assert guard.poll_revocations() == [record.key_id]
    assert _code(lambda: guard.still_valid(identity)) == "UNAUTHENTICATED"


def test_revoking_again_changes_nothing_and_another_tenants_key_is_not_found(make_store):
    store = make_store()
    record, _ = store.create_key("viewer", "alpha")
    with pytest.raises(KeyNotFound):
        store.revoke(record.key_id, tenant="beta")
    first = store.revoke(record.key_id, tenant="alpha")
    assert first.revoked and store.revoke(record.key_id).revoked_s == first.revoked_s
    with pytest.raises(KeyNotFound):
        store.revoke("000000000000")


def test_the_first_admin_key_is_made_once_with_mode_0600(make_store, tmp_path):
    store = make_store()
    path = ensure_admin_key(store, tmp_path / "data")
    assert path == tmp_path / "data" / ADMIN_KEY_FILE and stat.S_IMODE(os.stat(path).st_mode) == 0o600
    key = path.read_text().strip()
    assert Guard(store).identify(f"Bearer {key}").role == "admin"
    assert ensure_admin_key(store, tmp_path / "data") is None
    store.revoke(split_key(key)[0])
    assert ensure_admin_key(store, tmp_path / "other") is not None  # none active: a new one


def test_nodes_starting_together_make_one_admin_key(make_store, tmp_path):
    stores = [make_store() for _ in range(4)]
    made = []
    threads = [
        threading.Thread(target=lambda s=s, i=i: made.append(ensure_admin_key(s, tmp_path / str(i))))
        for i, s in enumerate(stores)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sum(path is not None for path in made) == 1
    assert [k.role for k in stores[0].list_keys()] == ["admin"]


def test_session_owners_audit_and_shared_secrets(make_store):
    store, other_node = make_store(), make_store()
    store.set_session_owner("s1", "alpha")
    assert other_node.session_owner("s1") == "alpha" and other_node.session_owner("s2") is None
    other_node.forget_session("s1")
    assert store.session_owner("s1") is None
    store.audit("alpha", "k1", "take", "s1", {"subject_ids": ["p1"]})
    store.audit("beta", "k2", "style", "s2", {})
    trail = other_node.audit_trail("alpha")
    assert [(e["key_id"], e["action"], e["session_id"], e["detail"]) for e in trail] == [
        ("k1", "take", "s1", {"subject_ids": ["p1"]})
    ]
    assert other_node.audit_trail("alpha", after_seq=trail[0]["seq"]) == []
    assert store.shared_secret("cookie") == other_node.shared_secret("cookie") != store.shared_secret("other")


def test_a_replaced_login_secret_reaches_every_node_at_its_next_poll(make_store):
    store, other_node = make_store(), make_store()
    here, there = Guard(store), Guard(other_node)
    first = here.login_secret
    assert there.login_secret == first == store.shared_secret(LOGIN_SECRET)  # the nodes sign alike
    other_node.rotate_secret(LOGIN_SECRET)
    assert here.login_secret == first  # until the poll
    here.poll_revocations()
    assert here.login_secret == other_node.shared_secret(LOGIN_SECRET) != first


def test_a_login_ended_on_one_node_is_refused_by_every_node_until_its_cookie_expires(make_store):
    store, other_node = make_store(), make_store()
    now = [time.time()]
    here, there = Guard(store), Guard(other_node, clock=lambda: now[0])
    expires_s = now[0] + 3600
    here.end_login("a" * 32, expires_s)
    assert here.login_ended("a" * 32) and not there.login_ended("a" * 32)  # here at once, there at its poll
    there.poll_revocations()
    assert there.login_ended("a" * 32) and not there.login_ended("b" * 32)
    assert Guard(make_store()).login_ended("a" * 32)  # a node started later knows it from the start
    now[0] = expires_s + 1  # its cookie has expired: nothing left to refuse
    there.poll_revocations()
    assert not there.login_ended("a" * 32)
    store.end_login("b" * 32, time.time() - 1)  # recorded, and gone with the next one ended
    store.end_login("c" * 32, time.time() + 3600)
    with store._read() as db:  # the records keep no login past its cookie's expiry
        assert sorted(row[0] for row in db.execute("SELECT login_id FROM ended_logins").fetchall()) == ["a" * 32, "c" * 32]
    assert sorted(store.ended_logins(0.0))[0] == ("a" * 32, expires_s)


def test_the_sqlite_store_is_readable_by_its_user_only(tmp_path):
    store = SqliteAccessStore(tmp_path)
    assert stat.S_IMODE(os.stat(store.where).st_mode) == 0o600
    store.close()


def test_without_authentication_everyone_is_the_default_admin():
    guard = Guard(None)
    assert guard.identify(None) == OPEN and guard.authorize("Bearer junk", Verb.KEY_MANAGE) == OPEN
    assert bearer("bearer  abc ") == "abc" and bearer("Basic abc") is None


def test_the_watcher_polls_until_stopped(make_store):
    store = make_store()
    guard = Guard(store, poll_s=0.01)
    record, key = store.create_key("engine")
    identity = guard.identify(f"Bearer {key}", fresh=False)

    async def run():
        guard.start()
        store.revoke(record.key_id)
        for _ in range(200):
            await asyncio.sleep(0.01)
            try:
                guard.still_valid(identity)
            except DirectorError as exc:
                guard.stop()
                return exc.code
        guard.stop()
        return None

    assert asyncio.run(run()) == grpc.StatusCode.UNAUTHENTICATED
