"""The monitors' render process (render/monitor.py), real: the picture shows the target in
its colour where the camera projects it, the worker's loop never waits for a render, a render
process that dies fails its pending views and the next view starts another, and what a session's
views hold goes with the session."""

from __future__ import annotations

import io
import os
import signal
import threading
import time

import numpy as np
import pytest
from PIL import Image

from camdirector.geometry.camera import project_to_screen
from camdirector.infra.channels import ViewQuery, decode_view
from camdirector.render.main import RENDERERS_KEPT, TOP_VIEW_MARGIN_M, Painter
from camdirector.render.snapshots import render_job, scene_geometry
from camdirector.server_settings import ServerSettings
from camdirector.worker.table import SessionTable
from load_tests.soak import sample_process
from tests.service.wire_client import two_target_request, walk

REPLY_TIMEOUT_S = 60.0
VIEWED_SESSIONS = 60
MAX_RENDER_PROCESS_GROWTH_MB = 30.0


@pytest.fixture
def table():
    t = SessionTable(ServerSettings(checkpoint_store="off"))
    yield t
    t.close_all()


class Answer:
    """A view's reply, as the worker's reply callback receives it (from another thread)."""

    def __init__(self):
        self.done = threading.Event()
        self.status = self.body = None

    def __call__(self, status: int, body: bytes) -> None:
        self.status, self.body = status, body
        self.done.set()

    def wait(self) -> tuple[dict, np.ndarray]:
        assert self.done.wait(REPLY_TIMEOUT_S), "no answer from the render process"
        assert self.status == 0, self.body
        header, image = decode_view(self.body)
        return header, np.asarray(Image.open(io.BytesIO(image)).convert("RGB"))


def view(table: SessionTable, session_id: str, query: ViewQuery = ViewQuery()) -> Answer:
    answer = Answer()
    table.view(session_id, query, answer)
    return answer


def stream(table: SessionTable, session_id: str, n: int, start: int = 1) -> None:
    for update in walk(session_id, n, start_frame=start):
        table.frame(update)


def orange(pixel) -> bool:
    """The targets' orange (#e07b00) under any shading: red strong, green about half, blue low."""
    r, g, b = (int(c) for c in pixel)
    return r > 90 and 0.3 * r < g < 0.8 * r and b < 0.35 * r


def test_the_program_view_shows_each_target_in_its_colour_where_the_camera_projects_it(table):
    table.create("s", two_target_request(seed=2))
    stream(table, "s", 40)
    header, pixels = view(table, "s").wait()
    session = table.held["s"].session
    job = render_job(session, ViewQuery())
    assert header["frame"] == 40 and header["placeholder"] is None and pixels.shape == (180, 320, 3)
    # The capsules' centres (their transforms' positions), projected by the geometry the rig uses.
    centres = np.array([tf.position_world for tf in session.target_transforms])
    screen = project_to_screen(job.pose, job.lens, centres)
    assert np.all(np.abs(screen) < 0.9), "both targets are framed"
    for x, y in screen:
        col, row = int((x + 1) / 2 * 320), int((1 - y) / 2 * 180)
        assert orange(pixels[row, col]), f"target pixel at ({row}, {col}) is {pixels[row, col]}"
    assert not orange(pixels[2, 2]) and not orange(pixels[177, 317])  # the corners show no target


def test_asking_for_a_view_never_waits_for_the_render(table):
    """The render process stopped (SIGSTOP), a view is asked for and frames go on: the worker's
    loop only queues the snapshot. Resumed, the view is answered with the frame it was asked at."""
    table.create("s", two_target_request(seed=2))
    stream(table, "s", 5)
    view(table, "s").wait()  # started and warm
    pid = table.monitor.pid
    os.kill(pid, signal.SIGSTOP)
    try:
        answer = Answer()
        asked = threading.Thread(target=table.view, args=("s", ViewQuery(), answer))
        asked.start()
        asked.join(timeout=10.0)
        assert not asked.is_alive(), "asking for a view waited for the stopped render process"
        stream(table, "s", 30, start=6)  # the session streams on meanwhile
        assert table.held["s"].session.last_state.frame == 35 and not answer.done.is_set()
    finally:
        os.kill(pid, signal.SIGCONT)
    header, _ = answer.wait()
    assert header["frame"] == 5, "the picture is of the moment it was asked for"


