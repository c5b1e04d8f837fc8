"""Who is calling, and may they: the check every transport makes (gRPC metadata, the ZeroMQ
envelope's key frame, HTTP's Authorization header or the dashboard's cookie).

    identify(authorization, fresh)  -> Identity, or UNAUTHENTICATED (no key, unknown, revoked)
    check(identity, verb)           -> PERMISSION_DENIED when the key's role lacks the verb

A streaming frame asks with `fresh=False`: its key is checked against this node's cache (a dict
lookup and a SHA-256 of the secret, about 2 us), which a background poll of the records database
keeps current: a key revoked on any node stops streaming frames here within `poll_s`. Every
other call (`fresh=True`) reads the key's row from the records database, so a revocation through
any node holds at once for them.

The same poll keeps the dashboard's logins current (front/http/auth.py checks the cookies): the
secret that signs them (`login_secret`; rotated by `camdirector keys rotate-secret`, every login
made before is refused) and the logins ended by logout on any node (`login_ended`).

With authentication off (`--no-auth`) every caller is `OPEN`: tenant `default`, role `admin`.

The records database down (PostgreSQL, `AccessUnavailable`): keys already in this node's cache keep
streaming frames; every call that must read or write a record answers UNAVAILABLE (HTTP 503) in
words naming only the kind of store (`RECORDS_DOWN`), and the reason goes to the log once per
outage (`records_down`; the poll notes its end). A hung one (infra/postgres.py bounds each call)
must not stall the front's event loop, which answers every stream's frames: a caller on the loop
reads and writes records through `off_loop` (a few threads of the guard's own) and awaits them,
and `authorize_async` reads a key there only when it must (fresh, or not cached).
"""

from __future__ import annotations

import asyncio
import functools
import logging
import secrets
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, TypeVar

import grpc

from camdirector.access.keys import LOGIN_SECRET, AccessStore, AccessUnavailable, ApiKey, secret_matches, split_key
from camdirector.access.roles import Verb, allows
from camdirector.errors import DirectorError, internal, unavailable

log = logging.getLogger("camdirector.access")

REVOCATION_POLL_S = 0.25  # how often each node looks for keys revoked elsewhere, s
CLOCK_SKEW_S = 30.0  # revocations are read this far back from the last poll (nodes' clocks differ)
RECORDS = "the records database"  # what a client is told of it: any caller reads it, so no URL or host
RECORDS_DOWN = f"{RECORDS} is unreachable; retry later"
RECORDS_THREADS = 4  # records calls the event loop has in flight at once (the database takes one at a time)

T = TypeVar("T")


@dataclass(frozen=True)
class Identity:
    key_id: str | None  # None when authentication is off
    role: str
    tenant: str

    def label(self) -> str:
        return f"key {self.key_id}" if self.key_id else "no key (authentication off)"


OPEN = Identity(None, "admin", "default")


def unauthenticated(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.UNAUTHENTICATED, message)


def denied(message: str) -> DirectorError:
    return DirectorError(grpc.StatusCode.PERMISSION_DENIED, message)


def bearer(authorization: str | None) -> str | None:
    """The key of an `Authorization: Bearer KEY` value, None when there is none."""
    if not authorization:
        return None
    scheme, _, token = authorization.strip().partition(" ")
    return token.strip() if scheme.lower() == "bearer" and token.strip() else None


