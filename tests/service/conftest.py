"""The `raw` fixture: the same tests over both transports."""

from __future__ import annotations

import pytest

from tests.service.wire_client import GrpcRaw, ZmqRaw


@pytest.fixture(params=["grpc", "zmq"])
def raw(request, server):
    """The same tests over both transports."""
    client = GrpcRaw(server.grpc) if request.param == "grpc" else ZmqRaw(server.zmq)
    client.transport = request.param
    yield client
    client.close()
