"""The dashboard in a real browser (Debian's Chromium, driven by Playwright) against a real server: a
director finds a streaming session, sees its frames, shots and why the camera moved, where along the
camera's trail its framing was lost and by how much, changes its style live (and the streaming
client gets the new style on its next frame), sees a refused style's reason and, in a map mode, the
anticipation map; on the tracks rig, the scores of the targets it chose; in a match, the candidates,
a take held until released (the streaming client gets it), the fallback's reason when the held
player dies, the event log and, with a delay, the cut the director plans, which the program then
makes; and submits a motion overview job, then watches its preview and contact sheet.

Where Chromium is absent (a clone without root, so `make test` could not install it) the tests skip
with the reason; `.ci/run` sets CAMDIRECTOR_REQUIRE_BROWSER=1, which makes that a failure.
"""
from __future__ import annotations

import os
import re
import shutil
import time

import httpx
import numpy as np
import pytest

from camdirector.v1 import director_pb2 as pb
from tests.precompute.tracks.tiny_levels import corridor
from tests.server.test_match_sessions import PLAYERS, RATE_HZ, match_request
from tests.server.test_match_sessions import frames as match_frames
from tests.server.tracks_sessions import actor_frames, corridor_walk, obj_text, tracks_request
from tests.server.wire_client import GrpcRaw, box_object, two_target_request, walk

playwright = pytest.importorskip("playwright.sync_api")

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
TIMEOUT_MS = 20_000


@pytest.fixture(scope="module")
def browser():
    if CHROMIUM is None:
        if os.environ.get("CAMDIRECTOR_REQUIRE_BROWSER") == "1":
            pytest.fail("Chromium is required (CAMDIRECTOR_REQUIRE_BROWSER=1): scripts/system-deps.sh installs it as root")
        pytest.skip("no Chromium here: `make test` installs Debian's chromium when run as root")
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True)
        yield browser
        browser.close()


@pytest.fixture
def page(browser, server):
    context = browser.new_context()
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(f"http://{server.http}/")                     # redirected to /dashboard/
    yield page
    context.close()
    assert not errors, f"the page raised: {errors}"


def canvas_has_drawing(page, selector: str) -> bool:
    return page.eval_on_selector(selector, """c => {
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        for (let i = 3; i < d.length; i += 4) if (d[i] > 0) return true;
        return false; }""")


def test_watch_a_session_and_change_its_style_live(server, page):
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", two_target_request(seed=5, style=pb.Style(
        visibility=pb.FRAMING_ONLY))).session_id
    raw.stream(list(walk(session_id, 90)))
    try:
        assert page.url.endswith("/dashboard/")
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        playwright.expect(page.locator("#session-id")).to_have_text(session_id)
        playwright.expect(page.locator("#shot-summary")).to_contain_text("frames 1–90: 1 shots, 1 cuts")
        playwright.expect(page.locator("#why li").first).to_contain_text("frame 90")
        playwright.expect(page.locator("#why li").last).to_contain_text("cut at frame 1 to shot")
        assert canvas_has_drawing(page, "#topview") and canvas_has_drawing(page, "#timeline")
        playwright.expect(page.locator("#style-json")).to_contain_text('"visibility": "FRAMING_ONLY"')

        page.select_option('#style-form select[name="visibility"]', "RAYCAST")
        page.fill('#style-form input[name="preferredPhiDeg"]', "50")
        page.click("#style-form button[type=submit]")
        playwright.expect(page.locator("#style-result")).to_have_text("applied")
        after = raw.stream(list(walk(session_id, 10, start_frame=91)))
        assert all(any(f.startswith("search_") for f in u.diagnostics.flags) for u in after)
        playwright.expect(page.locator("#why li").first).to_contain_text("search_")
        playwright.expect(page.locator("#style-json")).to_contain_text('"preferredPhiDeg": 50')

        page.fill('#style-form input[name="preferredPhiDeg"]', "500")      # the form's own limit holds it back
        page.click("#style-form button[type=submit]")
        assert page.eval_on_selector('#style-form input[name="preferredPhiDeg"]', "i => !i.validity.valid")
        page.fill('#style-form input[name="preferredPhiDeg"]', "50")
        page.fill('#style-form input[name="maxSpeedMS"]', "0")              # the server refuses it
        page.click("#style-form button[type=submit]")
        playwright.expect(page.locator("#style-result")).to_contain_text("422")
        playwright.expect(page.locator("#style-result")).to_contain_text("max_speed_m_s")
        assert page.get_attribute("#style-result", "class") == "error"
        more = raw.stream(list(walk(session_id, 3, start_frame=101)))     # the session goes on as it was
        assert [u.frame for u in more] == [101, 102, 103] and all(
            any(f.startswith("search_") for f in u.diagnostics.flags) for u in more)

        playwright.expect(page.locator("#amap-figure")).to_be_hidden()      # RAYCAST builds no map
        page.fill('#style-form input[name="maxSpeedMS"]', "")
        page.select_option('#style-form select[name="visibility"]', "ANTICIPATION")
        page.click("#style-form button[type=submit]")
        playwright.expect(page.locator("#style-result")).to_have_text("applied")
        raw.stream(list(walk(session_id, 10, start_frame=104)))
        playwright.expect(page.locator("#amap-figure")).to_be_visible()
        page.wait_for_function("document.querySelector('#amap').naturalWidth === 256")  # 64 texels, 4 px each
    finally:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        raw.close()
    playwright.expect(page.locator("#shot-summary")).to_have_text("the session has ended")


