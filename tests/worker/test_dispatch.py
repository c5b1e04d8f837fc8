"""Requests as bytes to the session table (worker/dispatch.py): a monitor's view refused at once
for an unknown session or a query that is not one, before anything is rendered."""

from __future__ import annotations

import pytest

from camdirector.errors import DirectorError
from camdirector.infra.channels import ViewQuery
from camdirector.server_settings import ServerSettings
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.table import SessionTable
from tests.service.wire_client import two_target_request


def test_a_view_of_an_unknown_session_or_with_a_garbled_query_is_refused_at_once(tmp_path):
    table = SessionTable(ServerSettings(data_dir=str(tmp_path), checkpoint_store="off"))
    requests = Dispatcher(table)
    never_called = []
    with pytest.raises(DirectorError) as refused:
        requests.view("nobody", ViewQuery().to_json(), lambda *answer: never_called.append(answer))
    assert refused.value.code.name == "NOT_FOUND"
    table.create("s", two_target_request(seed=2))
    for payload in (b"\xff", ViewQuery().to_json().replace(b"program", b"sideways")):
        with pytest.raises(DirectorError) as refused:
            requests.view("s", payload, lambda *answer: never_called.append(answer))
        assert refused.value.code.name == "INVALID_ARGUMENT"
    assert not never_called and table.monitor is None  # no render process started for them
    table.close_all()
