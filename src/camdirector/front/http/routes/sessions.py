"""REST routes of the live sessions, for the dashboard and operations tools.

    GET /v1/sessions                      {"sessions": [summary, ...]}
    GET /v1/sessions/{id}?last=N&after_frame=F   {"session": summary, "style": Style, "frames": [...],
                                          "roster": [...]}
    GET /v1/sessions/{id}/amap.png        the map modes' anticipation map around the camera now
    PUT /v1/sessions/{id}/style           body: a camdirector.v1.Style in protobuf's JSON mapping
                                          -> {"session_id", "style"}; as UpdateStyle on the wire
    POST /v1/sessions/{id}/take           body: a camdirector.v1.TakeShotRequest in protobuf's JSON
                                          mapping without session_id ({"subject_ids": [..],
                                          "kind": "SHOT_DUEL", "release": false}) -> {"session_id",
                                          "shot": the shot held, null after a release}; as TakeShot

A summary is the router's (worker, frames, streams, idle and age in s, transports); frames are the
session's timeline (`timeline.py`): camera position and view direction, target aim points, cut,
shot id, visibility, framing error, the flags that say why the camera moved, compute time; a
MATCH session's also the program's shot, the candidate shots, the players and their teams, the
game events and the planned next cut (while its broadcast delay fills, frames without a camera).
The frames name targets by id; the roster gives each its display name and team name once per
answer (names are a game's text: a viewer shows them as text, never as markup). A style sent
here replaces the session's whole style, exactly as `UpdateStyle` does (and is recorded the same
way), so the client streaming the session sees the change on its next frame. A take (a MATCH
session's, the dashboard's take button) holds a human's shot from the program's next frame until
released.

Errors as on the wire, with the same messages: an unknown session 404, a style the rig refuses 422
(INVALID_ARGUMENT) or 409 (FAILED_PRECONDITION), a body that is not a Style 422, one that
is not JSON at all 400; a take naming an unknown player 404, for a session of another rig 409, a
body that is not a TakeShotRequest (or names a session) or a kind that does not fit its players 422;
a worker lost while answering 503.
"""

from __future__ import annotations

from typing import Annotated, Any

import grpc
import orjson
from fastapi import APIRouter, Body, Depends, HTTPException, Query, Response
from google.protobuf import json_format
from pydantic import BaseModel, Field

from camdirector.access.guard import Identity
from camdirector.access.roles import Verb
from camdirector.errors import DirectorError
from camdirector.front.http.auth import require
from camdirector.front.router import SessionRouter
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.timeline import TIMELINE_FRAMES

_HTTP_STATUS = {
    grpc.StatusCode.INVALID_ARGUMENT: 422,
    grpc.StatusCode.NOT_FOUND: 404,
    grpc.StatusCode.FAILED_PRECONDITION: 409,
    grpc.StatusCode.RESOURCE_EXHAUSTED: 429,
    grpc.StatusCode.UNIMPLEMENTED: 501,
    grpc.StatusCode.UNAVAILABLE: 503,
}
_WORKER_LOST = {"description": "the worker holding the session died while answering; the session is gone"}


class SessionSummary(BaseModel):
    session_id: str
    worker: int = Field(description="worker process slot holding it")
    frames: int = Field(description="frames answered")
    streams: int = Field(description="frame streams attached now")
    idle_s: float = Field(description="since its client's last request, s")
    age_s: float = Field(description="since it was created, s")
    transports: list[str]


class SessionList(BaseModel):
    sessions: list[SessionSummary]


class ShotOut(BaseModel):
    subject_ids: list[str] = Field(description="players shown")
    kind: str = Field(description="camdirector.v1.ShotKind name (SHOT_DUEL, SHOT_FOLLOW, SHOT_GROUP, SHOT_OVERVIEW)")
    reason: str
    held: bool = Field(False, description="a human's take (or its fallback), kept until released")


class CandidateOut(BaseModel):
    shot: ShotOut
    score: float = Field(ge=0.0, description="the director's interest, comparable within one frame")
    camera: list[float] = Field(description="its camera position, m")
    forward: list[float] = Field(description="its unit view direction")


class GameEventOut(BaseModel):
    time_s: float = Field(description="game time, s")
    kind: str = Field(description="camdirector.v1.EventKind name (EVENT_KILL, ...)")
    actor_id: str = Field(description="for a kill, the attacker")
    other_actor_id: str = Field(description="for a kill, the victim")
    priority: int = Field(ge=0, le=15, description="as sent; 0: the kind's default")
    label: str


