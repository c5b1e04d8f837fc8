"""Who calls an HTTP route, and may they (access/guard.py does the checking).

A request proves itself one of two ways:
- `Authorization: Bearer KEY`, as tools and scripts send it;
- the dashboard's cookie, set by `POST /v1/login` after it was shown a key once: it names the
  key (not its secret) and the login (an id of its own), is signed with a secret the nodes share
  (so any node behind a balancer reads it), HttpOnly, SameSite=Strict and Secure over TLS, and
  expires after COOKIE_TTL_S. A login ends earlier at logout (its id is recorded as ended, so a
  copy of the cookie is refused too) or when the secret is replaced (`camdirector keys
  rotate-secret`), on every node within the guard's poll (access/guard.py).
  A state-changing request carrying the cookie must also carry `X-CSRF-Token` (the token
  `/v1/login` and `/v1/whoami` give, derived from the cookie) and, when the browser sends an
  Origin, one matching the request's host: a page of another site can send neither.

Answers: 401 (with `WWW-Authenticate: Bearer`) without a valid key or login, 403 for a role
without the verb or a change without its CSRF token and origin, whatever bytes the cookie, token or
Origin hold; another tenant's things answer 404 in the routes themselves. 503 (with `Retry-After`)
while the records database that holds the keys is down (access/guard.py).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import re
import secrets
import time
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import urlsplit

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from camdirector.access.guard import Guard, Identity, denied, unauthenticated
from camdirector.access.keys import AccessUnavailable
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


# KEY_ID.LOGIN_ID.EXPIRES_S.SIGNATURE: a key id (keys.py), 16 random bytes, whole seconds since the
# epoch, and the HMAC-SHA256 of the rest in unpadded URL-safe base64.
_COOKIE_SHAPE = re.compile(r"([0-9a-f]{12})\.([0-9a-f]{32})\.([0-9]{1,12})\.[A-Za-z0-9_-]{43}", re.ASCII)


@dataclass(frozen=True)
class SignedLogin:
    """What a valid login cookie says."""

    key_id: str
    login_id: str
    expires_s: int


class CookieSigner:
    """Makes and reads the dashboard's login cookie and its CSRF token; `secret` gives the secret
    they are signed with now (the guard's `login_secret`, which its poll keeps current)."""

    def __init__(self, secret: Callable[[], bytes], clock: Callable[[], float] = time.time) -> None:
        self.secret = secret
        self.clock = clock

    def cookie(self, key_id: str) -> str:
        """A new login's cookie."""
        body = f"{key_id}.{secrets.token_hex(16)}.{int(self.clock() + COOKIE_TTL_S)}"
        return f"{body}.{_sign(self.secret(), body)}"

    def login(self, cookie: str) -> SignedLogin | None:
        """The login a cookie of this service's names, signed with the current secret and not
        expired; None for any other text (shaped first, so that no bytes of it can raise)."""
        shape = _COOKIE_SHAPE.fullmatch(cookie)
        if shape is None:
            return None
        body, _, signature = cookie.rpartition(".")
        if not hmac.compare_digest(signature, _sign(self.secret(), body)):
            return None
        key_id, login_id, expires = shape.groups()
        return SignedLogin(key_id, login_id, int(expires)) if int(expires) > self.clock() else None

    def csrf_token(self, cookie: str) -> str:
        return _sign(self.secret(), "csrf:" + cookie)

    def csrf_matches(self, cookie: str, token: str) -> bool:
        # As bytes: compare_digest refuses a str holding anything but ASCII (a header may).
        return hmac.compare_digest(token.encode(), self.csrf_token(cookie).encode())


def _http(exc: DirectorError) -> HTTPException:
    if exc.code.name == "UNAUTHENTICATED":
        return HTTPException(401, exc.message, headers={"WWW-Authenticate": "Bearer"})
    if exc.code.name == "UNAVAILABLE":  # the records database down (Guard.records_down)
        return HTTPException(503, exc.message, headers={"Retry-After": "10"})  # as routes/job_resources.py's 503s
    return HTTPException(403, exc.message)


def _same_origin(request: Request) -> bool:
    origin = request.headers.get("origin")
    if origin is None:  # not a browser, or one that sends no Origin: the CSRF token still has to match
        return True
    try:
        return urlsplit(origin).netloc == request.headers.get("host", "")
    except ValueError:  # not a URL ("http://["): no origin of ours
        return False


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
        login = signer.login(cookie)
        if login is None:
            raise unauthenticated("the login has expired or is not this service's: log in again")
        if guard.login_ended(login.login_id):
            raise unauthenticated("this login was ended (logged out): log in again")
        if request.method not in _SAFE_METHODS:
            if not signer.csrf_matches(cookie, request.headers.get(CSRF_HEADER, "")) or not _same_origin(request):
                raise denied(
                    f"a request with the login cookie that changes anything needs the {CSRF_HEADER} "
                    "header of /v1/whoami, from this service's own pages"
                )
        return guard.identify_key_id(login.key_id)
    except DirectorError as exc:
        raise _http(exc) from None
    except AccessUnavailable as exc:  # here, not the app's handler: the request gate calls this before any route
        raise _http(guard.records_down(exc)) from None


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
