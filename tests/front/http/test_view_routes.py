"""The monitors' routes on a real server (two worker processes, each with its render process): a
picture of a streaming session's camera, a live MJPEG stream that follows it and ends with it,
renders shared among viewers, viewers that go away leaving nothing open, placeholders that say
why there is no picture, and every kind of bad request answered with its 4xx while the session
streams on."""

from __future__ import annotations

import asyncio
import io
import os
import re
import time

import httpx
import numpy as np
import pytest
from PIL import Image

from camdirector.v1 import director_pb2 as pb
from tests.service.test_match_sessions import match_request
from tests.service.wire_client import GrpcRaw, two_target_request, walk

BOUNDARY = b"--camdirector-view"


@pytest.fixture
def streamed(server):
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", two_target_request(seed=4)).session_id
    raw.stream(list(walk(session_id, 20)))
    with httpx.Client(base_url=f"http://{server.http}", timeout=60.0) as http:
        yield raw, http, session_id
    try:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    finally:
        raw.close()


def image_of(reply: httpx.Response) -> Image.Image:
    return Image.open(io.BytesIO(reply.content))


def metric(http: httpx.Client, name: str) -> float:
    found = re.search(rf"^{name} (\S+)$", http.get("/metrics").text, re.MULTILINE)
    return float(found.group(1))


def parts(stream: httpx.Response):
    """(headers, JPEG bytes) of each part of an MJPEG response, as they arrive."""
    buffer = b""
    for chunk in stream.iter_bytes():
        buffer += chunk
        while True:
            start = buffer.find(BOUNDARY)
            head_end = buffer.find(b"\r\n\r\n", start)
            if start < 0 or head_end < 0:
                break
            headers = dict(line.split(": ", 1) for line in buffer[start:head_end].decode().split("\r\n")[1:])
            end = head_end + 4 + int(headers["Content-Length"])
            if len(buffer) < end:
                break
            yield headers, buffer[head_end + 4 : end]
            buffer = buffer[end:]


def test_a_view_is_a_picture_of_the_last_frame_at_the_size_asked(streamed):
    _, http, session_id = streamed
    reply = http.get(f"/v1/sessions/{session_id}/view")
    assert reply.status_code == 200 and reply.headers["content-type"] == "image/jpeg"
    assert reply.headers["x-camdirector-frame"] == "20" and "x-camdirector-placeholder" not in reply.headers
    assert float(reply.headers["x-camdirector-render-ms"]) > 0.0
    assert image_of(reply).size == (320, 180)  # the lens's 16:9
    wide = http.get(f"/v1/sessions/{session_id}/view", params={"width": 640, "format": "png"})
    assert wide.headers["content-type"] == "image/png" and image_of(wide).size == (640, 360)
    assert image_of(http.get(f"/v1/sessions/{session_id}/view", params={"width": 200, "height": 200})).size == (200, 200)
    top = http.get(f"/v1/sessions/{session_id}/topview.png")
    assert top.headers["content-type"] == "image/png"
    x0, z0, x1, z1 = (float(v) for v in top.headers["x-camdirector-bounds-m"].split(","))
    assert x0 < 1.5 < x1 and z0 < 4.0 < z1  # around the pillar


def test_many_viewers_of_one_picture_share_one_render(streamed):
    _, http, session_id = streamed
    http.get(f"/v1/sessions/{session_id}/view")  # the render process is warm
    time.sleep(0.3)
    before = metric(http, "camdirector_view_renders_total")

    async def viewers(n: int) -> list[httpx.Response]:
        async with httpx.AsyncClient(base_url=str(http.base_url), timeout=60.0) as client:
            return await asyncio.gather(*(client.get(f"/v1/sessions/{session_id}/view") for _ in range(n)))

    replies = asyncio.run(viewers(12))
    assert all(r.status_code == 200 for r in replies)
    assert len({r.content for r in replies}) == 1
    renders = metric(http, "camdirector_view_renders_total") - before
    assert 1 <= renders <= 2, f"{renders} renders for 12 viewers of one picture"


def test_a_live_stream_follows_the_session_and_ends_with_it(server):
    """Ten more frames streamed after each part received: every part shows a newer frame than
    the one before (whatever the machine's load), and closing the session ends the stream."""
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", two_target_request(seed=4)).session_id
    raw.stream(list(walk(session_id, 5)))
    frames_seen, fed = [], 5
    with httpx.Client(base_url=f"http://{server.http}", timeout=60.0) as http:
        with http.stream("GET", f"/v1/sessions/{session_id}/view.mjpeg", params={"fps": 8}) as stream:
            assert stream.headers["content-type"] == "multipart/x-mixed-replace; boundary=camdirector-view"
            for headers, jpeg in parts(stream):
                frames_seen.append(int(headers["X-Camdirector-Frame"]))
                assert Image.open(io.BytesIO(jpeg)).size == (320, 180)
                if fed < 95:
                    raw.stream(list(walk(session_id, 10, start_frame=fed + 1)))
                    fed += 10
                elif frames_seen[-1] == 95:
                    raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    raw.close()
    assert frames_seen[0] == 5 and frames_seen[-1] == 95, frames_seen
    assert frames_seen == sorted(frames_seen) and len(set(frames_seen)) >= 5, frames_seen


