"""`camdirector serve`: the front process with its transports, and the worker pool."""

from __future__ import annotations

import asyncio
import json
import logging
import signal
import socket
import ssl
import sys
from pathlib import Path

import grpc
import uvicorn

from camdirector.access.guard import Guard
from camdirector.access.keys import AccessUnavailable, ensure_admin_key, open_access_store
from camdirector.front.edge import EdgeFront
from camdirector.front.grpc_service import start_grpc
from camdirector.front.http.app import build_app
from camdirector.front.http.routes.levels import install_level_routes
from camdirector.front.http.routes.overview import install_overview_routes
from camdirector.front.job_runner import open_jobs
from camdirector.front.live_check import LiveCheck
from camdirector.front.loop_watch import LoopWatch
from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionRouter
from camdirector.front.zmq_service import ZmqTransport, curve_server_keys
from camdirector.infra.heap import freeze_startup_heap
from camdirector.infra.plugins import import_plugins
from camdirector.infra.private_files import make_private
from camdirector.jobs import JobSettings, JobsUnavailable, service_kinds
from camdirector.server_settings import ServerSettings
from camdirector.worker.checkpoint_stores import CheckpointError, open_store

log = logging.getLogger("camdirector.serve")


def _bind_http(address: str) -> socket.socket:
    host, _, port = address.rpartition(":")
    # IPPROTO_TCP spelled out: asyncio turns Nagle off (TCP_NODELAY) on accepted connections only
    # when the listening socket says it is TCP; with proto 0 every answer after the first on a
    # kept-alive connection waited about 40 ms for the client's delayed ACK.
    sock = socket.socket(socket.AF_INET6 if ":" in host.strip("[]") else socket.AF_INET, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host.strip("[]"), int(port)))
    sock.listen(2048)  # before the ready line: connections queue until uvicorn accepts them
    return sock


def open_guard(settings: ServerSettings) -> tuple[Guard, dict]:
    """The node's guard over its records database, and what the ready line says of it: with
    authentication on and no admin key anywhere, one is made and written to DIR/admin.key (its
    path is logged and announced, never the key)."""
    store = open_access_store(settings.job_store, settings.data_dir)
    announce: dict = {"auth": settings.auth}
    if settings.auth:
        made = ensure_admin_key(store, settings.data_dir)
        if made is not None:
            log.warning(
                "no key existed: an admin key was written to %s (mode 0600); make others with "
                "`camdirector keys create` or POST /v1/keys",
                made,
            )
            announce["admin_key_file"] = str(made)
    return Guard(store, enabled=settings.auth), announce


def _tls_credentials(settings: ServerSettings) -> grpc.ServerCredentials | None:
    if not settings.tls:
        return None
    return grpc.ssl_server_credentials([(Path(settings.tls_key).read_bytes(), Path(settings.tls_cert).read_bytes())])


def _live_tls(settings: ServerSettings) -> ssl.SSLContext | None:
    """The liveness port's TLS: the node's certificate, as its gRPC and HTTP ports show it."""
    if not settings.tls:
        return None
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(settings.tls_cert, settings.tls_key)
    return context


async def serve(settings: ServerSettings, stop: asyncio.Event | None = None) -> None:
    """Runs until `stop` is set or SIGINT/SIGTERM arrives. Prints one JSON line when ready:
    {"event": "ready", "grpc": ..., "zmq": ..., "http": ..., "auth": bool} with the bound
    addresses (and "live", the liveness port's, when it has one), and with authentication on the
    ZeroMQ server's CURVE public key ("zmq_server_key") and, when one was made, "admin_key_file"."""
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    metrics = Metrics()
    guard, announce = open_guard(settings)
    router = SessionRouter(settings, metrics, guard=guard)
    await router.start()
    loop_watch = LoopWatch(metrics.loop_lag)
    loop_watch.start()
    guard.start()
    bound: dict[str, str] = {}
    grpc_server = edge = zmq_transport = http_server = http_task = jobs = live = None
    try:
        if settings.zmq_addr:
            curve = curve_server_keys(settings.data_dir) if settings.auth else None
            zmq_transport = ZmqTransport(router, settings.zmq_addr, guard, curve)
            bound["zmq"] = zmq_transport.address
            if curve is not None:
                announce["zmq_server_key"] = curve[0].decode()
        if settings.edge:  # the compiled edge: gRPC's port, ZeroMQ's socket, or both (front/edge.py)
            edge = EdgeFront(router, guard)
            grpc_bound = await edge.start(
                settings.grpc_addr if settings.grpc_edge else None, zmq_transport if settings.zmq_edge else None
            )
            if grpc_bound is not None:
                bound["grpc"] = grpc_bound
        if settings.grpc_addr and not settings.grpc_edge:
            grpc_server, bound["grpc"] = await start_grpc(router, settings.grpc_addr, guard, _tls_credentials(settings))
        if zmq_transport is not None and not settings.zmq_edge:
            zmq_transport.start()
        if settings.http_addr:
            sock = _bind_http(settings.http_addr)
            bound["http"] = "{}:{}".format(*sock.getsockname()[:2])
            app = build_app(router, bound, secure_cookie=settings.tls, loop_watch=loop_watch)
            job_settings = JobSettings.for_server(settings)
            jobs = open_jobs(Path(settings.data_dir), service_kinds(), job_settings)
            install_overview_routes(app, jobs, job_settings)
            install_level_routes(app, jobs, Path(settings.data_dir), job_settings)
            app.openapi()  # built now, not on the loop by the first request that reads it (body_limits.py)
            jobs.start()  # queued and interrupted jobs from before a restart run again
            # A live view left open past shutdown is cut after this long (the hub ends its own first).
            config = uvicorn.Config(
                app,
                log_level="warning",
                lifespan="off",
                timeout_graceful_shutdown=3,
                ssl_certfile=settings.tls_cert if settings.tls else None,
                ssl_keyfile=settings.tls_key if settings.tls else None,
            )
            http_server = uvicorn.Server(config)
            http_task = asyncio.create_task(http_server.serve(sockets=[sock]))
            http_task.add_done_callback(lambda task: _http_ended(task, http_server, stop))
        if settings.live_addr:  # last: the balancer sends nothing here before every transport listens
            live = LiveCheck(settings.live_addr, lambda: loop_watch.last_wake_s, tls=_live_tls(settings))
            live.start()
            bound["live"] = live.address
        freeze_startup_heap()  # before the first frame: full collections walk only what comes after
        print(json.dumps({"event": "ready", **bound, "workers": settings.workers, "tls": settings.tls, **announce}), flush=True)
        await stop.wait()
    finally:
        log.info("stopping")
        if live is not None:  # first: the balancer takes the node out while it stops
            live.stop()
        if http_server is not None:
            app.state.views.close()
            http_server.should_exit = True
            assert http_task is not None  # started with http_server
            await http_task
        if jobs is not None:
            jobs.close()  # running jobs go back to the queue
        if grpc_server is not None:
            await grpc_server.stop(grace=1.0)
        if edge is not None:
            await edge.stop()  # before the ZeroMQ socket closes: the edge may be reading it
        if zmq_transport is not None:
            await zmq_transport.stop()
        loop_watch.stop()
        await router.stop()
        guard.stop()
        if guard.store is not None:
            guard.store.close()


