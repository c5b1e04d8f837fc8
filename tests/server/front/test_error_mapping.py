"""An unexpected exception reaches a client as INTERNAL on every transport (gRPC would say
UNKNOWN on its own), with the details in the server's log; and the front reads a request's
session id from field 1 without parsing the rest."""
from __future__ import annotations

import asyncio
import logging

import grpc
import pytest

from camdirector.server.errors import DirectorError
from camdirector.server.front.grpc_service import DirectorGrpc
from camdirector.server.front.router import session_id_of
from camdirector.v1 import director_pb2 as pb


class _Aborted(Exception):
    pass


class _Context:
    """Only what DirectorGrpc calls on a grpc.aio.ServicerContext: abort."""

    def __init__(self):
        self.status = None

    async def abort(self, code, details):
        self.status = (code, details)
        raise _Aborted()


class _Labels:
    def labels(self, *names):
        return self

    def inc(self):
        pass

    def observe(self, value):
        pass


class _Router:
    metrics = type("Metrics", (), {"errors": _Labels(), "request": _Labels()})()


def test_an_unexpected_exception_is_internal_over_grpc_and_logged(caplog):
    service, context = DirectorGrpc(_Router()), _Context()

    async def broken(payload):
        raise KeyError("a bug")

    with caplog.at_level(logging.ERROR, logger="camdirector.grpc"), pytest.raises(_Aborted):
        asyncio.run(service._unary("UpdateStyle", broken, b"", context))
    code, details = context.status
    assert code == grpc.StatusCode.INTERNAL and "KeyError" in details
    assert "UpdateStyle failed" in caplog.text and "a bug" in caplog.text


def test_a_director_error_keeps_its_status_over_grpc():
    service, context = DirectorGrpc(_Router()), _Context()

    async def refused(payload):
        raise DirectorError(grpc.StatusCode.NOT_FOUND, "no such thing")

    with pytest.raises(_Aborted):
        asyncio.run(service._unary("Frame", refused, b"", context))
    assert context.status == (grpc.StatusCode.NOT_FOUND, "no such thing")


@pytest.mark.parametrize("message", [
    pb.FrameUpdate(session_id="s-1", frame=7, time_s=0.5, packed_ids=["a", "b"], packed_transforms=[0.0] * 20),
    pb.FrameUpdate(frame=9, session_id="ünï"),  # other fields first, non-ASCII id
    pb.UpdateStyleRequest(session_id="s-2", style=pb.Style(visibility=pb.RAYCAST)),
    pb.CloseSessionRequest(session_id="s-3"),
    pb.TakeShotRequest(session_id="s-4", subject_ids=["p1"], release=True),
])
def test_field_one_is_the_parsed_session_id(message):
    assert session_id_of(type(message), message.SerializeToString()) == message.session_id


@pytest.mark.parametrize("payload, contains", [
    (b"", "session_id is empty"),
    (pb.FrameUpdate(frame=3).SerializeToString(), "session_id is empty"),
    (b"\x0a\x05ab", "not a serialized"),        # a length past the end
    (b"\xff\xff\xff", "not a serialized"),      # a truncated varint
    (b"\x0a\x02\xff\xfe", "not a serialized"),  # not UTF-8
])
def test_an_unreadable_session_id_is_invalid(payload, contains):
    with pytest.raises(DirectorError) as err:
        session_id_of(pb.FrameUpdate, payload)
    assert err.value.code == grpc.StatusCode.INVALID_ARGUMENT and contains in err.value.message