class Guard:
    """`store` None: authentication off. `clock`: wall time, s (revocation times are wall times)."""

    def __init__(
        self,
        store: AccessStore | None,
        *,
        enabled: bool = True,
        poll_s: float = REVOCATION_POLL_S,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.store = store
        self.enabled = enabled and store is not None
        self.poll_s = poll_s
        self.clock = clock
        self._cache: dict[str, tuple[ApiKey, str]] = {}
        self._polled_s = clock()
        self._watcher: asyncio.Task[None] | None = None
        self._ended_logins: dict[str, float] = {}  # login id -> when its cookie expires, s
        self._ended_lock = threading.Lock()  # the poll's thread and the routes' threads note ended logins
        self._records_down = False  # an outage was logged and the poll has not reached the database since
        self._records_threads = ThreadPoolExecutor(RECORDS_THREADS, thread_name_prefix="records")
        # told each key id found revoked (`refresh`): the compiled gRPC edge, which checks its streams itself
        self.on_revoked: list[Callable[[str], None]] = []
        # Without keys no login is made: a secret of this process's own signs nothing anyone uses.
        self.login_secret = secrets.token_bytes(32)
        if self.enabled:
            self.login_secret = self.key_store().shared_secret(LOGIN_SECRET)
            self._note_ended_logins(self.key_store().ended_logins(0.0))

    def key_store(self) -> AccessStore:
        """The key store, for the calls made with authentication on (`enabled` implies a store)."""
        assert self.store is not None, "authentication is off: there is no key store"
        return self.store

    async def off_loop(self, call: Callable[..., T], *args: Any) -> T:
        """`call(*args)`, a call to the records database, run in one of the guard's threads and
        awaited: the event loop goes on answering frames while the database takes its time."""
        return await asyncio.get_running_loop().run_in_executor(self._records_threads, functools.partial(call, *args))

    # -- identity
    def identify(self, authorization: str | None, *, fresh: bool = True) -> Identity:
        """The caller (in a thread: a key not read from the cache is read from the records database)."""
        if not self.enabled:
            return OPEN
        key_id, secret = self._key(authorization)
        found = (None if fresh else self._cache.get(key_id)) or self._lookup(key_id)
        return self._identity(key_id, secret, found)

    async def authorize_async(self, authorization: str | None, verb: Verb, *, fresh: bool = True) -> Identity:
        """`authorize` for a caller on the event loop: a key found in the cache (`fresh` False)
        costs no wait; one read from the records database is read through `off_loop`."""
        identity = OPEN
        if self.enabled:
            key_id, secret = self._key(authorization)
            found = None if fresh else self._cache.get(key_id)
            if found is None:
                found = await self.off_loop(self._lookup, key_id)
            identity = self._identity(key_id, secret, found)
        self.check(identity, verb)
        return identity

    @staticmethod
    def _key(authorization: str | None) -> tuple[str, str]:
        """(id, secret) of the key an Authorization value carries; UNAUTHENTICATED without one."""
        token = bearer(authorization)
        if token is None:
            raise unauthenticated("no key: send 'authorization: Bearer KEY' (docs/security.md)")
        parts = split_key(token)
        if parts is None:
            raise unauthenticated("the key is not a camdirector key (cdk_...)")
        return parts

    def _lookup(self, key_id: str) -> tuple[ApiKey, str]:
        """The key's record read from the records database, and cached; UNAUTHENTICATED when unknown."""
        found = self.key_store().lookup(key_id)
        if found is None:
            raise unauthenticated("unknown key")
        self._cache[key_id] = found
        return found

    @staticmethod
    def _identity(key_id: str, secret: str, found: tuple[ApiKey, str]) -> Identity:
        record, stored_hash = found
        if not secret_matches(secret, stored_hash):
            raise unauthenticated("unknown key")
        if record.revoked:
            raise unauthenticated(f"key {key_id} was revoked")
        return Identity(key_id, record.role, record.tenant)

    def identify_key_id(self, key_id: str) -> Identity:
        """The identity of a key named by id alone, read fresh (a signed login cookie, whose
        signature stands for the secret shown at login)."""
        found = self.key_store().lookup(key_id)
        if found is None or found[0].revoked:
            raise unauthenticated("the key of this login was revoked: log in with another key")
        self._cache[key_id] = found
        return Identity(key_id, found[0].role, found[0].tenant)

    def still_valid(self, identity: Identity) -> None:
        """UNAUTHENTICATED when the identity's key was revoked since (a stream's later messages)."""
        if identity.key_id is None:
            return
        found = self._cache.get(identity.key_id)
        if found is not None and found[0].revoked:
            raise unauthenticated(f"key {identity.key_id} was revoked")

    @staticmethod
    def check(identity: Identity, verb: Verb) -> None:
        if not allows(identity.role, verb):
            raise denied(f"a key of role {identity.role!r} may not {verb.value} (docs/security.md)")

    def authorize(self, authorization: str | None, verb: Verb, *, fresh: bool = True) -> Identity:
        identity = self.identify(authorization, fresh=fresh)
        self.check(identity, verb)
        return identity

    # -- revocation
    def refresh(self, key_id: str) -> None:
        """A key revoked through this node: its cached record read again, so that streams using
        it end at their next message."""
        if key_id in self._cache:
            found = self.key_store().lookup(key_id)
            if found is None:
                self._cache.pop(key_id)
            else:
                self._cache[key_id] = found
            if found is not None and found[0].revoked:  # what still_valid refuses
                for tell in self.on_revoked:
                    tell(key_id)

    def poll_revocations(self) -> list[str]:
        """Learns what changed on any node since the last poll: keys revoked (marked in the cache;
        their ids returned), logins ended, and the login secret replaced."""
        now = self.clock()
        store = self.key_store()
        revoked = store.revoked_since(self._polled_s - CLOCK_SKEW_S)
        self._note_ended_logins(store.ended_logins(self._polled_s - CLOCK_SKEW_S))
        login_secret = store.shared_secret(LOGIN_SECRET)
        self._polled_s = now
        if self._records_down:
            self._records_down = False
            log.warning("%s is reachable again", RECORDS)
        if login_secret != self.login_secret:
            self.login_secret = login_secret
            log.info("the dashboard's login secret was replaced: every login made before is refused")
        hit = []
        for key_id, _ in revoked:
            if key_id in self._cache and not self._cache[key_id][0].revoked:
                self.refresh(key_id)
                hit.append(key_id)
        return hit

    # -- the dashboard's logins
    def end_login(self, login_id: str, expires_s: float) -> None:
        """Logout: the login is refused from now on, here at once and by other nodes from their
        next poll; `expires_s`, when its cookie expires anyway."""
        self.key_store().end_login(login_id, expires_s)
        self._note_ended_logins([(login_id, expires_s)])

    def login_ended(self, login_id: str) -> bool:
        return login_id in self._ended_logins

    def _note_ended_logins(self, ended: list[tuple[str, float]]) -> None:
        """Adds logins ended and forgets those whose cookies have expired since."""
        now = self.clock()
        with self._ended_lock:
            self._ended_logins.update(ended)
            for login_id in [i for i, expires_s in self._ended_logins.items() if expires_s <= now]:
                del self._ended_logins[login_id]

    async def _watch(self) -> None:
        while True:
            await asyncio.sleep(self.poll_s)
            try:
                for key_id in await self.off_loop(self.poll_revocations):
                    log.info("key %s revoked: refused from now on", key_id)
            except AccessUnavailable as exc:  # keep the last known keys
                self.records_down(exc)
            except Exception as exc:  # a bug: the poll goes on with the last known keys
                log.warning("polling revoked keys: %s", exc)

    def refusal(self, exc: Exception, what: str, session_id: Callable[[], str | None], logger: logging.Logger) -> DirectorError:
        """The error a call that raised `exc` is answered with, the same on every transport (gRPC,
        ZeroMQ, the compiled edge): a DirectorError as it is; UNAVAILABLE when the records database
        was needed and is down (records_down); INTERNAL for anything else, a bug (errors.internal,
        its traceback logged with `what` and the session `session_id()` names)."""
        if isinstance(exc, DirectorError):
            return exc
        if isinstance(exc, AccessUnavailable):
            return self.records_down(exc)
        return internal(exc, what, session_id(), logger)

    def records_down(self, exc: AccessUnavailable) -> DirectorError:
        """The answer to a call that needed the records database while it is down: UNAVAILABLE
        (the SDKs retry it), naming no URL or host; the reason (its URL's secrets hidden,
        infra/postgres.py) is logged once per outage, not per call or poll."""
        if not self._records_down:
            self._records_down = True
            log.warning("%s; keys already known here keep streaming frames until it is back", exc)
        return unavailable(RECORDS_DOWN)

    def start(self) -> None:
        if self.enabled:
            self._watcher = asyncio.create_task(self._watch())

    def stop(self) -> None:
        if self._watcher is not None:
            self._watcher.cancel()
        self._records_threads.shutdown(wait=False)

    # -- the audit trail (module docstring of keys.py)
    def audit(self, identity: Identity, action: str, session_id: str | None = None, detail: dict[str, Any] | None = None) -> None:
        if self.store is not None:
            self.store.audit(identity.tenant, identity.key_id, action, session_id, detail)
