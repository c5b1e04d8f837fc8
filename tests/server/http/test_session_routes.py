"""The /v1/sessions routes on a real server (two worker processes): a session streamed over gRPC
shows its frames, cuts and flags; a style PUT over HTTP changes the streaming session as
UpdateStyle does; every kind of bad request answers its 4xx and the session keeps working."""
from __future__ import annotations

import io

import grpc
import httpx
import numpy as np
import pytest
from PIL import Image

from camdirector.server.errors import DirectorError
from camdirector.server.http.routes.sessions import http_error
from camdirector.server.sessions.timeline import TIMELINE_FRAMES
from camdirector.v1 import director_pb2 as pb
from tests.server.wire_client import GrpcRaw, two_target_request, walk


@pytest.fixture
def streamed(server):
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", two_target_request(seed=4, style=pb.Style(
        visibility=pb.FRAMING_ONLY))).session_id
    replies = raw.stream(list(walk(session_id, 20)))
    with httpx.Client(base_url=f"http://{server.http}", timeout=30.0) as http:
        yield raw, http, session_id, replies
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    raw.close()


def test_a_session_shows_its_frames_and_style(streamed):
    _, http, session_id, replies = streamed
    detail = http.get(f"/v1/sessions/{session_id}").json()
    assert detail["session"]["session_id"] == session_id and detail["session"]["frames"] == 20
    assert detail["style"] == {"visibility": "FRAMING_ONLY"}
    frames = detail["frames"]
    assert [f["frame"] for f in frames] == list(range(1, 21))
    for frame, reply in zip(frames, replies):
        p = reply.pose.position
        assert frame["camera"] == pytest.approx([p.x, p.y, p.z], abs=1e-4)
        assert frame["cut"] == reply.cut and frame["shot_id"] == reply.shot_id
        assert frame["flags"] == list(reply.diagnostics.flags)
        assert np.linalg.norm(frame["forward"]) == pytest.approx(1.0, abs=1e-3)
        assert len(frame["targets"]) == 2
    assert frames[0]["cut"]                           # the first frame opens the first shot
    assert [f["frame"] for f in http.get(f"/v1/sessions/{session_id}", params={"last": 5}).json()["frames"]] \
        == list(range(16, 21))
    newer = http.get(f"/v1/sessions/{session_id}", params={"after_frame": 17}).json()["frames"]
    assert [f["frame"] for f in newer] == [18, 19, 20]                 # what a live view has not seen
    assert http.get(f"/v1/sessions/{session_id}", params={"after_frame": 20}).json()["frames"] == []
    listed = http.get("/v1/sessions").json()["sessions"]
    assert session_id in {s["session_id"] for s in listed}


def test_a_style_put_over_http_changes_the_streaming_session(streamed):
    raw, http, session_id, _ = streamed
    reply = http.put(f"/v1/sessions/{session_id}/style",
                     json={"visibility": "RAYCAST", "preferredPhiDeg": 50})
    assert reply.status_code == 200, reply.text
    assert reply.json()["style"] == {"visibility": "RAYCAST", "preferredPhiDeg": 50.0}
    after = raw.stream(list(walk(session_id, 10, start_frame=21)))
    assert all(any(f.startswith("search_") for f in u.diagnostics.flags) for u in after)  # the paper's search now
    detail = http.get(f"/v1/sessions/{session_id}").json()
    assert detail["style"]["visibility"] == "RAYCAST"
    assert any(f.startswith("search_") for f in detail["frames"][-1]["flags"])


@pytest.mark.parametrize("body, status, detail", [
    ({"visibility": "NO_SUCH_MODE"}, 422, "not a camdirector.v1.Style"),
    ({"mapResolution": -3}, 422, "not a camdirector.v1.Style"),
    ({"colour": "red"}, 422, "not a camdirector.v1.Style"),
    ({"maxSpeedMS": 0}, 422, "max_speed_m_s"),
    ({"preferredPhiDeg": 500}, 422, "preferred_phi_deg"),
    ({"screenA": {"x": 0.2}, "screenB": {"x": 0.2}}, 422, "must differ"),
    ({"shotSize": "SHOT_SIZE_LONG"}, 422, "TRACKS"),
])
def test_bad_styles_answer_4xx_and_change_nothing(streamed, body, status, detail):
    raw, http, session_id, _ = streamed
    reply = http.put(f"/v1/sessions/{session_id}/style", json=body)
    assert reply.status_code == status and detail in reply.json()["detail"], reply.text
    assert http.get(f"/v1/sessions/{session_id}").json()["style"] == {"visibility": "FRAMING_ONLY"}
    after = raw.stream(list(walk(session_id, 3, start_frame=21)))
    assert [u.frame for u in after] == [21, 22, 23] and not any(u.stale for u in after)


def test_unknown_sessions_and_bad_queries(streamed):
    _, http, session_id, _ = streamed
    for reply in (http.get("/v1/sessions/nope"), http.put("/v1/sessions/nope/style", json={})):
        assert reply.status_code == 404 and "unknown session id 'nope'" in reply.json()["detail"]
    for query in ({"last": 0}, {"last": TIMELINE_FRAMES + 1}, {"last": "x"}, {"after_frame": -1},
                  {"after_frame": "x"}, {"after_frame": 2**63}):
        assert http.get(f"/v1/sessions/{session_id}", params=query).status_code == 422, query
    for body in ([1, 2], "style", None):
        assert http.put(f"/v1/sessions/{session_id}/style", json=body).status_code == 422
    assert http.put(f"/v1/sessions/{session_id}/style", content=b"{not json",
                    headers={"content-type": "application/json"}).status_code == 422


def test_the_anticipation_map_of_a_map_mode_session(server, streamed):
    _, http, framing_only, _ = streamed
    refused = http.get(f"/v1/sessions/{framing_only}/amap.png")
    assert refused.status_code == 409 and "FRAMING_ONLY" in refused.json()["detail"]
    assert http.get("/v1/sessions/nope/amap.png").status_code == 404
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", two_target_request(seed=4, style=pb.Style(
        visibility=pb.ANTICIPATION, map_resolution=32))).session_id
    try:
        raw.stream(list(walk(session_id, 20)))
        reply = http.get(f"/v1/sessions/{session_id}/amap.png")
        assert reply.status_code == 200 and reply.headers["content-type"] == "image/png"
        image = np.asarray(Image.open(io.BytesIO(reply.content)).convert("RGB"))
        assert image.shape == (32 * 4, 32 * 4, 3)
        assert (image == (30, 80, 220)).all(axis=-1).sum() >= 20          # the camera's cross is in the window
        red = image[..., 1] < 128                                           # predicted occluded
        assert red.any() and not red.all(), "the pillar and the cart occlude part of the window, not all"
    finally:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        raw.close()


@pytest.mark.parametrize("code, status", [(grpc.StatusCode.INVALID_ARGUMENT, 422), (grpc.StatusCode.NOT_FOUND, 404),
                                          (grpc.StatusCode.FAILED_PRECONDITION, 409),
                                          (grpc.StatusCode.UNAVAILABLE, 503), (grpc.StatusCode.INTERNAL, 500)])
def test_wire_errors_keep_their_message_as_http_errors(code, status):
    error = http_error(DirectorError(code, "what went wrong"))
    assert (error.status_code, error.detail) == (status, "what went wrong")