def test_viewers_that_go_away_leave_no_stream_and_no_socket(streamed, server):
    _, http, session_id = streamed
    front = server.proc.pid
    http.get(f"/v1/sessions/{session_id}/view")
    descriptors = len(os.listdir(f"/proc/{front}/fd"))
    for _ in range(3):
        with httpx.Client(base_url=str(http.base_url), timeout=60.0) as viewer:
            with viewer.stream("GET", f"/v1/sessions/{session_id}/view.mjpeg", params={"fps": 5}) as stream:
                received = parts(stream)  # held: a dropped generator closes the response at once
                next(received)
                assert metric(http, "camdirector_view_streams") >= 1
    deadline = time.monotonic() + 15.0
    while time.monotonic() < deadline and (
        metric(http, "camdirector_view_streams") > 0 or len(os.listdir(f"/proc/{front}/fd")) > descriptors
    ):
        time.sleep(0.2)
    assert metric(http, "camdirector_view_streams") == 0
    assert len(os.listdir(f"/proc/{front}/fd")) <= descriptors


def test_placeholders_say_why_there_is_no_picture(server):
    raw = GrpcRaw(server.grpc)
    with httpx.Client(base_url=f"http://{server.http}", timeout=60.0) as http:
        fresh = raw.call("CreateSession", two_target_request(seed=4)).session_id
        reply = http.get(f"/v1/sessions/{fresh}/view")
        assert reply.status_code == 200 and reply.headers["x-camdirector-placeholder"] == "no camera yet: no frame answered"
        assert image_of(reply).size == (320, 180)
        assert (
            http.get(f"/v1/sessions/{fresh}/view", params={"shot": "cut_before"}).headers["x-camdirector-placeholder"]
            == "no camera yet: no frame answered"
        )
        match = raw.call("CreateSession", match_request(delay_s=5.0)).session_id
        raw.stream([pb.FrameUpdate(session_id=match, frame=1, time_s=0.0)])
        assert http.get(f"/v1/sessions/{match}/view").headers["x-camdirector-placeholder"].startswith("buffering")
        bare = two_target_request(seed=4)
        del bare.objects[:]
        empty = raw.call("CreateSession", bare).session_id
        top = http.get(f"/v1/sessions/{empty}/topview.png")
        assert top.status_code == 200 and "no world geometry" in top.headers["x-camdirector-placeholder"]
        assert "x-camdirector-bounds-m" not in top.headers
        # its camera view: the targets against the sky, under a banner that says there is no world
        raw.stream(
            [
                pb.FrameUpdate(session_id=empty, frame=k, time_s=k / 60.0, states=[u.states[0]])
                for k, u in enumerate(walk(empty, 10), start=1)
            ]
        )  # the walker alone: no cart here
        seen = http.get(f"/v1/sessions/{empty}/view", params={"format": "png"})
        assert seen.headers["x-camdirector-note"].startswith("no world geometry")
        assert "x-camdirector-placeholder" not in seen.headers and seen.headers["x-camdirector-frame"] == "10"
        pixels = np.asarray(image_of(seen).convert("RGB")).astype(int)
        assert np.all(pixels[1, :, :] < 80), "a dark banner across the top"
        orange = (pixels[..., 0] > 90) & (pixels[..., 1] < 0.8 * pixels[..., 0]) & (pixels[..., 2] < 0.35 * pixels[..., 0])
        assert orange[40:].sum() > 200, "the targets are drawn below it"
        for session_id in (fresh, match, empty):
            raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
    raw.close()


@pytest.mark.parametrize(
    "path, params, status, detail",
    [
        ("view", {"width": 2000}, 422, "less than or equal to 1280"),
        ("view", {"width": 8}, 422, "greater than or equal to 16"),
        ("view", {"height": 1000}, 422, "less than or equal to 720"),
        ("view", {"shot": "sideways"}, 422, "'program', 'candidate'"),
        ("view", {"shot": "candidate"}, 422, "a candidate view names the candidate's players"),
        ("view", {"format": "gif"}, 422, "'jpeg' or 'png'"),
        ("view.mjpeg", {"fps": 50}, 422, "less than or equal to 10"),
        ("view.mjpeg", {"fps": 0}, 422, "greater than 0"),
    ],
)
def test_bad_view_requests_are_refused_and_the_session_streams_on(streamed, path, params, status, detail):
    raw, http, session_id = streamed
    reply = http.get(f"/v1/sessions/{session_id}/{path}", params=params)
    assert reply.status_code == status and detail in reply.text, reply.text
    assert raw.stream(list(walk(session_id, 3, start_frame=21)))[-1].frame == 23


@pytest.mark.parametrize("path", ["view", "view.mjpeg", "topview.png"])
def test_unknown_and_closed_sessions_are_404(server, path):
    raw = GrpcRaw(server.grpc)
    closed = raw.call("CreateSession", two_target_request(seed=4)).session_id
    raw.call("CloseSession", pb.CloseSessionRequest(session_id=closed))
    raw.close()
    with httpx.Client(base_url=f"http://{server.http}", timeout=60.0) as http:
        for session_id in ("no-such-session", closed):
            reply = http.get(f"/v1/sessions/{session_id}/{path}")
            assert reply.status_code == 404 and "unknown session id" in reply.json()["detail"]