FRAMING_RGB = (0xE0, 0x40, 0xFB)   # dashboard.js FRAMING_COLOUR: the strip's framing line and the top view's marks


def framing_pixels(page, selector: str) -> tuple[int, int | None]:
    """How many pixels of a canvas are drawn in the framing colour, and the topmost row holding one
    (None when none is)."""
    return tuple(page.eval_on_selector(selector, """(c, [r, g, b]) => {
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let count = 0, top = null;
        for (let i = 0; i < d.length; i += 4) {
            if (Math.abs(d[i] - r) + Math.abs(d[i + 1] - g) + Math.abs(d[i + 2] - b) < 24 && d[i + 3] > 0) {
                count += 1;
                if (top === null) top = Math.floor(i / 4 / c.width);
            }
        }
        return [count, top]; }""", list(FRAMING_RGB)))


def test_a_director_sees_where_the_framing_was_lost(server, page):
    """A REACTIVE session, its two targets standing still: a wall slides onto the line from A to the
    camera, 30 % of the way from A; the rig pulls the camera in front of it, A stays on its point and
    B leaves the frame (framing error 0.93, against 0 before)."""
    wall_size = (2.5, 2.5, 0.1)
    parked = (100.0, 1.5, 100.0)
    request = two_target_request(seed=6, style=pb.Style(visibility=pb.REACTIVE))
    del request.objects[:]                                                 # no pillar or cart: only the wall
    request.objects.append(box_object("wall", parked, wall_size, dynamic=True))
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", request).session_id

    def wall_at(first: int, n: int, position, yaw_rad: float = 0.0) -> list[pb.FrameUpdate]:
        return [pb.FrameUpdate(session_id=session_id, frame=i, time_s=i / 60.0, states=[pb.ObjectState(
            id="wall", transform=pb.Transform(position=pb.Vec3(x=position[0], y=position[1], z=position[2]),
                                              rotation=pb.Quat(y=np.sin(yaw_rad / 2), w=np.cos(yaw_rad / 2))))])
                for i in range(first, first + n)]

    try:
        clear = raw.stream(wall_at(1, 40, parked))
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        summary = page.locator("#shot-summary")
        playwright.expect(summary).to_contain_text("frames 1–40")
        playwright.expect(summary).to_contain_text("framing error 0.00 now, at most 0.00, lost (above 0.5) in 0 frames")
        assert framing_pixels(page, "#topview")[0] == 0                 # nothing lost: no mark
        clear_line = framing_pixels(page, "#timeline")
        assert clear_line[0] > 0                                         # the error's line, along the band's floor

        p = clear[-1].pose.position
        a_world, camera_world = np.array([0.0, 1.5, 0.0]), np.array([p.x, p.y, p.z])
        spot = a_world + 0.3 * (camera_world - a_world)
        to_camera = camera_world - a_world
        yaw_rad = np.arctan2(to_camera[0], to_camera[2])                    # the wall square to the line
        blocked = raw.stream(wall_at(41, 40, spot, yaw_rad))
        assert all("pulled_in" in u.diagnostics.flags for u in blocked)
        frames = httpx.get(f"http://{server.http}/v1/sessions/{session_id}", timeout=30.0).json()["frames"]
        lost = [f["framing_error"] for f in frames if f["framing_error"] > 0.5]
        assert len(lost) == 40 and min(lost) > 0.8                        # B is out of the frame
        playwright.expect(summary).to_contain_text("frames 1–80")
        playwright.expect(summary).to_contain_text(
            f"framing error {frames[-1]['framing_error']:.2f} now, at most {max(lost):.2f}, lost (above 0.5) in 40 frames")
        assert framing_pixels(page, "#topview")[0] > 0                   # the pulled-in camera places are marked
        assert framing_pixels(page, "#timeline")[1] < clear_line[1]      # the error's line rose off the floor
    finally:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        raw.close()


