"""Roles and the verbs each may use: the one table every transport asks (docs/security.md shows
it, and tests/access/test_every_door.py checks each route and RPC against that page).

A key has one role and one tenant (a name that infra/tenants.py checks). Sessions, levels and
jobs belong to the tenant of the key that made them; a key sees nothing of another tenant's
(answered as if it did not exist).
"""

from __future__ import annotations

from enum import Enum


class Verb(str, Enum):
    SESSION_CREATE = "session.create"  # CreateSession
    SESSION_STREAM = "session.stream"  # Frame, StreamFrames
    SESSION_STYLE = "session.style"  # UpdateStyle, PUT /v1/sessions/{id}/style
    SESSION_CLOSE = "session.close"  # CloseSession
    SESSION_TAKE = "session.take"  # TakeShot (take and release), POST /v1/sessions/{id}/take
    SESSION_READ = "session.read"  # list, timeline, A-map, monitors, top view, the match directors
    LEVEL_READ = "level.read"  # list and read levels and their jobs
    LEVEL_WRITE = "level.write"  # add, replace, delete levels; cancel their jobs
    JOB_SUBMIT = "job.submit"  # submit an overview job
    JOB_READ = "job.read"  # list and read overview jobs and their results
    JOB_CANCEL = "job.cancel"  # cancel an overview job
    KEY_MANAGE = "key.manage"  # create, list, revoke the tenant's keys
    AUDIT_READ = "audit.read"  # GET /v1/audit
    METRICS_READ = "metrics.read"  # GET /metrics (node-wide counters, no tenant's data)
    SCHEMA_READ = "schema.read"  # GET /openapi.json (the REST API's OpenAPI document)


_VIEWER = {Verb.SESSION_READ, Verb.LEVEL_READ, Verb.JOB_READ}
ROLE_VERBS: dict[str, frozenset[Verb]] = {
    "engine": frozenset({Verb.SESSION_CREATE, Verb.SESSION_STREAM, Verb.SESSION_STYLE, Verb.SESSION_CLOSE}),
    "director": frozenset(_VIEWER | {Verb.SESSION_STYLE, Verb.SESSION_TAKE, Verb.JOB_SUBMIT, Verb.JOB_CANCEL}),
    "viewer": frozenset(_VIEWER),
    "admin": frozenset(Verb),
}
ROLES = tuple(ROLE_VERBS)


def allows(role: str, verb: Verb) -> bool:
    return verb in ROLE_VERBS.get(role, ())
