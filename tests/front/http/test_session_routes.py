"""The /v1/sessions routes on a real server (two worker processes): a session streamed over gRPC
shows its frames, cuts and flags; a style PUT over HTTP changes the streaming session as
UpdateStyle does; a MATCH session shows its program, candidates and events, and a take POSTed over
HTTP holds its program until released; every kind of bad request answers its 4xx and the session
keeps working."""

from __future__ import annotations

import io

import grpc
import httpx
import numpy as np
import pytest
from PIL import Image

from camdirector.errors import DirectorError
from camdirector.front.http.routes.sessions import http_error
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.timeline import TIMELINE_FRAMES
from tests.service.test_match_sessions import PLAYERS, match_request
from tests.service.test_match_sessions import frames as match_frames
from tests.service.wire_client import GrpcRaw, two_target_request, walk


@pytest.fixture
def streamed(server):
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", two_target_request(seed=4, style=pb.Style(visibility=pb.FRAMING_ONLY))).session_id
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
        assert frame["framing_error"] == pytest.approx(0.0, abs=1e-4)  # FRAMING_ONLY composes both exactly
    assert frames[0]["cut"]  # the first frame opens the first shot
    assert [f["frame"] for f in http.get(f"/v1/sessions/{session_id}", params={"last": 5}).json()["frames"]] == list(
        range(16, 21)
    )
    newer = http.get(f"/v1/sessions/{session_id}", params={"after_frame": 17}).json()["frames"]
    assert [f["frame"] for f in newer] == [18, 19, 20]  # what a live view has not seen
    assert http.get(f"/v1/sessions/{session_id}", params={"after_frame": 20}).json()["frames"] == []
    listed = http.get("/v1/sessions").json()["sessions"]
    assert session_id in {s["session_id"] for s in listed}


def test_a_style_put_over_http_changes_the_streaming_session(streamed):
    raw, http, session_id, _ = streamed
    reply = http.put(f"/v1/sessions/{session_id}/style", json={"visibility": "RAYCAST", "preferredPhiDeg": 50})
    assert reply.status_code == 200, reply.text
    assert reply.json()["style"] == {"visibility": "RAYCAST", "preferredPhiDeg": 50.0}
    after = raw.stream(list(walk(session_id, 10, start_frame=21)))
    assert all(any(f.startswith("search_") for f in u.diagnostics.flags) for u in after)  # the paper's search now
    detail = http.get(f"/v1/sessions/{session_id}").json()
    assert detail["style"]["visibility"] == "RAYCAST"
    assert any(f.startswith("search_") for f in detail["frames"][-1]["flags"])


@pytest.mark.parametrize(
    "body, status, detail",
    [
        ({"visibility": "NO_SUCH_MODE"}, 422, "not a camdirector.v1.Style"),
        ({"mapResolution": -3}, 422, "not a camdirector.v1.Style"),
        ({"colour": "red"}, 422, "not a camdirector.v1.Style"),
        ({"maxSpeedMS": 0}, 422, "max_speed_m_s"),
        ({"preferredPhiDeg": 500}, 422, "preferred_phi_deg"),
        ({"screenA": {"x": 0.2}, "screenB": {"x": 0.2}}, 422, "must differ"),
        ({"shotSize": "SHOT_SIZE_LONG"}, 422, "TRACKS"),
    ],
)
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
    for query in (
        {"last": 0},
        {"last": TIMELINE_FRAMES + 1},
        {"last": "x"},
        {"after_frame": -1},
        {"after_frame": "x"},
        {"after_frame": 2**63},
    ):
        assert http.get(f"/v1/sessions/{session_id}", params=query).status_code == 422, query
    for body in ([1, 2], "style", None):
        assert http.put(f"/v1/sessions/{session_id}/style", json=body).status_code == 422
    assert (
        http.put(
            f"/v1/sessions/{session_id}/style", content=b"{not json", headers={"content-type": "application/json"}
        ).status_code
        == 422
    )


def test_the_anticipation_map_of_a_map_mode_session(server, streamed):
    _, http, framing_only, _ = streamed
    refused = http.get(f"/v1/sessions/{framing_only}/amap.png")
    assert refused.status_code == 409 and "FRAMING_ONLY" in refused.json()["detail"]
    assert http.get("/v1/sessions/nope/amap.png").status_code == 404
    raw = GrpcRaw(server.grpc)
    session_id = raw.call(
        "CreateSession", two_target_request(seed=4, style=pb.Style(visibility=pb.ANTICIPATION, map_resolution=32))
    ).session_id
    try:
        raw.stream(list(walk(session_id, 20)))
        reply = http.get(f"/v1/sessions/{session_id}/amap.png")
        assert reply.status_code == 200 and reply.headers["content-type"] == "image/png"
        image = np.asarray(Image.open(io.BytesIO(reply.content)).convert("RGB"))
        assert image.shape == (32 * 4, 32 * 4, 3)
        assert (image == (30, 80, 220)).all(axis=-1).sum() >= 20  # the camera's cross is in the window
        red = image[..., 1] < 128  # predicted occluded
        assert red.any() and not red.all(), "the pillar and the cart occlude part of the window, not all"
    finally:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        raw.close()


@pytest.mark.parametrize(
    "code, status",
    [
        (grpc.StatusCode.INVALID_ARGUMENT, 422),
        (grpc.StatusCode.NOT_FOUND, 404),
        (grpc.StatusCode.FAILED_PRECONDITION, 409),
        (grpc.StatusCode.UNAVAILABLE, 503),
        (grpc.StatusCode.INTERNAL, 500),
    ],
)
def test_wire_errors_keep_their_message_as_http_errors(code, status):
    error = http_error(DirectorError(code, "what went wrong"))
    assert (error.status_code, error.detail) == (status, "what went wrong")