def test_submit_an_overview_job_and_watch_its_preview(server, page, shared_data, tmp_path):
    page.set_input_files('#overview-form input[name="file"]',
                         str(shared_data / "mocap/bandai_namco/dataset-1_run_active_001.bvh"))
    page.click("#overview-form button[type=submit]")
    playwright.expect(page.locator("#overview-result")).to_contain_text("queued")
    job_id = page.text_content("#overview-result").split()[1]
    row = page.locator(f'#jobs tbody tr[data-job="{job_id}"]')
    playwright.expect(row.locator("td[data-status]")).to_have_text("succeeded", timeout=120_000)
    playwright.expect(row).to_contain_text("dataset-1_run_active_001.bvh")
    row.locator("button").click()
    page.wait_for_function("document.querySelector('#job-sheet').naturalWidth > 0")
    page.wait_for_function("document.querySelector('#job-video').readyState >= 1")  # metadata of the H.264 file
    assert page.eval_on_selector("#job-video", "v => v.duration") == pytest.approx(72 / 30, abs=0.1)

    bad = tmp_path / "notes.bvh"
    bad.write_text("this is not a motion capture file\n")
    page.set_input_files('#overview-form input[name="file"]', str(bad))
    page.click("#overview-form button[type=submit]")
    playwright.expect(page.locator("#overview-result")).to_contain_text("400")
    assert page.get_attribute("#overview-result", "class") == "error"


def test_a_tracks_session_shows_the_scores_of_its_targets(server, page):
    http = httpx.Client(base_url=f"http://{server.http}", timeout=30.0)
    added = http.post("/v1/levels", data={"name": "dashboard-corridor"},
                      files={"level": ("corridor.obj", obj_text(corridor()).encode())})
    assert added.status_code == 202, added.text
    deadline = time.monotonic() + 60.0
    while http.get(f"/v1/level-jobs/{added.json()['id']}").json()["status"] != "succeeded":
        assert time.monotonic() < deadline, "the level job did not succeed"
        time.sleep(0.1)
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", tracks_request("dashboard-corridor", (2.0, 0.0, 2.0))).session_id
    times, feet = corridor_walk(3.0)
    raw.stream(actor_frames(session_id, times, feet))
    try:
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        playwright.expect(page.locator("#why li").last).to_contain_text("tracks_cut_first_shot; target scored shot size")
        playwright.expect(page.locator("#why li").first).to_contain_text("graph distance")
        playwright.expect(page.locator("#shot-summary")).to_contain_text(     # the tracks rig's framing error
            re.compile(r"framing error \d+\.\d\d now, at most \d+\.\d\d"))
        assert framing_pixels(page, "#timeline")[0] > 0
        assert page.eval_on_selector("#toric-fields", "f => f.disabled")
        page.select_option('#style-form select[name="shotSize"]', "SHOT_SIZE_MEDIUM")
        page.click("#style-form button[type=submit]")
        playwright.expect(page.locator("#style-result")).to_have_text("applied")
        playwright.expect(page.locator("#style-json")).to_contain_text('"shotSize": "SHOT_SIZE_MEDIUM"')
    finally:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        raw.close()
        http.delete("/v1/levels/dashboard-corridor")
        http.close()