def test_a_render_process_that_dies_fails_what_waits_and_the_next_view_starts_another(table):
    table.create("s", two_target_request(seed=2))
    stream(table, "s", 5)
    view(table, "s").wait()
    pid = table.monitor.pid
    os.kill(pid, signal.SIGSTOP)
    pending = view(table, "s")
    os.kill(pid, signal.SIGKILL)
    assert pending.done.wait(REPLY_TIMEOUT_S)
    assert pending.status == 14 and b"the view renderer exited" in pending.body  # UNAVAILABLE
    deadline = time.monotonic() + 10.0
    while table.monitor.pid == pid and time.monotonic() < deadline:
        time.sleep(0.05)
    header, pixels = view(table, "s").wait()  # a new process, sent the session's meshes again
    assert table.monitor.pid not in (None, pid) and header["frame"] == 5 and pixels.shape == (180, 320, 3)
    stream(table, "s", 5, start=6)
    assert table.held["s"].session.last_state.frame == 10


def test_the_top_view_covers_the_static_world_and_marks_it(table):
    table.create("s", two_target_request(seed=2))
    header, pixels = view(table, "s", ViewQuery(shot="top")).wait()
    # The pillar, a 1 x 3 x 1 m box at (1.5, 4.0): the only static object.
    m = TOP_VIEW_MARGIN_M
    assert header["bounds_m"] == pytest.approx([1.0 - m, 3.5 - m, 2.0 + m, 4.5 + m])
    assert header["media_type"] == "image/png" and header["placeholder"] is None
    h, w, _ = pixels.shape
    assert pixels[h // 2, w // 2].tolist() != pixels[1, 1].tolist(), "the pillar is drawn in the middle, sky at the edge"


def test_a_world_without_static_geometry_gets_a_top_view_placeholder(table):
    request = two_target_request(seed=2)
    del request.objects[:]
    table.create("s", request)
    header, _ = view(table, "s", ViewQuery(shot="top")).wait()
    assert header["bounds_m"] is None and "no world geometry" in header["placeholder"]


def test_a_painter_keeps_few_renderers_and_forgets_a_session_whole(table):
    """In-process Painter: at most RENDERERS_KEPT renderers (sessions x sizes), and a forgotten
    session leaves nothing behind."""
    table.create("s", two_target_request(seed=2))
    stream(table, "s", 3)
    session = table.held["s"].session
    painter = Painter()
    try:
        for k in range(RENDERERS_KEPT + 3):
            painter.add_session(f"s{k}", scene_geometry(session))
            job = render_job(session, ViewQuery(width_px=160 + 16 * (k % 2)))
            job = type(job)(**{**job.__dict__, "session_id": f"s{k}"})
            header, _ = decode_view(painter.render(job))
            assert header["frame"] == 3
            assert len(painter._renderers) <= RENDERERS_KEPT
        painter.render(type(job)(**{**render_job(session, ViewQuery(shot="top")).__dict__, "session_id": "s0"}))
        for k in range(RENDERERS_KEPT + 3):
            painter.forget(f"s{k}")
        assert not painter._renderers and not painter._geometry and not painter._top
    finally:
        painter.close()


def test_sessions_viewed_and_closed_leave_the_render_process_where_it_started(table):
    """Sessions created, streamed, viewed (program and top view) and closed one after another:
    the render process's memory grows by less than MAX_RENDER_PROCESS_GROWTH_MB and its open
    descriptors come back to where they were (each session's renderers, their GL objects and
    meshes, go with it). The first session is a warm-up: the GL driver loads once."""

    def one_session(k: int) -> None:
        session_id = f"s{k}"
        table.create(session_id, two_target_request(seed=k))
        stream(table, session_id, 3)
        view(table, session_id).wait()
        view(table, session_id, ViewQuery(shot="top")).wait()
        table.close(session_id)

    one_session(0)
    pid = table.monitor.pid
    before = sample_process(pid)
    for k in range(1, VIEWED_SESSIONS + 1):
        one_session(k)
    table.create("last", two_target_request(seed=1))
    view(table, "last", ViewQuery(shot="top")).wait()  # answered after every forget before it
    after = sample_process(pid)
    assert table.monitor.pid == pid, "one render process served them all"
    assert after.rss_mb - before.rss_mb < MAX_RENDER_PROCESS_GROWTH_MB, (before, after)
    assert after.open_fds == before.open_fds, (before, after)
