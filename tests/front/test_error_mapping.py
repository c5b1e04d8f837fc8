"""An unexpected exception reaches a client as INTERNAL on every transport (gRPC would say
UNKNOWN on its own), with the details in the server's log; and the front reads a request's
session id from field 1 without parsing the rest."""

from __future__ import annotations

import asyncio
import logging

import grpc
import pytest
import zmq
import zmq.asyncio

from camdirector.access.guard import Guard
from camdirector.errors import DirectorError
from camdirector.front.grpc_service import DirectorGrpc
from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionRouter, session_id_of
from camdirector.front.zmq_service import ZmqTransport
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb


class _Aborted(Exception):
    pass


class _Context:
    """Only what DirectorGrpc calls on a grpc.aio.ServicerContext: abort, invocation_metadata."""

    def __init__(self):
        self.status = None

    def invocation_metadata(self):
        return ()

    async def send_initial_metadata(self, metadata):
        pass

    async def abort(self, code, details):
        self.status = (code, details)
        raise _Aborted()


class _Router:
    """What DirectorGrpc reads from a SessionRouter besides the calls a test passes in."""

    def __init__(self):
        self.metrics = Metrics()


def _service(rpc: str, call) -> DirectorGrpc:
    """A DirectorGrpc without authentication whose `rpc` is `call(payload, identity)`."""
    service = DirectorGrpc(_Router(), Guard(None))
    service.calls.by_rpc[rpc] = call
    return service


def test_an_unexpected_exception_is_internal_over_grpc_and_logged(caplog):
    async def broken(payload, identity):
        raise KeyError("a bug")

    service, context = _service("UpdateStyle", broken), _Context()
    with caplog.at_level(logging.ERROR, logger="camdirector.grpc"), pytest.raises(_Aborted):
        asyncio.run(service._unary("UpdateStyle", b"", context))
    code, details = context.status
    assert code == grpc.StatusCode.INTERNAL and "KeyError" in details and "a bug" not in details
    assert "UpdateStyle of no session failed" in caplog.text and "a bug" in caplog.text  # the traceback


def test_an_unexpected_exception_is_internal_over_zeromq_and_logged_with_its_session(caplog, tmp_path):
    """The same mapping on the ZeroMQ socket: a real ROUTER socket and DEALER client, a real
    router (sessions inline) whose Frame handler is broken."""

    async def exchange() -> list[bytes]:
        router = SessionRouter(ServerSettings(workers=0, data_dir=str(tmp_path)), Metrics())
        transport = ZmqTransport(router, "tcp://127.0.0.1:*", router.guard)

        async def broken(payload, identity):
            raise KeyError("a bug")

        transport._handlers[b"Frame"] = (transport._handlers[b"Frame"][0], broken)
        transport.start()
        client = zmq.asyncio.Context.instance().socket(zmq.DEALER)
        client.setsockopt(zmq.LINGER, 0)
        client.connect(transport.address)
        try:
            await client.send_multipart([b"Frame", pb.FrameUpdate(session_id="s-9", frame=1).SerializeToString()])
            reply = await asyncio.wait_for(client.recv_multipart(), 10.0)
        finally:
            client.close()
            await transport.stop()
        assert (
            router.metrics.registry.get_sample_value("camdirector_errors_total", {"transport": "zmq", "code": "INTERNAL"}) == 1.0
        )
        return reply

    with caplog.at_level(logging.ERROR, logger="camdirector.zmq"):
        code, message = asyncio.run(exchange())
    assert code == str(grpc.StatusCode.INTERNAL.value[0]).encode()
    assert b"KeyError" in message and b"session s-9" in message and b"a bug" not in message
    assert "Frame of session s-9 failed" in caplog.text and "a bug" in caplog.text


def test_a_director_error_keeps_its_status_over_grpc():
    async def refused(payload, identity):
        raise DirectorError(grpc.StatusCode.NOT_FOUND, "no such thing")

    service, context = _service("Frame", refused), _Context()
    with pytest.raises(_Aborted):
        asyncio.run(service._unary("Frame", b"", context))
    assert context.status == (grpc.StatusCode.NOT_FOUND, "no such thing")


@pytest.mark.parametrize(
    "message",
    [
        pb.FrameUpdate(session_id="s-1", frame=7, time_s=0.5, packed_ids=["a", "b"], packed_transforms=[0.0] * 20),
        pb.FrameUpdate(frame=9, session_id="ünï"),  # other fields first, non-ASCII id
        pb.UpdateStyleRequest(session_id="s-2", style=pb.Style(visibility=pb.RAYCAST)),
        pb.CloseSessionRequest(session_id="s-3"),
        pb.TakeShotRequest(session_id="s-4", subject_ids=["p1"], release=True),
    ],
)
def test_field_one_is_the_parsed_session_id(message):
    assert session_id_of(type(message), message.SerializeToString()) == message.session_id


@pytest.mark.parametrize(
    "payload, contains",
    [
        (b"", "session_id is empty"),
        (pb.FrameUpdate(frame=3).SerializeToString(), "session_id is empty"),
        (b"\x0a\x05ab", "not a serialized"),  # a length past the end
        (b"\xff\xff\xff", "not a serialized"),  # a truncated varint
        (b"\x0a\x02\xff\xfe", "not a serialized"),  # not UTF-8
    ],
)
def test_an_unreadable_session_id_is_invalid(payload, contains):
    with pytest.raises(DirectorError) as err:
        session_id_of(pb.FrameUpdate, payload)
    assert err.value.code == grpc.StatusCode.INVALID_ARGUMENT and contains in err.value.message