@pytest.fixture
def match(server):
    """A MATCH session of four players with a 1 s delay, 90 frames streamed (a kill at frame 60)."""
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", match_request(delay_s=1.0)).session_id
    replies = raw.stream(list(match_frames(session_id, 90, kill_at={59: ("a0", "b0")})))
    with httpx.Client(base_url=f"http://{server.http}", timeout=30.0) as http:
        yield raw, http, session_id, replies
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    raw.close()


def test_a_match_session_shows_its_program_candidates_and_events(match):
    _, http, session_id, replies = match
    frames = http.get(f"/v1/sessions/{session_id}").json()["frames"]
    answered = [u for u in replies if not u.buffering]
    assert [f["frame"] for f in frames] == [u.frame for u in answered]  # the buffering frames gave way
    for frame, reply in zip(frames, answered):
        assert frame["buffering"] is False and frame["players"] == list(PLAYERS) and frame["teams"] == [0, 0, 1, 1]
        assert frame["framing_error"] is None  # the MATCH rig does not measure it
        assert frame["shot"] == {
            "subject_ids": list(reply.shot.subject_ids),
            "kind": pb.ShotKind.Name(reply.shot.kind),
            "reason": reply.shot.reason,
            "held": reply.shot.held,
            "replay": None,  # a live shot
            "eyes_id": reply.shot.eyes_id,
        }
        assert [c["shot"]["subject_ids"] for c in frame["candidates"]] == [list(c.shot.subject_ids) for c in reply.candidates]
        for candidate, sent in zip(frame["candidates"], reply.candidates):
            p = sent.pose.position
            assert candidate["camera"] == pytest.approx([p.x, p.y, p.z], abs=1e-4)
            assert candidate["score"] == pytest.approx(sent.score, abs=1e-4)
    kills = [(f["frame"], e) for f in frames for e in f["events"]]
    assert [(frame, e["kind"], e["actor_id"], e["other_actor_id"]) for frame, e in kills] == [
        (60, "EVENT_KILL", "a0", "b0")
    ]  # at the program's moment of the kill


def test_a_take_over_rest_holds_the_program_until_released(match):
    raw, http, session_id, _ = match
    taken = http.post(f"/v1/sessions/{session_id}/take", json={"subject_ids": ["a1", "b1"], "kind": "SHOT_DUEL"})
    assert taken.status_code == 200, taken.text
    assert taken.json() == {
        "session_id": session_id,
        "shot": {
            "subject_ids": ["a1", "b1"],
            "kind": "SHOT_DUEL",
            "reason": "take: a human's choice, held until released",
            "held": True,
        },
    }
    held = raw.stream(list(match_frames(session_id, 60, start=90)))
    assert all(list(u.shot.subject_ids) == ["a1", "b1"] and u.shot.held for u in held)
    assert http.get(f"/v1/sessions/{session_id}", params={"last": 1}).json()["frames"][0]["shot"]["subject_ids"] == ["a1", "b1"]
    released = http.post(f"/v1/sessions/{session_id}/take", json={"release": True})
    assert released.status_code == 200 and released.json() == {"session_id": session_id, "shot": None}
    after = raw.stream(list(match_frames(session_id, 10, start=150)))
    assert not any(u.shot.held for u in after)


@pytest.mark.parametrize(
    "body, status, detail",
    [
        ({"subject_ids": ["zz"]}, 404, "'zz' is not a player"),
        ({"subject_ids": ["a0", "a0"]}, 422, "twice"),
        ({"subject_ids": ["a0"], "kind": "SHOT_DUEL"}, 422, "cannot show 1"),
        ({"subject_ids": ["a0"], "kind": "SHOT_CLOSEUP"}, 422, "not a camdirector.v1.TakeShotRequest"),
        ({"subjectIds": "a0"}, 422, "not a camdirector.v1.TakeShotRequest"),
        ({"release": "yes"}, 422, "not a camdirector.v1.TakeShotRequest"),
        ({"who": "a0"}, 422, "not a camdirector.v1.TakeShotRequest"),
        ({}, 422, "names its subject_ids"),
        ({"sessionId": "other", "subject_ids": ["a0"]}, 422, "the session is the path's"),
        ([["a0"]], 422, "dict"),
    ],
)
def test_bad_takes_answer_4xx_and_the_match_streams_on(match, body, status, detail):
    raw, http, session_id, _ = match
    reply = http.post(f"/v1/sessions/{session_id}/take", json=body)
    assert reply.status_code == status and detail in str(reply.json()["detail"]), reply.text
    after = raw.stream(list(match_frames(session_id, 3, start=90)))
    assert [u.frame for u in after] == [61, 62, 63] and not any(u.stale or u.shot.held for u in after)


def test_a_take_for_an_unknown_session_or_another_rig(streamed):
    _, http, toric_session, _ = streamed
    unknown = http.post("/v1/sessions/nope/take", json={"subject_ids": ["a"]})
    assert unknown.status_code == 404 and "unknown session id 'nope'" in unknown.json()["detail"]
    refused = http.post(f"/v1/sessions/{toric_session}/take", json={"subject_ids": ["a"]})
    assert refused.status_code == 409 and "RIG_MATCH" in refused.json()["detail"]
    assert (
        http.post(
            f"/v1/sessions/{toric_session}/take", content=b"{not json", headers={"content-type": "application/json"}
        ).status_code
        == 422
    )
