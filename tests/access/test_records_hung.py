"""The guard and the session router on the front's event loop while the records database hangs
(PostgreSQL stopped by SIGSTOP, issue 40): a key read fresh, a session's owner and an audit write
wait in the guard's threads and come back AccessUnavailable, a key the node knows is answered from
its cache, and the loop runs on meanwhile (a ticker task counts its turns)."""

from __future__ import annotations

import asyncio

import pytest

from camdirector.access.guard import Guard
from camdirector.access.keys import AccessUnavailable, PostgresAccessStore
from camdirector.access.roles import Verb
from camdirector.deploy.services import PostgresServer
from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionRouter
from camdirector.server_settings import ServerSettings
from tests.conftest import service_or_skip
from tests.infra.test_postgres_deadlines import RETURNS_WITHIN_S, stopped

TICK_S = 0.01
TICKS_WHILE_WAITING = 10  # the ticker's turns while the calls wait, at the least (a loop that waits gets none)


def test_the_loop_runs_on_while_the_records_database_hangs(tmp_path):
    postgres = service_or_skip(lambda: PostgresServer(tmp_path / "postgres").start())
    try:
        store = PostgresAccessStore(postgres.url)
        _, key = store.create_key("engine", "alpha")
        guard = Guard(store)
        router = SessionRouter(ServerSettings(workers=1, data_dir=str(tmp_path / "data")), Metrics(), guard=guard)

        async def while_hung() -> int:
            known = await guard.authorize_async(f"Bearer {key}", Verb.SESSION_CREATE)  # read, and cached
            ticks = 0

            async def tick() -> None:
                nonlocal ticks
                while True:
                    await asyncio.sleep(TICK_S)
                    ticks += 1

            ticker = asyncio.create_task(tick())
            with stopped(postgres):
                with pytest.raises(AccessUnavailable):
                    await guard.authorize_async(f"Bearer {key}", Verb.SESSION_CREATE, fresh=True)
                assert await guard.authorize_async(f"Bearer {key}", Verb.SESSION_STREAM, fresh=False) == known
                with pytest.raises(AccessUnavailable):
                    await router._client_entry("a-session-held-elsewhere", "alpha")
                with pytest.raises(AccessUnavailable):
                    await guard.off_loop(guard.audit, known, "style", "a-session", {})
            ticker.cancel()
            return ticks

        ticks = asyncio.run(asyncio.wait_for(while_hung(), RETURNS_WITHIN_S))
        assert ticks >= TICKS_WHILE_WAITING, ticks
        guard.stop()
        store.close()
    finally:
        postgres.stop()
