"""The session router's memory of sessions lost with their worker, a session whose owner cannot be
recorded, and the front's metrics of a frame."""

from __future__ import annotations

import asyncio
import uuid

import grpc
import pytest

from camdirector.access.guard import Guard
from camdirector.access.keys import AccessUnavailable, PostgresAccessStore, SqliteAccessStore
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.services import PostgresServer
from camdirector.errors import DirectorError
from camdirector.front import router as router_module
from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionEntry, SessionRouter
from camdirector.geometry.camera import Lens
from camdirector.server_settings import ServerSettings
from tests.conftest import service_or_skip


def _code_and_message(router: SessionRouter, session_id: str) -> tuple[grpc.StatusCode, str]:
    with pytest.raises(DirectorError) as err:
        router._entry(session_id, "default")
    return err.value.code, err.value.message


def test_without_checkpoints_sessions_lost_with_their_worker_say_so_and_the_oldest_are_forgotten(tmp_path, monkeypatch):
    monkeypatch.setattr(router_module, "LOST_IDS_KEPT", 3)
    router = SessionRouter(ServerSettings(workers=0, data_dir=str(tmp_path), checkpoint_store="off"), Metrics())
    for i in range(5):
        router.sessions[f"lost-{i}"] = SessionEntry(slot=0, created_s=0.0, last_seen_s=0.0)
    router._worker_lost(0)
    assert router.sessions == {}
    for i in (2, 3, 4):  # the newest LOST_IDS_KEPT
        code, message = _code_and_message(router, f"lost-{i}")
        assert code == grpc.StatusCode.UNAVAILABLE and "worker process holding it" in message and "died" in message
    for session_id in ("lost-0", "lost-1", "never-made"):  # forgotten, or never known
        code, message = _code_and_message(router, session_id)
        assert code == grpc.StatusCode.NOT_FOUND and "unknown session id" in message


def test_with_checkpoints_sessions_of_a_lost_worker_go_to_the_least_loaded_others_to_be_restored(tmp_path):
    router = SessionRouter(ServerSettings(workers=3, data_dir=str(tmp_path)), Metrics())
    for i in range(4):
        router.sessions[f"lost-{i}"] = SessionEntry(slot=0, created_s=0.0, last_seen_s=0.0)
    router.sessions["kept"] = SessionEntry(slot=1, created_s=0.0, last_seen_s=0.0)
    router._worker_lost(0)
    moved = [router.sessions[f"lost-{i}"] for i in range(4)]
    assert all(e.restoring for e in moved) and not router.sessions["kept"].restoring
    assert sorted(e.slot for e in moved) == [1, 1, 2, 2]  # five sessions on two workers: three and two


def test_with_checkpoints_a_client_request_for_an_unknown_session_is_given_to_a_worker_to_restore(tmp_path):
    router = SessionRouter(ServerSettings(workers=2, data_dir=str(tmp_path)), Metrics())
    entry = asyncio.run(router._client_entry("from-elsewhere", "default"))
    assert entry.restoring and router.sessions["from-elsewhere"] is entry
    code, message = _code_and_message(router, "never-asked-by-its-client")  # the dashboard's asks adopt nothing
    assert code == grpc.StatusCode.NOT_FOUND and "never-asked-by-its-client" not in router.sessions


def test_another_tenants_session_is_answered_as_one_that_does_not_exist(tmp_path):
    router = SessionRouter(ServerSettings(workers=2, data_dir=str(tmp_path)), Metrics())
    router.sessions["s-alpha"] = SessionEntry(slot=0, created_s=0.0, last_seen_s=0.0, tenant="alpha")
    assert router._entry("s-alpha", "alpha").tenant == "alpha"
    with pytest.raises(DirectorError) as theirs:
        router._entry("s-alpha", "beta")
    with pytest.raises(DirectorError) as missing:
        router._entry("s-other", "beta")
    assert theirs.value.code == missing.value.code == grpc.StatusCode.NOT_FOUND
    assert theirs.value.message.replace("s-alpha", "ID") == missing.value.message.replace("s-other", "ID")
    assert [s["session_id"] for s in router.describe("alpha")] == ["s-alpha"] and router.describe("beta") == []


