"""The Director service's calls for one authenticated caller, the same over gRPC and ZeroMQ: which
verb each RPC needs (access/roles.py), the caller's tenant passed to the router, and the audit
trail of style changes, takes and releases.

    RPC            verb             key checked against
    CreateSession  session.create   the records database
    Frame          session.stream   this node's cache (access/guard.py)
    StreamFrames   session.stream   this node's cache, on every message
    UpdateStyle    session.style    the records database
    TakeShot       session.take     the records database
    CloseSession   session.close    the records database

The records database is read and written off the event loop (Guard.authorize_async, off_loop): a
hung one delays these calls, never another session's frames.

CreateSession is refused FAILED_PRECONDITION, on every transport, when its client_protocol says
the client speaks a newer protocol than this server (version.py; docs/protocol.md, "Versions").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from google.protobuf import json_format

from camdirector.access.guard import Guard, Identity
from camdirector.access.roles import Verb
from camdirector.errors import precondition
from camdirector.front.router import SessionRouter, session_id_of, varint_at, wire_fields
from camdirector.v1 import director_pb2 as pb
from camdirector.version import PROTOCOL, VERSION


@dataclass(frozen=True)
class Rpc:
    verb: Verb
    fresh: bool  # read the key from the records database (False: this node's cache)


RPCS = {
    "CreateSession": Rpc(Verb.SESSION_CREATE, True),
    "Frame": Rpc(Verb.SESSION_STREAM, False),
    "StreamFrames": Rpc(Verb.SESSION_STREAM, False),
    "UpdateStyle": Rpc(Verb.SESSION_STYLE, True),
    "TakeShot": Rpc(Verb.SESSION_TAKE, True),
    "CloseSession": Rpc(Verb.SESSION_CLOSE, True),
}


_CLIENT_PROTOCOL_FIELD = pb.CreateSessionRequest.DESCRIPTOR.fields_by_name["client_protocol"].number


def check_client_protocol(protocol: int) -> None:
    """FAILED_PRECONDITION for a client that speaks a newer protocol than this server's PROTOCOL,
    said in CreateSessionRequest.client_protocol or gRPC's `camdirector-protocol` metadata."""
    if protocol > PROTOCOL:
        raise precondition(
            f"this client speaks camdirector protocol {protocol}, this server (camdirector {VERSION}) "
            f"protocol {PROTOCOL}: upgrade the server, or use a client of release {VERSION}"
        )


def client_protocol_of(payload: bytes) -> int:
    """CreateSessionRequest.client_protocol of a serialized request, read from the wire format
    without parsing the scene (router.wire_fields); the last occurrence counts, as when protobuf
    parses it. 0 (not said) when absent, or when the payload is unreadable: the worker refuses that."""
    protocol = 0
    try:
        for field_number, wire_type, start, _ in wire_fields(payload):
            if field_number == _CLIENT_PROTOCOL_FIELD and wire_type == 0:
                protocol = varint_at(payload, start)[0] & 0xFFFFFFFF  # uint32: protobuf keeps the low 32 bits
    except ValueError:
        return 0
    return protocol


def _as_dict(message) -> dict:
    return json_format.MessageToDict(message, preserving_proto_field_name=True)


class SessionCalls:
    """Each method takes the serialized request and the caller, and returns the serialized answer."""

    def __init__(self, router: SessionRouter, guard: Guard, transport: str) -> None:
        self.router = router
        self.guard = guard
        self.transport = transport
        self.by_rpc = {
            "CreateSession": self.create,
            "Frame": self.frame,
            "UpdateStyle": self.update_style,
            "TakeShot": self.take_shot,
            "CloseSession": self.close,
        }

    async def create(self, payload: bytes, identity: Identity) -> bytes:
        check_client_protocol(client_protocol_of(payload))
        return await self.router.create(payload, self.transport, identity.tenant)

    async def frame(self, payload: bytes, identity: Identity) -> bytes:
        return await self.router.frame(payload, session_id_of(pb.FrameUpdate, payload), self.transport, identity.tenant)

    async def update_style(self, payload: bytes, identity: Identity) -> bytes:
        reply = await self.router.update_style(payload, identity.tenant)
        request = pb.UpdateStyleRequest.FromString(payload)  # the worker took it: it parses
        detail = {"style": _as_dict(request.style), "via": self.transport}
        await self.guard.off_loop(self.guard.audit, identity, "style", request.session_id, detail)
        return reply

    async def take_shot(self, payload: bytes, identity: Identity) -> bytes:
        reply = await self.router.take_shot(payload, identity.tenant)
        request = pb.TakeShotRequest.FromString(payload)
        detail: dict[str, Any] = {"via": self.transport}  # JSON, into the audit trail
        if not request.release:
            detail.update(subject_ids=list(request.subject_ids), kind=pb.ShotKind.Name(request.kind))
        action = "release" if request.release else "take"
        await self.guard.off_loop(self.guard.audit, identity, action, request.session_id, detail)
        return reply

    async def close(self, payload: bytes, identity: Identity) -> bytes:
        return await self.router.close(payload, identity.tenant)
