"""gRPC transport (grpc.aio): the Director service, health checking and reflection.

Handlers take and return serialized bytes: the front only reads the session id to route, and the
worker that holds the session parses the rest, so nothing is parsed twice in full.
A bad frame ends its stream with a status; the session itself stays and a new stream may resume it.
"""
from __future__ import annotations

import logging
import time

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection

from camdirector.errors import DirectorError, internal
from camdirector.front.router import SessionRouter, named_session, session_id_of
from camdirector.v1 import director_pb2 as pb

log = logging.getLogger("camdirector.grpc")
SERVICE = "camdirector.v1.Director"
TRANSPORT = "grpc"


class DirectorGrpc:
    def __init__(self, router: SessionRouter):
        self.router = router
        self.metrics = router.metrics

    async def _unary(self, rpc: str, call, payload: bytes, context: grpc.aio.ServicerContext) -> bytes:
        t0 = time.perf_counter()
        try:
            return await call(payload)
        except DirectorError as exc:
            self.metrics.labelled(self.metrics.errors, TRANSPORT, exc.code.name).inc()
            await context.abort(exc.code, exc.message)
        except Exception as exc:  # a bug: INTERNAL, as on ZeroMQ, never grpc's UNKNOWN
            await self._abort_internal(rpc, exc, named_session(rpc, payload), context)
        finally:
            self.metrics.labelled(self.metrics.request, TRANSPORT, rpc).observe(time.perf_counter() - t0)

    async def _abort_internal(self, rpc: str, exc: Exception, session_id: str | None,
                              context: grpc.aio.ServicerContext) -> None:
        error = internal(exc, rpc, session_id, log)
        self.metrics.labelled(self.metrics.errors, TRANSPORT, error.code.name).inc()
        await context.abort(error.code, error.message)

    async def create_session(self, payload, context):
        return await self._unary("CreateSession", lambda p: self.router.create(p, TRANSPORT), payload, context)

    async def update_style(self, payload, context):
        return await self._unary("UpdateStyle", self.router.update_style, payload, context)

    async def take_shot(self, payload, context):
        return await self._unary("TakeShot", self.router.take_shot, payload, context)

    async def close_session(self, payload, context):
        return await self._unary("CloseSession", self.router.close, payload, context)

    async def frame(self, payload, context):
        async def call(p):
            return await self.router.frame(p, session_id_of(pb.FrameUpdate, p), TRANSPORT)
        return await self._unary("Frame", call, payload, context)

    async def stream_frames(self, request_iterator, context: grpc.aio.ServicerContext):
        session_id = None
        try:
            async for payload in request_iterator:
                t0 = time.perf_counter()
                frame_session = session_id_of(pb.FrameUpdate, payload)
                if session_id is None:
                    self.router.stream_opened(frame_session)
                    session_id = frame_session
                elif frame_session != session_id:
                    raise DirectorError(grpc.StatusCode.INVALID_ARGUMENT,
                                        f"a stream carries one session: got {frame_session!r} on the stream of {session_id!r}")
                reply = await self.router.frame(payload, session_id, TRANSPORT)
                self.metrics.labelled(self.metrics.request, TRANSPORT, "StreamFrames").observe(time.perf_counter() - t0)
                yield reply
        except DirectorError as exc:
            self.metrics.labelled(self.metrics.errors, TRANSPORT, exc.code.name).inc()
            await context.abort(exc.code, exc.message)
        except Exception as exc:
            await self._abort_internal("StreamFrames", exc, session_id, context)
        finally:
            if session_id is not None:
                self.router.stream_closed(session_id)

    def handler(self) -> grpc.GenericRpcHandler:
        unary = lambda fn: grpc.unary_unary_rpc_method_handler(fn)  # noqa: E731 (bytes in, bytes out)
        return grpc.method_handlers_generic_handler(SERVICE, {
            "CreateSession": unary(self.create_session),
            "UpdateStyle": unary(self.update_style),
            "TakeShot": unary(self.take_shot),
            "CloseSession": unary(self.close_session),
            "Frame": unary(self.frame),
            "StreamFrames": grpc.stream_stream_rpc_method_handler(self.stream_frames),
        })


async def start_grpc(router: SessionRouter, address: str) -> tuple[grpc.aio.Server, str]:
    """Starts the server; returns it and the bound HOST:PORT (port 0 picks a free one)."""
    limit = router.settings.max_message_bytes
    server = grpc.aio.server(options=[
        ("grpc.max_receive_message_length", limit),
        ("grpc.max_send_message_length", limit),
        ("grpc.so_reuseport", 0),
    ])
    server.add_generic_rpc_handlers((DirectorGrpc(router).handler(),))
    health_servicer = health.aio.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, server)
    reflection.enable_server_reflection(
        (pb.DESCRIPTOR.services_by_name["Director"].full_name, health.SERVICE_NAME, reflection.SERVICE_NAME), server)
    host, _, _ = address.rpartition(":")
    port = server.add_insecure_port(address)
    if port == 0:
        raise OSError(f"cannot bind gRPC to {address}")
    await server.start()
    for service in ("", SERVICE):
        await health_servicer.set(service, health_pb2.HealthCheckResponse.SERVING)
    return server, f"{host}:{port}"