def test_a_director_takes_a_candidate_holds_it_and_sees_the_fallback(server, page):
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", match_request(delay_s=1.0)).session_id
    raw.stream(list(match_frames(session_id, 90)))
    try:
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        playwright.expect(page.locator("#match-view")).to_be_visible()
        playwright.expect(page.locator("#program-shot")).to_contain_text("(the director's)")
        playwright.expect(page.locator("#release")).to_be_hidden()
        candidate = page.locator("#candidates tbody tr").first
        subjects = candidate.get_attribute("data-subjects").split(",")
        assert set(subjects) <= set(PLAYERS)
        assert canvas_has_drawing(page, "#topview")

        candidate.locator("button").click()
        playwright.expect(page.locator("#take-result")).to_contain_text("held until released")
        held = raw.stream(list(match_frames(session_id, 60, start=90)))
        assert all(list(u.shot.subject_ids) == subjects for u in held)
        playwright.expect(page.locator("#program-shot")).to_contain_text("(held): take: a human's choice")
        playwright.expect(page.locator("#planned-cut")).to_have_text("none while a take is held")
        playwright.expect(page.locator("#release")).to_be_visible()

        victim = subjects[0]
        attacker = next(p for p in PLAYERS if p[0] != victim[0])         # an opponent kills the held player
        died = raw.stream(list(match_frames(session_id, 60, start=150, kill_at={160: (attacker, victim)})))
        fallback = f"take fallback: held player {victim} died (killed by {attacker}); following {attacker}"
        assert died[-1].shot.reason == fallback and list(died[-1].shot.subject_ids) == [attacker]
        playwright.expect(page.locator("#program-shot")).to_contain_text(fallback)
        playwright.expect(page.locator("#event-log li").first).to_contain_text(f"kill {attacker} → {victim}")

        page.click("#release")
        playwright.expect(page.locator("#take-result")).to_have_text("released")
        after = raw.stream(list(match_frames(session_id, 30, start=210)))
        assert not any(u.shot.held for u in after)  # the director has the program again
        playwright.expect(page.locator("#release")).to_be_hidden()
        playwright.expect(page.locator("#program-shot")).to_contain_text("(the director's)")
    finally:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        raw.close()


def test_a_match_with_a_delay_shows_the_cut_it_plans(server, page):
    raw = GrpcRaw(server.grpc)
    session_id = raw.call("CreateSession", match_request(delay_s=3.0)).session_id
    try:
        playwright.expect(page.locator(f'#sessions tbody tr[data-session="{session_id}"]')).to_be_visible()
        raw.stream(list(match_frames(session_id, 30)))                   # less than the delay
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        playwright.expect(page.locator("#program-shot")).to_contain_text("buffering")
        shown = set(raw.stream(list(match_frames(session_id, 120, start=30)))[-1].shot.subject_ids)
        attacker, victim = next(pair for pair in (("a0", "b0"), ("a1", "b1")) if not set(pair) <= shown)
        # The kill is streamed 5 frames before the newest: 2.83 s ahead of the program, which
        # plans to cut lead_s (2.5 s) before it.
        raw.stream(list(match_frames(session_id, 65, start=150, kill_at={210: (attacker, victim)})))
        planned = page.locator("#planned-cut")
        playwright.expect(planned).to_contain_text(f"to DUEL {attacker}, {victim}: planned kill in")
        cut_s = float(planned.text_content().split("(at ")[1].split(" s)")[0])
        program = raw.stream(list(match_frames(session_id, 60, start=215)))
        first = next(u for u in program if u.shot.reason.startswith("planned kill"))
        assert set(first.shot.subject_ids) == {attacker, victim} and first.cut
        assert first.time_s == pytest.approx(cut_s, abs=0.15)            # as announced, within a planning tick
        assert first.time_s <= 210 / RATE_HZ - 1.0                        # and not in the last second before it
    finally:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        raw.close()
