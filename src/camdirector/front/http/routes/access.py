"""REST routes of keys, logins and the audit trail (access/, docs/security.md).

POST   /v1/login        body {"key": KEY} -> the caller; sets the dashboard's login cookie
POST   /v1/logout       ends the login (on every node) and clears the cookie
GET    /v1/whoami       the caller: key id, role, tenant (and the CSRF token with the cookie)
GET    /v1/keys         the tenant's keys (admin)
POST   /v1/keys         body {"role", "name"} -> 201 the new key, shown this once (admin)
DELETE /v1/keys/{id}    revoke one of the tenant's keys (admin): refused at once on every node
(Without keys, `--no-auth`, both writes answer 403: a key made then would outlive the run.)
GET    /v1/audit?after_seq=&limit=   the tenant's takes, releases, style, level and key changes (admin)
"""

from __future__ import annotations

from typing import Annotated, Literal, get_args

from fastapi import APIRouter, Body, Depends, HTTPException, Query, Request, Response
from pydantic import BaseModel, Field

from camdirector.access.guard import Guard, Identity
from camdirector.access.keys import KeyNotFound
from camdirector.access.roles import ROLE_VERBS, ROLES, Verb
from camdirector.errors import DirectorError
from camdirector.front.http.auth import COOKIE, COOKIE_TTL_S, identify, require

_NOT_JSON = {"description": "the body cannot be read as JSON"}
Role = Literal["engine", "director", "viewer", "admin"]
assert set(get_args(Role)) == set(ROLES)  # noqa: S101 - the literal mirrors roles.py's table


class Caller(BaseModel):
    key_id: str | None = Field(description="null when the server runs without authentication")
    role: str
    tenant: str
    verbs: list[str] = Field(description="what the key's role may do (docs/security.md)")
    csrf_token: str | None = Field(None, description="send as X-CSRF-Token with the login cookie's changes")


class KeyOut(BaseModel):
    id: str
    name: str
    role: str
    tenant: str
    created_s: float
    revoked_s: float | None


class KeyList(BaseModel):
    keys: list[KeyOut]


class KeyCreated(KeyOut):
    key: str = Field(description="the key itself: shown once, stored only hashed")


class NewKey(BaseModel):
    role: Role
    name: str = Field("", max_length=200)


class Login(BaseModel):
    key: str = Field(max_length=256)


class AuditEntry(BaseModel):
    seq: int
    at_s: float
    key_id: str | None
    action: str
    session_id: str | None
    detail: dict


class AuditTrail(BaseModel):
    entries: list[AuditEntry]


def _caller(request: Request, identity: Identity, cookie: str | None) -> dict:
    token = request.app.state.cookies.csrf_token(cookie) if cookie else None
    return {
        "key_id": identity.key_id,
        "role": identity.role,
        "tenant": identity.tenant,
        "verbs": sorted(verb.value for verb in ROLE_VERBS[identity.role]),
        "csrf_token": token,
    }


def _keys_on(guard: Guard) -> None:
    """403 for a change of keys on a server without keys: a key made by a caller nobody checked
    would stay valid once keys are turned on (and, an admin's, stop the first start with keys
    from writing admin.key); a key revoked so could lock out the real admin."""
    if not guard.enabled:
        raise HTTPException(
            403,
            "this server runs without keys (--no-auth): keys are made and revoked only with "
            "authentication on (an admin key, or `camdirector keys` on the server's machine)",
        )


def build_access_router(guard: Guard, secure_cookie: bool) -> APIRouter:
    routes = APIRouter(prefix="/v1", tags=["access"])

    @routes.post("/login", response_model=Caller, responses={400: _NOT_JSON, 401: {"description": "not a valid key"}})
    def login(request: Request, response: Response, body: Login) -> dict:
        """Checks a key and keeps it as the dashboard's login cookie (module docstring of auth.py).
        A JSON body only: a page of another site cannot send one without the browser asking first."""
        try:
            identity = guard.identify(f"Bearer {body.key}")
        except DirectorError as exc:
            raise HTTPException(401, exc.message, headers={"WWW-Authenticate": "Bearer"}) from None
        if identity.key_id is None:
            return _caller(request, identity, None)
        cookie = request.app.state.cookies.cookie(identity.key_id)
        response.set_cookie(
            COOKIE, cookie, max_age=int(COOKIE_TTL_S), httponly=True, samesite="strict", secure=secure_cookie, path="/"
        )
        return _caller(request, identity, cookie)

    @routes.post("/logout", status_code=204, response_class=Response)
    def logout(request: Request) -> Response:
        """Ends the login its cookie names, on every node (a copy of the cookie is refused too), and
        has the browser forget the cookie."""
        login = request.app.state.cookies.login(request.cookies.get(COOKIE, ""))
        if login is not None:  # a valid cookie: only logins made with keys on have one
            guard.end_login(login.login_id, login.expires_s)
        response = Response(status_code=204)
        response.delete_cookie(COOKIE, path="/", httponly=True, samesite="strict", secure=secure_cookie)
        return response

    @routes.get("/whoami", response_model=Caller, responses={401: {"description": "no valid key"}})
    def whoami(request: Request) -> dict:
        """The caller's key, role and tenant."""
        identity = identify(request)
        return _caller(request, identity, request.cookies.get(COOKIE) if "authorization" not in request.headers else None)

    @routes.get("/keys", response_model=KeyList)
    def list_keys(identity: Annotated[Identity, Depends(require(Verb.KEY_MANAGE))]) -> dict:
        """The tenant's keys, revoked ones too (never a key itself)."""
        return {"keys": [k.as_public() for k in guard.key_store().list_keys(identity.tenant)]}

    @routes.post("/keys", status_code=201, response_model=KeyCreated, responses={400: _NOT_JSON})
    def create_key(identity: Annotated[Identity, Depends(require(Verb.KEY_MANAGE))], body: Annotated[NewKey, Body()]) -> dict:
        """A new key of the caller's tenant."""
        _keys_on(guard)
        record, text = guard.key_store().create_key(body.role, identity.tenant, body.name)
        guard.audit(identity, "key.create", None, {"key_id": record.key_id, "role": body.role, "name": body.name})
        return {**record.as_public(), "key": text}

    @routes.delete("/keys/{key_id}", response_model=KeyOut, responses={404: {"description": "no such key"}})
    def revoke_key(key_id: str, identity: Annotated[Identity, Depends(require(Verb.KEY_MANAGE))]) -> dict:
        """Revokes one of the tenant's keys: refused from now on by every node."""
        _keys_on(guard)
        try:
            record = guard.key_store().revoke(key_id, identity.tenant)
        except KeyNotFound:
            raise HTTPException(404, f"no key {key_id!r}") from None
        guard.refresh(key_id)
        guard.audit(identity, "key.revoke", None, {"key_id": key_id})
        return record.as_public()

    @routes.get("/audit", response_model=AuditTrail)
    def audit(
        identity: Annotated[Identity, Depends(require(Verb.AUDIT_READ))],
        after_seq: Annotated[int, Query(ge=0, le=2**62, description="only entries after this one")] = 0,
        limit: Annotated[int, Query(ge=1, le=5000)] = 500,
    ) -> dict:
        """The tenant's audit trail, oldest first: when, which key, which session, what."""
        return {"entries": guard.store.audit_trail(identity.tenant, after_seq, limit)} if guard.store else {"entries": []}

    return routes
