"""HTTP API (FastAPI): health, Prometheus metrics, the REST routes of the service, and the
director's dashboard (static files under /dashboard/ that read those routes).

Every route but `/healthz` (balancers probe it) and the dashboard's static files asks for a key
(auth.py); `/metrics` wants an admin's. Without keys, only this server's own address and pages
may use it (own_origin.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from fastapi import Depends, FastAPI, Request, Response
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, PlainTextResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import compile_path

from camdirector.access.guard import RECORDS, Identity
from camdirector.access.keys import AccessUnavailable
from camdirector.access.roles import Verb
from camdirector.front.http.auth import CookieSigner, require
from camdirector.front.http.body_limits import install_request_gate
from camdirector.front.http.own_origin import OwnOriginOnly
from camdirector.front.http.routes.access import build_access_router
from camdirector.front.http.routes.directors import build_director_router
from camdirector.front.http.routes.job_resources import answer_unavailable
from camdirector.front.http.routes.monitors import build_view_router
from camdirector.front.http.routes.sessions import build_session_router
from camdirector.front.loop_watch import LoopWatch
from camdirector.front.router import SessionRouter
from camdirector.front.view_hub import ViewHub
from camdirector.version import PROTOCOL, VERSION

DASHBOARD_DIR = Path(__file__).with_name("dashboard")


def build_app(
    router: SessionRouter, transports: dict[str, str], secure_cookie: bool = False, loop_watch: LoopWatch | None = None
) -> FastAPI:
    """The app; `app.state.views` is its ViewHub, which the server closes before stopping (its
    live streams would hold the HTTP server open). The router's guard checks every caller;
    `secure_cookie`: the login cookie is sent over TLS only; `loop_watch`: the front loop's lag,
    shown by /healthz."""
    app = FastAPI(
        title="camdirector",
        version=VERSION,
        description="Automated cinematographer: health, metrics, sessions, monitors, and offline jobs.",
        # No Swagger UI or ReDoc: FastAPI's pages load their scripts from a CDN, unpinned, into the
        # origin that holds the login cookie. The document itself is an admin's (openapi_document).
        docs_url=None,
        redoc_url=None,
        openapi_url=None,
    )
    app.state.views = ViewHub(router, router.metrics)
    app.state.guard = guard = router.guard
    app.state.cookies = CookieSigner(lambda: guard.login_secret)
    install_request_gate(app, router.settings.max_json_body_bytes)
    if not guard.enabled:  # added after the gate, so outside it: a request it refuses reaches nothing
        app.add_middleware(OwnOriginOnly, bound=transports["http"], configured=router.settings.http_addr)

    @app.get("/healthz")
    def healthz() -> dict:
        """Liveness and a short status: version and protocol, open sessions, worker processes, bound
        transports (a cluster upgraded node by node shows which node runs what), and whether keys
        are checked (`auth`: false under --no-auth) and plaintext beyond loopback allowed
        (`insecure`), so a node started unsafely shows it; `loop_lag_ms`, the largest lag of the
        loop that answers frames over the last 10 s (front/loop_watch.py)."""
        lag = {} if loop_watch is None else {"loop_lag_ms": round(loop_watch.recent_max_ms(), 1)}
        return {
            "status": "ok",
            "version": VERSION,
            "protocol": PROTOCOL,
            "sessions": len(router.sessions),
            "workers": router.pool.size,
            "transports": transports,
            "auth": guard.enabled,
            "insecure": router.settings.insecure,
            **lag,
        }

    @app.exception_handler(StarletteHTTPException)
    async def allow_every_method(request: Request, exc: StarletteHTTPException) -> Response:
        """A 405's Allow header names the methods of every documented route on the path:
        Starlette's names only those of the first route that matched (GET /v1/levels beside POST)."""
        if exc.status_code == 405:
            allowed = sorted(
                {
                    method.upper()
                    for template, operations in app.openapi()["paths"].items()
                    if compile_path(template)[0].match(request.url.path)
                    for method in operations
                }
            )
            if allowed:
                exc = StarletteHTTPException(405, exc.detail, headers={"Allow": ", ".join(allowed)})
        return await http_exception_handler(request, exc)

    @app.exception_handler(RequestValidationError)
    async def validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        """FastAPI's 422 without the `input` (and `ctx`) it copies from the request: an error
        never echoes what was sent (a body, a key sent in the wrong place)."""
        errors = [{"loc": list(e["loc"]), "msg": e["msg"], "type": e["type"]} for e in exc.errors()]
        return JSONResponse({"detail": errors}, status_code=422)

    @app.get("/metrics", response_class=PlainTextResponse)
    def metrics(_: Annotated[Identity, Depends(require(Verb.METRICS_READ))]) -> Response:
        """Prometheus text exposition."""
        return Response(generate_latest(router.metrics.registry), media_type=CONTENT_TYPE_LATEST)

    app.include_router(build_access_router(guard, secure_cookie))
    answer_unavailable(app, AccessUnavailable, RECORDS, guard.records_down)  # logins, keys, audit: 503
    app.include_router(build_session_router(router))
    app.include_router(build_director_router())
    app.include_router(build_view_router(app.state.views))
    # The director's dashboard: static files that read the routes above.
    app.mount("/dashboard", StaticFiles(directory=DASHBOARD_DIR, html=True), name="dashboard")

    @app.get("/", include_in_schema=False)
    def root() -> RedirectResponse:
        return RedirectResponse("/dashboard/")

    @app.get("/openapi.json", include_in_schema=False)
    def openapi_document(_: Annotated[Identity, Depends(require(Verb.SCHEMA_READ))]) -> JSONResponse:
        """The REST API's OpenAPI document, for an admin's tools (schemathesis, client generators)."""
        return JSONResponse(app.openapi())

    _document_key_answers(app)
    return app


def _document_key_answers(app: FastAPI) -> None:
    """Every operation that takes a key (its `security`, auth.py's scheme) documents the 401 and
    403 it answers, and every one that takes a body the 413 of its limit (body_limits.py), routes
    installed later included (the document is built on first request)."""
    build = app.openapi

    def openapi() -> dict:
        schema = build()  # FastAPI's cached document, made again when routes were added
        for operations in schema["paths"].values():
            for operation in operations.values():
                if operation.get("security"):
                    responses = operation.setdefault("responses", {})
                    responses.setdefault("401", {"description": "no key, an unknown one or a revoked one"})
                    responses.setdefault("403", {"description": "the key's role may not do this"})
                if "requestBody" in operation:
                    operation["responses"].setdefault("413", {"description": "the body is larger than the route's limit"})
        return schema

    app.openapi = openapi  # type: ignore[method-assign]  # FastAPI's documented way to extend its schema