class PlannedCutOut(BaseModel):
    time_s: float = Field(description="program time of the cut, s")
    shot: ShotOut


class TimelineFrameOut(BaseModel):
    frame: int
    time_s: float
    camera: list[float] | None = Field(description="camera position, m; null while a MATCH session buffers")
    forward: list[float] | None = Field(description="unit view direction; null while a MATCH session buffers")
    targets: list[list[float]] = Field(description="aim point of each target (MATCH: each player), m")
    cut: bool
    shot_id: int
    visibility: float = Field(ge=0.0, le=1.0)
    framing_error: float | None = Field(
        description=(
            "how far the framed points land from where the style puts them, normalised screen units (the frame is "
            "[-1, 1], so above 1 they may be out of it); null when the rig does not measure it (MATCH) or a point "
            "is behind the camera"
        )
    )
    flags: list[str] = Field(description="why the camera moved or degraded (search_cut, pulled_in, ...)")
    scores: dict[str, float] = Field(
        description="TRACKS: sub-scores in [0, 1] of the target chosen, and their total; MATCH: the shot's"
    )
    compute_ms: float
    # MATCH sessions only (timeline.py): the program, what the director could cut to, and what it plans
    buffering: bool | None = Field(None, description="the broadcast delay is still filling: no camera")
    shot: ShotOut | None = Field(None, description="the program's shot")
    candidates: list[CandidateOut] | None = Field(None, description="the best other shots now")
    players: list[str] | None = Field(None, description="player ids in target order")
    teams: list[int] | None = Field(None, description="each player's team, in target order")
    events: list[GameEventOut] | None = Field(None, description="game events at this program moment")
    planned_cut: PlannedCutOut | None = Field(None, description="the director's next planned cut, if any")


class RosterEntryOut(BaseModel):
    id: str = Field(description="the target's id, as the frames name it")
    display_name: str = Field(description="the name shown to people, as the client sent it; empty: show the id")
    team: int = Field(ge=0, description="MATCH: the player's team")
    team_name: str = Field(description="MATCH: the team's name as sent; may be empty")


class SessionDetail(BaseModel):
    session: SessionSummary
    style: dict[str, Any] = Field(description="camdirector.v1.Style as last sent, protobuf JSON")
    frames: list[TimelineFrameOut] = Field(description="oldest first")
    roster: list[RosterEntryOut] = Field(
        description="the targets (MATCH: the players) in target order with their names: untrusted text, show it as text"
    )


class StyleChanged(BaseModel):
    session_id: str
    style: dict[str, Any]


class ShotTaken(BaseModel):
    session_id: str
    shot: ShotOut | None = Field(description="the shot now held until released; null after a release")


def http_error(exc: DirectorError) -> HTTPException:
    """A wire error as an HTTP error with the same message (500 for INTERNAL and anything unlisted)."""
    return HTTPException(status_code=_HTTP_STATUS.get(exc.code, 500), detail=exc.message)


