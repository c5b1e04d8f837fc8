"""Bounded before authenticated (docs/security.md): every HTTP request's body has a limit that is
enforced while it is read, and a route that needs a key checks it before the body is read.

- Limits: LOGIN_BODY_BYTES for `POST /v1/login`, an upload route's own (`allow_body`, the job
  routes: ServerSettings.max_upload_bytes and the form around it), and
  ServerSettings.max_json_body_bytes for every other route. A Content-Length over the limit
  answers 413 before anything is read; a body without one (chunked) is counted as it arrives and
  answers 413 as soon as it passes.
- Key first: FastAPI reads and parses a body before it resolves a route's dependencies, so an
  unauthenticated upload used to be read whole and answered 422. A request with a body to an
  operation that takes a key (its `security` in the app's OpenAPI document, auth.py's scheme) is
  identified from its headers first (auth.identify): 401 before a byte of the body is read. The
  route's own dependency still checks the verb (403).

A pure ASGI middleware: Starlette's BaseHTTPMiddleware would buffer the body it should bound.
"""

from __future__ import annotations

import re

from fastapi import FastAPI, HTTPException, Request
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import Headers
from starlette.routing import compile_path
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from camdirector.front.http.auth import identify
from camdirector.server_settings import ServerSettings

LOGIN_PATH = "/v1/login"
LOGIN_BODY_BYTES = 4 * 1024  # a login's JSON: a key of at most 256 characters, with room, bytes


class BodyLimits:
    """The largest body each path takes: its own where one was allowed, else `default_bytes`."""

    def __init__(self, default_bytes: int) -> None:
        self.default_bytes = default_bytes
        self.by_path = {LOGIN_PATH: LOGIN_BODY_BYTES}

    def allow(self, path: str, max_bytes: int) -> None:
        self.by_path[path] = max_bytes

    def of(self, path: str) -> int:
        return self.by_path.get(path, self.default_bytes)


def install_request_gate(app: FastAPI, json_body_bytes: int) -> None:
    """Puts the gate in front of `app`, every route's body limited to `json_body_bytes` until an
    upload route allows its own (allow_body)."""
    app.state.body_limits = BodyLimits(json_body_bytes)
    app.add_middleware(RequestGate, limits=app.state.body_limits)


def allow_body(app: FastAPI, path: str, max_bytes: int) -> None:
    """Bodies to `path` may be up to `max_bytes` (an upload route's). An app built without the
    gate (a job routes' test mounts them on a bare app) gets it here, with the default JSON limit."""
    if not hasattr(app.state, "body_limits"):
        install_request_gate(app, ServerSettings.max_json_body_bytes)
    app.state.body_limits.allow(path, max_bytes)


def _too_large(limit: int) -> str:
    return f"request body larger than the limit of {limit} bytes"


class RequestGate:
    """The ASGI middleware of the module docstring."""

    def __init__(self, app: ASGIApp, limits: BodyLimits) -> None:
        self.app = app
        self.limits = limits
        self._templates: dict[str, re.Pattern[str]] = {}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        limit = self.limits.of(scope["path"])
        headers = Headers(scope=scope)
        length = headers.get("content-length")
        if length is not None and length.isdigit() and int(length) > limit:
            return await _refuse(scope, receive, send, HTTPException(413, _too_large(limit)))
        if (length not in (None, "0") or "transfer-encoding" in headers) and self._takes_key(scope):
            try:  # in a thread: a key not cached yet is looked up in the records database
                await run_in_threadpool(identify, Request(scope))
            except HTTPException as exc:
                return await _refuse(scope, receive, send, exc)
        seen = 0

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:  # raised into the route's body read; its HTTPException handler answers
                    raise HTTPException(413, _too_large(limit), headers={"Connection": "close"})
            return message

        await self.app(scope, counted, send)

    def _takes_key(self, scope: Scope) -> bool:
        """Whether the operation `scope` asks for takes a key, by the app's OpenAPI document
        (FastAPI's, cached; made again when routes are added)."""
        method = scope["method"].lower()
        for template, operations in scope["app"].openapi()["paths"].items():
            if method in operations and "security" in operations[method]:
                pattern = self._templates.get(template)
                if pattern is None:
                    pattern = self._templates[template] = compile_path(template)[0]
                if pattern.match(scope["path"]):
                    return True
        return False


async def _refuse(scope: Scope, receive: Receive, send: Send, exc: HTTPException) -> None:
    """Answers `exc` without reading the body, and closes the connection (its body is unread)."""
    response = JSONResponse({"detail": exc.detail}, exc.status_code, headers={**(exc.headers or {}), "Connection": "close"})
    await response(scope, receive, send)
