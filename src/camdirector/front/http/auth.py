"""Who calls an HTTP route, and may they (access/guard.py does the checking).

A request proves itself one of two ways:
- `Authorization: Bearer KEY`, as tools and scripts send it;
- the dashboard's cookie, set by `POST /v1/login` after it was shown a key once: it names the
  key (not its secret), is signed with a secret the nodes share (so any node behind a balancer
  reads it), HttpOnly, SameSite=Strict and Secure over TLS, and expires after COOKIE_TTL_S.
  A state-changing request carrying the cookie must also carry `X-CSRF-Token` (the token
  `/v1/login` and `/v1/whoami` give, derived from the cookie) and, when the browser sends an
  Origin, one matching the request's host: a page of another site can send neither.

Answers: 401 (with `WWW-Authenticate: Bearer`) without a valid key, 403 for a role without the
verb; another tenant's things answer 404 in the routes themselves.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import time
from urllib.parse import urlsplit

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from camdirector.access.guard import Guard, Identity, denied, unauthenticated
from camdirector.access.roles import Verb
from camdirector.errors import DirectorError

COOKIE = "camdirector_login"
COOKIE_TTL_S = 12 * 3600.0  # a dashboard login lasts a working day, s
CSRF_HEADER = "X-CSRF-Token"
_SAFE_METHODS = {"GET", "HEAD", "OPTIONS"}

# Declares the scheme in the OpenAPI document (tools and fuzzers send the header from it); the
# checking is ours, below, so that 401 and 403 come apart as docs/security.md says.
bearer_scheme = HTTPBearer(auto_error=False, description="an API key: `camdirector keys create`")


def _sign(secret: bytes, text: str) -> str:
    return base64.urlsafe_b64encode(hmac.new(secret, text.encode(), hashlib.sha256).digest()).decode().rstrip("=")


class CookieSigner:
    """Makes and reads the dashboard's login cookie and its CSRF token."""

    def __init__(self, secret: bytes, clock=time.time) -> None:
        self.secret = secret
        self.clock = clock

    def cookie(self, key_id: str) -> str:
        body = f"{key_id}.{int(self.clock() + COOKIE_TTL_S)}"
        return f"{body}.{_sign(self.secret, body)}"

    def key_id(self, cookie: str) -> str | None:
        """The key a valid, unexpired cookie names; None otherwise."""
        body, _, signature = cookie.rpartition(".")
        key_id, _, expires = body.partition(".")
        if not (body and hmac.compare_digest(signature, _sign(self.secret, body)) and expires.isdigit()):
            return None
        return key_id if int(expires) > self.clock() else None

    def csrf_token(self, cookie: str) -> str:
        return _sign(self.secret, "csrf:" + cookie)


def _http(exc: DirectorError) -> HTTPException:
    if exc.code.name == "UNAUTHENTICATED":
        return HTTPException(401, exc.message, headers={"WWW-Authenticate": "Bearer"})
    return HTTPException(403, exc.message)


def _same_origin(request: Request) -> bool:
    origin = request.headers.get("origin")
    if origin is None:  # not a browser, or one that sends no Origin: the CSRF token still has to match
        return True
    return urlsplit(origin).netloc == request.headers.get("host", "")


def identify(request: Request) -> Identity:
    """The caller of `request` (the module docstring's two ways); HTTPException 401 otherwise."""
    guard: Guard = request.app.state.guard
    authorization = request.headers.get("authorization")
    try:
        if authorization is not None or not guard.enabled:
            return guard.identify(authorization)
        cookie = request.cookies.get(COOKIE)
        if cookie is None:
            raise unauthenticated("no key: send 'Authorization: Bearer KEY', or log in to the dashboard")
        signer: CookieSigner = request.app.state.cookies
        key_id = signer.key_id(cookie)
        if key_id is None:
            raise unauthenticated("the login has expired or is not this service's: log in again")
        if request.method not in _SAFE_METHODS:
            token = request.headers.get(CSRF_HEADER, "")
            if not hmac.compare_digest(token, signer.csrf_token(cookie)) or not _same_origin(request):
                raise denied(
                    f"a request with the login cookie that changes anything needs the {CSRF_HEADER} "
                    "header of /v1/whoami, from this service's own pages"
                )
        return guard.identify_key_id(key_id)
    except DirectorError as exc:
        raise _http(exc) from None


def require(verb: Verb):
    """A route dependency: the caller, when its role has `verb` (401 / 403 otherwise)."""

    def caller(request: Request, _: HTTPAuthorizationCredentials | None = Depends(bearer_scheme)) -> Identity:
        identity = identify(request)
        try:
            Guard.check(identity, verb)
        except DirectorError as exc:
            raise _http(exc) from None
        return identity

    caller.__name__ = f"require_{verb.name.lower()}"
    return caller
