"""gRPC transport (grpc.aio): the Director service, health checking and reflection.

Handlers take and return serialized bytes: the front only reads the session id to route, and the
worker that holds the session parses the rest, so nothing is parsed twice in full.
Every call carries `authorization: Bearer KEY` metadata (access/guard.py): UNAUTHENTICATED without
a valid key, PERMISSION_DENIED for a role without the verb, NOT_FOUND for another tenant's session.
The health service stays open: balancers probe it without a key.
Every Director call's initial metadata says which server answers: `camdirector-version` (the
release) and `camdirector-protocol` (version.py), which the SDKs compare with their own.
A bad frame ends its stream with a status; the session itself stays and a new stream may resume it.
"""

from __future__ import annotations

import logging
import time

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection

from camdirector.access.guard import Guard
from camdirector.errors import DirectorError, invalid
from camdirector.front.router import SessionRouter, named_session, session_id_of
from camdirector.front.session_calls import RPCS, SessionCalls, check_client_protocol
from camdirector.v1 import director_pb2 as pb
from camdirector.version import PROTOCOL, VERSION

log = logging.getLogger("camdirector.grpc")
SERVICE = "camdirector.v1.Director"
SERVER_METADATA = (("camdirector-version", VERSION), ("camdirector-protocol", str(PROTOCOL)))
TRANSPORT = "grpc"


def _metadata(context: grpc.aio.ServicerContext, name: str) -> str | None:
    for key, value in context.invocation_metadata() or ():
        if key == name:
            return value
    return None


def _authorization(context: grpc.aio.ServicerContext) -> str | None:
    return _metadata(context, "authorization")


def check_protocol_metadata(sent: str | None) -> None:
    """FAILED_PRECONDITION for a client newer than this server by its `camdirector-protocol`
    metadata (none: a client from before the header); its request's client_protocol is checked
    the same on every transport (session_calls.py)."""
    if sent is None:
        return
    if not (sent.isascii() and sent.isdigit()):
        raise invalid(f"camdirector-protocol metadata {sent[:20]!r} is not a whole number")
    check_client_protocol(int(sent))


class DirectorGrpc:
    def __init__(self, router: SessionRouter, guard: Guard):
        self.router = router
        self.guard = guard
        self.calls = SessionCalls(router, guard, TRANSPORT)
        self.metrics = router.metrics

    # grpc annotates ServicerContext.abort as returning, but it always raises: no return after it
    async def _unary(self, rpc: str, payload: bytes, context: grpc.aio.ServicerContext) -> bytes:  # type: ignore[return]
        """The RPC's call (session_calls.py) for a caller whose key allows its verb."""
        t0 = time.perf_counter()
        try:
            await context.send_initial_metadata(SERVER_METADATA)
            need = RPCS[rpc]
            identity = await self.guard.authorize_async(_authorization(context), need.verb, fresh=need.fresh)
            if rpc == "CreateSession":
                check_protocol_metadata(_metadata(context, "camdirector-protocol"))
            return await self.calls.by_rpc[rpc](payload, identity)
        except Exception as exc:  # a bug: INTERNAL, as on ZeroMQ, never grpc's UNKNOWN
            await self._abort(self.guard.refusal(exc, rpc, lambda: named_session(rpc, payload), log), context)
        finally:
            self.metrics.labelled(self.metrics.request, TRANSPORT, rpc).observe(time.perf_counter() - t0)

    async def _abort(self, error: DirectorError, context: grpc.aio.ServicerContext) -> None:
        self.metrics.labelled(self.metrics.errors, TRANSPORT, error.code.name).inc()
        await context.abort(error.code, error.message)

    def _unary_handler(self, rpc: str) -> grpc.RpcMethodHandler:
        async def handle(payload: bytes, context: grpc.aio.ServicerContext) -> bytes:
            return await self._unary(rpc, payload, context)

        return grpc.unary_unary_rpc_method_handler(handle)  # bytes in, bytes out

    async def stream_frames(self, request_iterator, context: grpc.aio.ServicerContext):
        session_id = None
        try:
            await context.send_initial_metadata(SERVER_METADATA)
            need = RPCS["StreamFrames"]
            identity = await self.guard.authorize_async(_authorization(context), need.verb, fresh=need.fresh)
            async for payload in request_iterator:
                t0 = time.perf_counter()
                self.guard.still_valid(identity)
                frame_session = session_id_of(pb.FrameUpdate, payload)
                if session_id is None:
                    await self.router.stream_opened(frame_session, identity.tenant)
                    session_id = frame_session
                elif frame_session != session_id:
                    raise DirectorError(
                        grpc.StatusCode.INVALID_ARGUMENT,
                        f"a stream carries one session: got {frame_session!r} on the stream of {session_id!r}",
                    )
                reply = await self.router.frame(payload, session_id, TRANSPORT, identity.tenant)
                self.metrics.labelled(self.metrics.request, TRANSPORT, "StreamFrames").observe(time.perf_counter() - t0)
                yield reply
        except Exception as exc:  # AccessUnavailable: a session of this tenant not held here, its owner unread
            await self._abort(self.guard.refusal(exc, "StreamFrames", lambda: session_id, log), context)
        finally:
            if session_id is not None:
                self.router.stream_closed(session_id)

    def handler(self) -> grpc.GenericRpcHandler:
        handlers = {rpc: self._unary_handler(rpc) for rpc in RPCS if rpc != "StreamFrames"}
        handlers["StreamFrames"] = grpc.stream_stream_rpc_method_handler(self.stream_frames)
        return grpc.method_handlers_generic_handler(SERVICE, handlers)


async def start_grpc(
    router: SessionRouter, address: str, guard: Guard, tls: grpc.ServerCredentials | None = None
) -> tuple[grpc.aio.Server, str]:
    """Starts the server (over TLS with `tls`); returns it and the bound HOST:PORT (port 0 picks a
    free one)."""
    limit = router.settings.max_message_bytes
    server = grpc.aio.server(
        options=[
            ("grpc.max_receive_message_length", limit),
            ("grpc.max_send_message_length", limit),
            ("grpc.so_reuseport", 0),
        ]
    )
    server.add_generic_rpc_handlers((DirectorGrpc(router, guard).handler(),))
    health_servicer = health.aio.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, server)
    reflection.enable_server_reflection(
        (pb.DESCRIPTOR.services_by_name["Director"].full_name, health.SERVICE_NAME, reflection.SERVICE_NAME), server
    )
    host, _, _ = address.rpartition(":")
    port = server.add_secure_port(address, tls) if tls is not None else server.add_insecure_port(address)
    if port == 0:
        raise OSError(f"cannot bind gRPC to {address}")
    await server.start()
    for service in ("", SERVICE):
        await health_servicer.set(service, health_pb2.HealthCheckResponse.SERVING)
    return server, f"{host}:{port}"
