"""The one error type of the SDK, raised alike by the gRPC and ZeroMQ transports.

Both transports carry a gRPC status code and a message: gRPC natively, ZeroMQ as the first
reply frame (the code in ASCII decimal, ``b"0"`` meaning OK) followed by a UTF-8 message. Either
way the caller sees a :class:`DirectorError` whose ``code`` is a :class:`grpc.StatusCode`.
"""

from __future__ import annotations

import grpc

__all__ = ["DirectorError", "status_code_from_value"]

# grpc.StatusCode values are (int, str) pairs; the wire carries only the int.
_CODE_BY_VALUE: dict[int, grpc.StatusCode] = {code.value[0]: code for code in grpc.StatusCode}


class DirectorError(Exception):
    """A call to the director failed.

    Attributes
    ----------
    code : grpc.StatusCode
        The status the server (or the client, for a timeout or a broken reply) answered,
        e.g. ``NOT_FOUND`` for an unknown session, ``INVALID_ARGUMENT`` for bad input,
        ``DEADLINE_EXCEEDED`` when no reply came within the client's timeout.
    message : str
        The server's explanation, meant for humans.
    """

    def __init__(self, code: grpc.StatusCode, message: str) -> None:
        super().__init__(code, message)
        self.code = code
        self.message = message

    def __str__(self) -> str:
        return f"{self.code.name}: {self.message}"

    def __repr__(self) -> str:
        return f"DirectorError(grpc.StatusCode.{self.code.name}, {self.message!r})"

    @classmethod
    def from_rpc_error(cls, error: grpc.RpcError) -> DirectorError:
        """Wraps an error raised by a grpc (sync or aio) call."""
        code = error.code() if hasattr(error, "code") else None
        details = error.details() if hasattr(error, "details") else None
        if not isinstance(code, grpc.StatusCode):
            code = grpc.StatusCode.UNKNOWN
        return cls(code, details or str(error))

    @classmethod
    def from_zmq_reply(cls, code_frame: bytes, payload: bytes) -> DirectorError:
        """Wraps a ZeroMQ error reply: ``code_frame`` is the ASCII decimal status code."""
        message = payload.decode("utf-8", errors="replace")
        try:
            value = int(code_frame)
        except ValueError:
            return cls(grpc.StatusCode.INTERNAL, f"malformed status frame {code_frame[:32]!r}: {message}")
        code = status_code_from_value(value)
        if code.value[0] != value:
            message = f"status {value}: {message}"
        return cls(code, message)


def status_code_from_value(value: int) -> grpc.StatusCode:
    """The :class:`grpc.StatusCode` whose numeric value is ``value``; ``UNKNOWN`` if none is."""
    return _CODE_BY_VALUE.get(value, grpc.StatusCode.UNKNOWN)
