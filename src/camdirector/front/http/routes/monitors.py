"""REST routes of the monitors: what a session's camera sees (issue 16).

    GET /v1/sessions/{id}/view         one picture (JPEG or PNG) of the program camera now, of a
                                       MATCH session's candidate shot (shot=candidate&subjects=p1,p6),
                                       or of the last cut (shot=cut_before | cut_after)
    GET /v1/sessions/{id}/view.mjpeg   the same as a live stream: MJPEG (multipart/x-mixed-replace)
                                       at `fps` frames a second, a new part when the picture changes
    GET /v1/sessions/{id}/topview.png  the world from straight above, made once per session; its
                                       world rectangle in the X-Camdirector-Bounds-M header
                                       ("x0,z0,x1,z1", m; x across, z down the image)

Pictures are rendered in the worker's render process (render/main.py), never in the frame
path, and shared among viewers (front/view_hub.py). Headers: X-Camdirector-Frame (the session frame
shown), X-Camdirector-Render-Ms, and X-Camdirector-Placeholder with the reason when the picture
is a placeholder (no camera yet, a delay still filling, no such candidate, no cut yet, a world
without geometry): still 200, so a monitor keeps its place. A camera view labels the players in it
with their names (render/snapshots.py) and lists those labels, nearest last, in
X-Camdirector-Labels: a JSON array of strings, non-ASCII escaped (a header is ASCII).

The live stream is MJPEG rather than a WebSocket: an <img> shows it with no script, any HTTP
client or video tool (ffmpeg, VLC) reads it, it passes every proxy that passes HTTP, and its one
direction is all a monitor needs. Its cost is a connection per stream (a browser allows six per
host), so the dashboard streams the program monitor only and refreshes the others as pictures.

Errors: an unknown or closed session 404; a size over its limit or an unknown shot 422; more
than MAX_STREAMS live streams, or than the tenant's share of them, 429; a render that fails or
takes more than RENDER_TIMEOUT_S, or a worker lost, 503.
"""

from __future__ import annotations

import json
import math
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Query, Response
from fastapi.responses import StreamingResponse

from camdirector.access.guard import Identity
from camdirector.access.roles import Verb
from camdirector.errors import DirectorError, invalid
from camdirector.front.http.auth import require
from camdirector.front.http.routes.sessions import http_error
from camdirector.front.view_hub import MAX_STREAM_FPS, View, ViewHub
from camdirector.infra.channels import DEFAULT_WIDTH_PX, MAX_HEIGHT_PX, MAX_WIDTH_PX, MIN_SIDE_PX, ViewQuery

BOUNDARY = "camdirector-view"
DEFAULT_FPS = 4.0
_ERRORS: dict[int | str, dict[str, Any]] = {
    404: {"description": "no such session (or it closed)"},
    422: {"description": "a size over its limit, or an unknown shot"},
    503: {"description": "the render failed or timed out, or the worker holding the session died"},
}

Shot = Literal["program", "candidate", "cut_before", "cut_after"]
Width = Annotated[int, Query(ge=MIN_SIDE_PX, le=MAX_WIDTH_PX, description="picture width, px")]
Height = Annotated[
    int | None,
    Query(
        ge=MIN_SIDE_PX, le=MAX_HEIGHT_PX, description=("picture height, px; left out: the width over the session lens's aspect")
    ),
]
Subjects = Annotated[
    str, Query(max_length=4096, description=("shot=candidate: the candidate's players, comma-separated, in any order"))
]


def _headers(view: View) -> dict[str, str]:
    headers = {"Cache-Control": "no-store", "X-Camdirector-Render-Ms": f"{view.render_ms:.3f}"}
    if view.frame is not None:
        headers["X-Camdirector-Frame"] = str(view.frame)
    if view.placeholder is not None:
        headers["X-Camdirector-Placeholder"] = view.placeholder
    if view.note is not None:
        headers["X-Camdirector-Note"] = view.note
    if view.bounds_m is not None:
        headers["X-Camdirector-Bounds-M"] = ",".join(f"{v:.4f}" for v in view.bounds_m)
    if view.labels:  # names from a game: JSON with every non-ASCII character escaped, as a header must be
        headers["X-Camdirector-Labels"] = json.dumps(view.labels, ensure_ascii=True)
    return headers


