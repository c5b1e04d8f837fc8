"""`camdirector serve`: the front process with its transports, and the worker pool."""
from __future__ import annotations

import asyncio
import json
import logging
import signal
import socket
import sys
from pathlib import Path

import uvicorn

from camdirector.front.grpc_service import start_grpc
from camdirector.front.http.app import build_app
from camdirector.front.http.routes.levels import install_level_routes
from camdirector.front.http.routes.overview import install_overview_routes
from camdirector.front.job_runner import open_jobs
from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionRouter
from camdirector.front.zmq_service import ZmqTransport
from camdirector.jobs import JobsUnavailable, service_kinds
from camdirector.server_settings import ServerSettings
from camdirector.worker.checkpoint_stores import CheckpointError, open_store

log = logging.getLogger("camdirector.serve")


def _bind_http(address: str) -> socket.socket:
    host, _, port = address.rpartition(":")
    # IPPROTO_TCP spelled out: asyncio turns Nagle off (TCP_NODELAY) on accepted connections only
    # when the listening socket says it is TCP; with proto 0 every answer after the first on a
    # kept-alive connection waited about 40 ms for the client's delayed ACK.
    sock = socket.socket(socket.AF_INET6 if ":" in host.strip("[]") else socket.AF_INET, socket.SOCK_STREAM,
                         socket.IPPROTO_TCP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host.strip("[]"), int(port)))
    sock.listen(2048)  # before the ready line: connections queue until uvicorn accepts them
    return sock


async def serve(settings: ServerSettings, stop: asyncio.Event | None = None) -> None:
    """Runs until `stop` is set or SIGINT/SIGTERM arrives. Prints one JSON line when ready:
    {"event": "ready", "grpc": ..., "zmq": ..., "http": ...} with the bound addresses."""
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    metrics = Metrics()
    router = SessionRouter(settings, metrics)
    await router.start()
    bound: dict[str, str] = {}
    grpc_server = zmq_transport = http_server = http_task = jobs = None
    try:
        if settings.grpc_addr:
            grpc_server, bound["grpc"] = await start_grpc(router, settings.grpc_addr)
        if settings.zmq_addr:
            zmq_transport = ZmqTransport(router, settings.zmq_addr)
            zmq_transport.start()
            bound["zmq"] = zmq_transport.address
        if settings.http_addr:
            sock = _bind_http(settings.http_addr)
            bound["http"] = "{}:{}".format(*sock.getsockname()[:2])
            app = build_app(router, bound)
            jobs = open_jobs(Path(settings.data_dir), service_kinds(), settings.job_settings())
            install_overview_routes(app, jobs, settings.job_settings())
            install_level_routes(app, jobs, Path(settings.data_dir), settings.job_settings())
            jobs.start()  # queued and interrupted jobs from before a restart run again
            # A live view left open past shutdown is cut after this long (the hub ends its own first).
            config = uvicorn.Config(app, log_level="warning", lifespan="off", timeout_graceful_shutdown=3)
            http_server = uvicorn.Server(config)
            http_server.install_signal_handlers = lambda: None  # ours above
            http_task = asyncio.create_task(http_server.serve(sockets=[sock]))
        print(json.dumps({"event": "ready", **bound, "workers": settings.workers}), flush=True)
        await stop.wait()
    finally:
        log.info("stopping")
        if http_server is not None:
            app.state.views.close()
            http_server.should_exit = True
            await http_task
        if jobs is not None:
            jobs.close()  # running jobs go back to the queue
        if grpc_server is not None:
            await grpc_server.stop(grace=1.0)
        if zmq_transport is not None:
            await zmq_transport.stop()
        await router.stop()


def run(settings: ServerSettings) -> int:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:  # a node whose checkpoints have nowhere to go refuses to start, rather than lose sessions later
        store = open_store(settings.checkpoint_store, settings.data_dir, settings.checkpoint_keep_s, check=True)
    except CheckpointError as exc:
        print(f"camdirector serve: {exc}", file=sys.stderr)
        return 2
    if store is not None:
        store.close()
    try:
        asyncio.run(serve(settings))
    except JobsUnavailable as exc:  # the job store or queue is down at start
        print(f"camdirector serve: {exc}", file=sys.stderr)
        return 2
    return 0
