"""The one error type the edges (servicers, ZeroMQ handler, routes) turn into a status."""
from __future__ import annotations

import grpc


class DirectorError(Exception):
    """An error answered to the client: a gRPC status code and a message for a person.

    Raised only where input enters (wire decoding, session table, transports); inside the frame
    loop the pipeline degrades and flags instead.
    """

    def __init__(self, code: grpc.StatusCode, message: str):
        super().__init__(message)
        self.code = code
        self.message = message

    def __reduce__(self):  # crosses process boundaries (worker -> front) by pickling
        return (DirectorError, (self.code, self.message))


def invalid(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.INVALID_ARGUMENT, message)


def not_found(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.NOT_FOUND, message)


def exhausted(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.RESOURCE_EXHAUSTED, message)


def precondition(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.FAILED_PRECONDITION, message)


def unimplemented(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.UNIMPLEMENTED, message)


def unavailable(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.UNAVAILABLE, message)


def internal(exc: Exception) -> DirectorError:
    """An unexpected failure while handling one request, reported without losing the server."""
    return DirectorError(grpc.StatusCode.INTERNAL, f"internal error: {type(exc).__name__}: {exc}")