def build_session_router(router: SessionRouter) -> APIRouter:
    routes = APIRouter(prefix="/v1/sessions", tags=["sessions"])

    @routes.get("", response_model=SessionList)
    async def list_sessions(identity: Annotated[Identity, Depends(require(Verb.SESSION_READ))]) -> dict:
        """The tenant's open sessions: worker, frames answered, streams attached, idle time."""
        # async: run on the event loop that adds and removes sessions, not beside it in a thread
        return {"sessions": router.describe(identity.tenant)}

    @routes.get(
        "/{session_id}", response_model=SessionDetail, responses={404: {"description": "no such session"}, 503: _WORKER_LOST}
    )
    async def get_session(
        session_id: str,
        identity: Annotated[Identity, Depends(require(Verb.SESSION_READ))],
        last: Annotated[int, Query(ge=1, le=TIMELINE_FRAMES, description="newest frames wanted")] = TIMELINE_FRAMES,
        after_frame: Annotated[
            int | None,
            Query(
                ge=0, le=2**63 - 1, description=("only frames numbered above this (a live view asks for what it has not seen)")
            ),
        ] = None,
    ) -> Response:
        """One session: summary, style, and its newest frames with why the camera moved."""
        try:
            detail = await router.timeline(session_id, last, after_frame, identity.tenant)
        except DirectorError as exc:
            raise http_error(exc) from None
        # Sent as is: validating 600 frames against the model would hold the front's event loop,
        # which routes every session's frames, for milliseconds.
        return Response(orjson.dumps(detail), media_type="application/json")

    @routes.get(
        "/{session_id}/amap.png",
        response_class=Response,
        responses={
            200: {"content": {"image/png": {}}},
            404: {"description": "no such session"},
            409: {"description": "the session's style builds no anticipation map"},
            503: _WORKER_LOST,
        },
    )
    async def get_anticipation_map(
        session_id: str, identity: Annotated[Identity, Depends(require(Verb.SESSION_READ))]
    ) -> Response:
        """The occlusion anticipation map around the camera now (map_view.py): rows theta,
        columns phi, white visible to red occluded, the camera crossed in blue."""
        try:
            png = await router.anticipation_png(session_id, identity.tenant)
        except DirectorError as exc:
            raise http_error(exc) from None
        return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})

    @routes.put(
        "/{session_id}/style",
        response_model=StyleChanged,
        responses={
            400: {"description": "the body cannot be read as JSON"},
            404: {"description": "no such session"},
            409: {"description": "the session's rig cannot take this style"},
            422: {"description": "not a Style, or a value out of range"},
            503: _WORKER_LOST,
        },
    )
    async def put_style(
        session_id: str,
        identity: Annotated[Identity, Depends(require(Verb.SESSION_STYLE))],
        style: Annotated[
            dict[str, Any],
            Body(description='camdirector.v1.Style, protobuf JSON (e.g. {"visibility": "RAYCAST", "preferredPhiDeg": 40})'),
        ],
    ) -> dict:
        """Replace the session's style, as UpdateStyle does."""
        try:
            msg = json_format.ParseDict(style, pb.Style())
        except json_format.ParseError as exc:
            raise HTTPException(status_code=422, detail=f"not a camdirector.v1.Style: {exc}") from None
        try:
            await router.update_style(
                pb.UpdateStyleRequest(session_id=session_id, style=msg).SerializeToString(), identity.tenant
            )
        except DirectorError as exc:
            raise http_error(exc) from None
        await router.guard.off_loop(router.guard.audit, identity, "style", session_id, {"style": style, "via": "http"})
        return {"session_id": session_id, "style": json_format.MessageToDict(msg)}

    @routes.post(
        "/{session_id}/take",
        response_model=ShotTaken,
        responses={
            400: {"description": "the body cannot be read as JSON"},
            404: {"description": "no such session, or a subject that is not one of its players"},
            409: {"description": "not a MATCH session"},
            422: {"description": "not a TakeShotRequest, or a kind that does not fit the subjects"},
            503: _WORKER_LOST,
        },
    )
    async def take_shot(
        session_id: str,
        identity: Annotated[Identity, Depends(require(Verb.SESSION_TAKE))],
        take: Annotated[
            dict[str, Any],
            Body(
                description="camdirector.v1.TakeShotRequest without session_id, "
                'protobuf JSON (e.g. {"subject_ids": ["p1", "p6"], '
                '"kind": "SHOT_DUEL"} or {"release": true})'
            ),
        ],
    ) -> dict:
        """Hold a human's shot on a MATCH session's program until released, as TakeShot does."""
        if {"session_id", "sessionId"} & take.keys():
            raise HTTPException(status_code=422, detail="the session is the path's: leave session_id out of the body")
        try:
            msg = json_format.ParseDict(take, pb.TakeShotRequest())
        except json_format.ParseError as exc:
            raise HTTPException(status_code=422, detail=f"not a camdirector.v1.TakeShotRequest: {exc}") from None
        msg.session_id = session_id
        try:
            reply = pb.TakeShotResponse.FromString(await router.take_shot(msg.SerializeToString(), identity.tenant))
        except DirectorError as exc:
            raise http_error(exc) from None
        await router.guard.off_loop(
            router.guard.audit,
            identity,
            "release" if msg.release else "take",
            session_id,
            {"via": "http"}
            if msg.release
            else {"via": "http", "subject_ids": list(msg.subject_ids), "kind": pb.ShotKind.Name(msg.kind)},
        )
        shot = (
            json_format.MessageToDict(reply.shot, preserving_proto_field_name=True, always_print_fields_with_no_presence=True)
            if reply.HasField("shot")
            else None
        )
        return {"session_id": session_id, "shot": shot}

    return routes
