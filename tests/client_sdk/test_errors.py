"""camdirector_client.errors: one error type, status codes mapped by value."""

from __future__ import annotations

import pickle

import grpc
import pytest

from camdirector_client import DirectorError
from camdirector_client.errors import status_code_from_value


@pytest.mark.parametrize("code", list(grpc.StatusCode))
def test_zmq_status_codes_map_by_value(code):
    assert status_code_from_value(code.value[0]) is code
    error = DirectorError.from_zmq_reply(str(code.value[0]).encode(), b"why")
    assert (error.code, error.message) == (code, "why")


def test_unknown_and_malformed_zmq_codes():
    error = DirectorError.from_zmq_reply(b"99", b"odd")
    assert error.code is grpc.StatusCode.UNKNOWN
    assert error.message == "status 99: odd"
    error = DirectorError.from_zmq_reply(b"NOT_FOUND", "caf\xe9".encode())
    assert error.code is grpc.StatusCode.INTERNAL
    assert "malformed status frame" in error.message and "caf\xe9" in error.message


def test_undecodable_message_is_replaced_not_raised():
    assert DirectorError.from_zmq_reply(b"5", b"\xff\xfe").code is grpc.StatusCode.NOT_FOUND


def test_str_repr_and_pickle():
    error = DirectorError(grpc.StatusCode.NOT_FOUND, "unknown session 's9'")
    assert str(error) == "NOT_FOUND: unknown session 's9'"
    assert repr(error) == "DirectorError(grpc.StatusCode.NOT_FOUND, \"unknown session 's9'\")"
    copy = pickle.loads(pickle.dumps(error))
    assert (copy.code, copy.message) == (error.code, error.message)


def test_from_rpc_error():
    class FakeRpcError(grpc.RpcError):
        def code(self):
            return grpc.StatusCode.RESOURCE_EXHAUSTED

        def details(self):
            return "too many sessions"

    error = DirectorError.from_rpc_error(FakeRpcError())
    assert (error.code, error.message) == (grpc.StatusCode.RESOURCE_EXHAUSTED, "too many sessions")
    bare = DirectorError.from_rpc_error(grpc.RpcError("bare"))
    assert bare.code is grpc.StatusCode.UNKNOWN