def _http_ended(task: asyncio.Task, http_server: uvicorn.Server, stop: asyncio.Event) -> None:
    """The HTTP server's task ended. Before `stop`, a node whose HTTP port is gone while its gRPC
    port answers is worse than a stopped one (a balancer's checks and the dashboard go on seeing
    half a node): logged with why, and the whole node stops. uvicorn ends by itself on a SIGINT or
    SIGTERM it caught (its own handlers replace the loop's while it serves) or an error."""
    if stop.is_set():
        return
    signals = [signal.Signals(s).name for s in getattr(http_server, "_captured_signals", [])]
    if signals:  # a stop asked for: the loop's handler would have set `stop`
        log.info("%s received (caught by the HTTP server)", ", ".join(signals))
    else:
        error = None if task.cancelled() else task.exception()
        log.error("the HTTP server ended by itself (%r); stopping the node", error)
    stop.set()


def _warn_unsafe(settings: ServerSettings, exposed: list[str]) -> None:
    """One warning on stderr at start for each of --no-auth and --insecure (/healthz says them too);
    `exposed`: the transports in clear beyond loopback (ServerSettings.plaintext_exposed)."""
    if not settings.auth:
        log.warning(
            "--no-auth: every caller is an admin of tenant default, without a key; for a machine of "
            "your own only (docs/security.md)"
        )
    if settings.insecure:
        log.warning(
            "--insecure: keys and scenes may cross the network in clear (%s); only where TLS ends at a "
            "proxy you trust (docs/security.md)",
            ", ".join(exposed) or "none beyond loopback now",
        )


def run(settings: ServerSettings) -> int:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    exposed = settings.plaintext_exposed()
    if exposed and not settings.insecure:  # as Redis's protected mode: never in clear by accident
        print(
            f"camdirector serve: refusing to serve {', '.join(exposed)} without encryption: keys and scenes would "
            "cross the network in clear. Give --tls-cert and --tls-key (ZeroMQ is encrypted whenever "
            "authentication is on), bind to 127.0.0.1, or pass --insecure when TLS ends at a proxy you trust.",
            file=sys.stderr,
        )
        return 2
    reachable = settings.network_exposed()
    if reachable and not settings.auth and not settings.insecure:  # TLS or not: anyone who connects is admin
        print(
            f"camdirector serve: refusing to serve {', '.join(reachable)} without keys (--no-auth): anyone who "
            "reaches it would be an admin. Drop --no-auth, bind to 127.0.0.1, or pass --insecure as well when "
            "the network in front of it is yours alone.",
            file=sys.stderr,
        )
        return 2
    _warn_unsafe(settings, exposed)
    if settings.tls:
        for what in (settings.tls_cert, settings.tls_key):
            if not Path(what).is_file():
                print(f"camdirector serve: TLS file {what} cannot be read", file=sys.stderr)
                return 2
    try:  # before anything is written or spawned: every process of the node inherits the umask
        make_private(settings.data_dir)
    except OSError as exc:
        print(f"camdirector serve: {exc}", file=sys.stderr)
        return 2
    try:  # the plugins register themselves in the front; every worker imports them again (worker/main.py)
        import_plugins(settings.plugins)
    except ValueError as exc:
        print(f"camdirector serve: {exc}", file=sys.stderr)
        return 2
    try:  # a node whose checkpoints have nowhere to go refuses to start, rather than lose sessions later
        store = open_store(settings.checkpoint_store, settings.data_dir, settings.checkpoint_keep_s, check=True)
    except CheckpointError as exc:
        print(f"camdirector serve: {exc}", file=sys.stderr)
        return 2
    if store is not None:
        store.close()
    try:
        asyncio.run(serve(settings))
    except (JobsUnavailable, AccessUnavailable) as exc:  # the records database or queue is down at start
        print(f"camdirector serve: {exc}", file=sys.stderr)
        return 2
    return 0