def _query(shot: str, subjects: str, width: int, height: int | None, image_format: str) -> ViewQuery:
    try:
        return ViewQuery(
            shot=shot,
            subjects=tuple(s for s in subjects.split(",") if s),
            width_px=width,
            height_px=height,
            image_format=image_format,
        )
    except ValueError as exc:
        raise http_error(invalid(str(exc))) from None


def build_view_router(hub: ViewHub) -> APIRouter:
    routes = APIRouter(prefix="/v1/sessions", tags=["monitors"])

    async def picture(session_id: str, query: ViewQuery, max_age_s: float, identity: Identity) -> View:
        try:
            return await hub.get(session_id, query, max_age_s, identity.tenant)
        except DirectorError as exc:
            raise http_error(exc) from None

    @routes.get(
        "/{session_id}/view",
        response_class=Response,
        responses={200: {"content": {"image/jpeg": {}, "image/png": {}}}, **_ERRORS},
    )
    async def get_view(
        session_id: str,
        identity: Annotated[Identity, Depends(require(Verb.SESSION_READ))],
        shot: Shot = "program",
        subjects: Subjects = "",
        width: Width = DEFAULT_WIDTH_PX,
        height: Height = None,
        format: Literal["jpeg", "png"] = "jpeg",
    ) -> Response:  # noqa: A002 - the query's name
        """What the session's camera (or a candidate's, or the last cut's) sees, rendered now or
        shared with another viewer's render of the same picture made within a tenth of a second."""
        view = await picture(session_id, _query(shot, subjects, width, height, format), 0.1, identity)
        return Response(view.image, media_type=view.media_type, headers=_headers(view))

    @routes.get(
        "/{session_id}/view.mjpeg",
        response_class=StreamingResponse,
        responses={
            200: {"content": {f"multipart/x-mixed-replace; boundary={BOUNDARY}": {}}},
            429: {"description": "too many live streams, on the node or of the caller's tenant"},
            **_ERRORS,
        },
    )
    async def stream_view(
        session_id: str,
        identity: Annotated[Identity, Depends(require(Verb.SESSION_READ))],
        shot: Shot = "program",
        subjects: Subjects = "",
        width: Width = DEFAULT_WIDTH_PX,
        height: Height = None,
        fps: Annotated[float, Query(gt=0.0, le=MAX_STREAM_FPS, description="frames a second")] = DEFAULT_FPS,
    ) -> StreamingResponse:
        """The view as a live MJPEG stream (module docstring), until the session ends."""
        query = _query(shot, subjects, width, height, "jpeg")
        first = await picture(session_id, query, 0.5 / fps, identity)  # a 404 before the stream starts
        try:
            hub.check_stream_room(identity.tenant)
        except DirectorError as exc:
            raise http_error(exc) from None

        async def parts():
            async for view in hub.stream(session_id, query, fps, first, identity.tenant):
                head = (
                    f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(view.image)}\r\n"
                    + "".join(f"{k}: {v}\r\n" for k, v in _headers(view).items() if k.startswith("X-"))
                    + "\r\n"
                )
                yield head.encode() + view.image + b"\r\n"

        return StreamingResponse(
            parts(), media_type=f"multipart/x-mixed-replace; boundary={BOUNDARY}", headers={"Cache-Control": "no-store"}
        )

    @routes.get(
        "/{session_id}/topview.png",
        response_class=Response,
        responses={200: {"content": {"image/png": {}}}, 404: _ERRORS[404], 503: _ERRORS[503]},
    )
    async def get_top_view(session_id: str, identity: Annotated[Identity, Depends(require(Verb.SESSION_READ))]) -> Response:
        """The session's static world (objects and level) from straight above, made once."""
        view = await picture(session_id, ViewQuery(shot="top"), math.inf, identity)
        headers = _headers(view)
        headers["Access-Control-Expose-Headers"] = "X-Camdirector-Bounds-M"
        return Response(view.image, media_type=view.media_type, headers=headers)

    return routes
