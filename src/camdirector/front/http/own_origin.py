"""Without keys (`--no-auth`), only this server's own address and pages may use its HTTP app
(docs/security.md). Any caller is then an admin, so a browser on the same machine is one too:

- DNS rebinding: a page of another site makes its own name resolve to this server's address, and
  its scripts then read and change this server as if they were its own pages. The browser still
  sends the page's name as Host, so every request (reads too) must name this server in Host: a
  loopback name or address, the name or address it was told to bind, or, when bound to every
  interface, any address literal or this machine's own names (no rebinding goes through an
  address literal).
- Cross-site forms: a page of another site posts a multipart form (a level replaced, a job
  queued) without asking the browser first. Every state-changing request with an Origin must come
  from this server's own origin: its host and port are the request's Host.

With keys none of this applies: a page holds no key, and the dashboard's cookie has its own CSRF
checks (auth.py). A pure ASGI middleware, answering 403 before a byte of the body is read.
"""

from __future__ import annotations

import ipaddress
import socket
from urllib.parse import urlsplit

from fastapi.responses import JSONResponse
from starlette.datastructures import Headers
from starlette.types import ASGIApp, Receive, Scope, Send

_SAFE_METHODS = {"GET", "HEAD", "OPTIONS"}


def _host_of(netloc: str) -> str | None:
    """The host of HOST[:PORT] ("[::1]:8080" -> "::1"), lower case; None when it has none."""
    try:
        return urlsplit(f"//{netloc}").hostname
    except ValueError:  # an unclosed IPv6 bracket
        return None


def _netloc_of(origin: str) -> str | None:
    """HOST[:PORT] of an Origin ("null" -> ""), lower case; None when it cannot be read."""
    try:
        return urlsplit(origin).netloc.lower()
    except ValueError:  # an unclosed IPv6 bracket
        return None


class OwnOriginOnly:
    """The module docstring's checks. `bound`: the HTTP socket's HOST:PORT; `configured`: the
    --http address it was given (a name there is one of this server's)."""

    def __init__(self, app: ASGIApp, bound: str, configured: str) -> None:
        self.app = app
        self.bound = ipaddress.ip_address(bound.rpartition(":")[0].strip("[]"))
        self.names = {name for name in ("localhost", _host_of(configured)) if name}
        if self.bound.is_unspecified:  # every interface: clients may dial this machine by its names
            self.names |= {socket.gethostname().lower(), socket.getfqdn().lower()}

    def _host_allowed(self, host: str | None) -> bool:
        if host is None:
            return False
        try:
            address = ipaddress.ip_address(host)
        except ValueError:  # a name
            return host in self.names
        return address.is_loopback or address == self.bound or self.bound.is_unspecified

    def refusal(self, method: str, headers: Headers) -> str | None:
        """Why a request is refused, None when it may go on."""
        host = headers.get("host", "")
        if not self._host_allowed(_host_of(host)):
            return (
                "this server runs without keys (--no-auth) and answers only requests that name it in "
                "their Host header (127.0.0.1, localhost, or the address it is bound to): the name used "
                "is not one of its own (DNS rebinding). Use its address, or turn keys on (docs/security.md)"
            )
        origin = headers.get("origin")
        if method not in _SAFE_METHODS and origin is not None and _netloc_of(origin) != host.lower():
            return (
                "this server runs without keys (--no-auth) and takes changes from its own pages only: "
                "the request's Origin is another site's. Turn keys on to use it from elsewhere (docs/security.md)"
            )
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and (why := self.refusal(scope["method"], Headers(scope=scope))) is not None:
            return await JSONResponse({"detail": why}, status_code=403)(scope, receive, send)
        await self.app(scope, receive, send)