def test_with_keys_a_node_adopts_only_a_session_the_records_say_is_the_callers(tmp_path):
    store = SqliteAccessStore(tmp_path)
    store.set_session_owner("s-alpha", "alpha")  # written by the node that created it
    router = SessionRouter(ServerSettings(workers=2, data_dir=str(tmp_path)), Metrics(), guard=Guard(store))
    with pytest.raises(DirectorError) as refused:
        asyncio.run(router._client_entry("s-alpha", "beta"))
    assert refused.value.code == grpc.StatusCode.NOT_FOUND and "s-alpha" not in router.sessions
    assert asyncio.run(router._client_entry("s-alpha", "alpha")).restoring
    with pytest.raises(DirectorError):
        asyncio.run(router._client_entry("s-unknown", "alpha"))  # no owner on record: nobody's
    store.close()


def test_a_session_whose_owner_cannot_be_recorded_is_dropped_by_its_worker(tmp_path, monkeypatch):
    """CreateSession with the records database gone between the key's check and the owner's record:
    UNAVAILABLE to the caller (who retries), and no session left on the worker that nobody could
    reach again."""
    postgres = service_or_skip(lambda: PostgresServer(tmp_path / "postgres").start())
    session_id = "0123456789abcdef0123456789abcdef"
    monkeypatch.setattr(router_module.uuid, "uuid4", lambda: uuid.UUID(session_id))
    settings = ServerSettings(workers=1, data_dir=str(tmp_path / "data"), checkpoint_store="off")
    router = SessionRouter(settings, Metrics(), guard=Guard(PostgresAccessStore(postgres.url)))
    scene = build_demo_scene(seed=7, duration_s=1.0)
    frame = next(frame_updates(scene, 1))
    frame.session_id = session_id

    async def create_then_frame() -> DirectorError:
        await router.pool.start()
        try:
            postgres.stop()
            with pytest.raises(AccessUnavailable):
                await router.create(session_request(scene, Lens()).SerializeToString(), "grpc")
            with pytest.raises(DirectorError) as unknown:
                await router.pool.call(0, "frame", session_id, frame.SerializeToString())
            return unknown.value
        finally:
            await router.pool.stop()

    try:
        unknown = asyncio.run(create_then_frame())
    finally:
        postgres.stop()
    assert router.sessions == {} and unknown.code == grpc.StatusCode.NOT_FOUND, unknown


def _sample(metrics: Metrics, name: str, labels: dict) -> float:
    return metrics.registry.get_sample_value(name, labels)


def test_a_frame_answered_is_counted_with_its_stage_times():
    metrics = Metrics()
    metrics.frame_answered("zmq", 0.5, {"ingest": 0.02, "motion": 0.13}, stale=False)
    metrics.frame_answered("zmq", 0.01, {}, stale=True)
    metrics.frame_answered("grpc", 0.4, {"ingest": 0.03}, stale=False, checkpoint_failed=True)
    assert _sample(metrics, "camdirector_checkpoint_failures_total", {}) == 1.0  # the checkpoint store was down
    assert _sample(metrics, "camdirector_frames_total", {"transport": "zmq"}) == 2.0
    assert _sample(metrics, "camdirector_frames_total", {"transport": "grpc"}) == 1.0
    assert _sample(metrics, "camdirector_stale_frames_total", {}) == 1.0
    assert _sample(metrics, "camdirector_frame_compute_seconds_count", {}) == 3.0
    assert _sample(metrics, "camdirector_stage_seconds_count", {"stage": "ingest"}) == 2.0
    assert _sample(metrics, "camdirector_stage_seconds_sum", {"stage": "motion"}) == pytest.approx(0.13e-3)
    assert _sample(metrics, "camdirector_stage_seconds_bucket", {"stage": "motion", "le": "0.0002"}) == 1.0  # 0.13 ms
    assert _sample(metrics, "camdirector_stage_seconds_bucket", {"stage": "motion", "le": "0.0001"}) == 0.0
    assert _sample(metrics, "camdirector_frame_compute_seconds_bucket", {"le": "0.0005"}) == 3.0  # a bound is in its bucket
    assert _sample(metrics, "camdirector_frame_compute_seconds_bucket", {"le": "0.0002"}) == 1.0
    assert metrics.labelled(metrics.request, "grpc", "Frame") is metrics.request.labels("grpc", "Frame")
