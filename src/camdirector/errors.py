"""The one error type the edges (servicers, ZeroMQ handler, routes) turn into a status."""

from __future__ import annotations

import logging

import grpc

_STATUS_CODES = {code.value[0]: code for code in grpc.StatusCode}


def status_code(number: int) -> grpc.StatusCode:
    """The gRPC status code of its number (as a worker's reply or the gRPC edge gives it); UNKNOWN
    for a number that is none."""
    return _STATUS_CODES.get(number, grpc.StatusCode.UNKNOWN)


class DirectorError(Exception):
    """An error answered to the client: a gRPC status code and a message for a person.

    Raised only where input enters (wire decoding, session table, transports); inside the frame
    loop the pipeline degrades and flags instead.
    """

    def __init__(self, code: grpc.StatusCode, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


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


def data_loss(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.DATA_LOSS, message)


def internal(exc: Exception, what: str, session_id: str | None, logger: logging.Logger) -> DirectorError:
    """An unexpected failure while handling one request (a bug, a full disk), answered the same
    way wherever it is caught (a worker's session table, the gRPC and ZeroMQ transports): INTERNAL
    with a short message naming the exception's type, the request and the session; the traceback
    goes to the server's log with the session id, never to the client. `what`: the request
    ("Frame", "CreateSession"); `session_id`: the session it names, None when it names none."""
    where = f"session {session_id}" if session_id else "no session"
    logger.error("%s of %s failed", what, where, exc_info=exc)
    return DirectorError(
        grpc.StatusCode.INTERNAL, f"internal error ({type(exc).__name__}) in {what} of {where}; the server's log has the details"
    )
