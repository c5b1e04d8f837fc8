"""A crew's rehearsal (issue 29, item 2): `camdirector play-match` streams a recorded bot match into a
real server in real time while the dashboard, in a real browser (Debian's Chromium driven by
Playwright, as test_dashboard.py), watches the session: the program monitor's picture and the
candidate shots change as the match plays, a candidate taken from the page goes to air (the
session's shot becomes the taken players, held, and play-match prints that cut) until released.

Where Chromium is absent the test skips with the reason (test_dashboard.py's `browser` fixture)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from tests.front.http.test_dashboard import SAME_PICTURE, TIMEOUT_MS, browser, difference, playwright, shown_pixels
from tests.matches.test_playback import registry
from tests.service.tracks_sessions import ROOT

__all__ = ["browser", "registry"]  # the fixtures this module uses from the others

CHANGE_TIMEOUT_S = 60.0  # three laps of the 20 s match


def wait_until(ok, what: str, timeout_s: float = CHANGE_TIMEOUT_S):
    """ok()'s first truthy value, asked every 0.2 s."""
    deadline = time.monotonic() + timeout_s
    while not (value := ok()):
        assert time.monotonic() < deadline, what
        time.sleep(0.2)
    return value


@pytest.fixture(scope="module")
def arena_server(registry):
    with ServerProcess("--workers", "1", "--data-dir", str(registry / "data"), transports=("grpc", "http")) as server:
        yield server


@pytest.fixture
def playing(registry, arena_server, tmp_path):
    """play-match looping the match at real time with a 2 s delay: (its session id, its stdout file)."""
    out, id_file = tmp_path / "out.jsonl", tmp_path / "sid"
    with open(out, "w") as stdout:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "camdirector",
                "play-match",
                str(registry / "m.npz"),
                "--server",
                arena_server.url("grpc"),
                "--delay-s",
                "2",
                "--loop",
                "--session-id-file",
                str(id_file),
            ],
            stdout=stdout,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
    try:
        session_id = wait_until(lambda: id_file.exists() and id_file.read_text().strip(), "play-match opened no session")
        yield session_id, out
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
        assert proc.returncode == 130, stderr
        summary = json.loads(out.read_text().splitlines()[-1])["summary"]
        assert summary["interrupted"] and summary["cuts"] >= 2
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_played_match_drives_the_dashboard_and_takes_go_to_air(arena_server, browser, playing):
    session_id, out = playing
    http = httpx.Client(base_url=f"http://{arena_server.http}", timeout=30.0)
    context = browser.new_context()
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        page.goto(f"http://{arena_server.http}/")
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        playwright.expect(page.locator("#match-view")).to_be_visible()
        playwright.expect(page.locator("#program-shot")).to_contain_text("(the director's)", timeout=30_000)

        # The program monitor and the candidates follow the match as it plays.
        program = page.locator("#program-view")
        first = shown_pixels(program)
        wait_until(lambda: difference(shown_pixels(program), first) > SAME_PICTURE, "the program monitor never changed")
        rows = page.locator("#candidates tbody tr")

        def offered():
            return rows.evaluate_all("rows => rows.map(r => r.dataset.key)")

        first_offered = wait_until(offered, "no candidate shot offered")
        wait_until(lambda: offered() not in ([], first_offered), f"the candidates stayed {first_offered}")

        # A candidate of players, taken from the page, goes to air and is held.
        row = page.locator('#candidates tbody tr:not([data-subjects=""])').first
        taken_at = http.get(f"/v1/sessions/{session_id}", params={"last": 1}).json()["frames"][-1]["frame"]
        row.locator("button").click()
        result = page.locator("#take-result")
        playwright.expect(result).to_contain_text("held until released")
        kind_and_subjects = result.text_content().removeprefix("taken: ").removesuffix(", held until released")
        taken = kind_and_subjects.split(" ", 1)[1].split(", ")

        def aired():
            frames = http.get(f"/v1/sessions/{session_id}", params={"after_frame": taken_at}).json()["frames"]
            return [f for f in frames if f.get("shot") and f["shot"]["held"]]

        held = wait_until(aired, "the take never went to air", timeout_s=30.0)
        assert held[0]["shot"]["subject_ids"] == taken and held[0]["cut"]
        playwright.expect(page.locator("#program-shot")).to_contain_text("(held): take: a human's choice")
        printed = wait_until(
            lambda: [json.loads(line)["cut"] for line in out.read_text().splitlines() if '"held": true' in line],
            "play-match printed no held cut",
            timeout_s=30.0,
        )
        assert printed[0]["subjects"] == taken and printed[0]["reason"].startswith("take: a human's choice")

        page.click("#release")
        playwright.expect(result).to_have_text("released")
        released_at = http.get(f"/v1/sessions/{session_id}", params={"last": 1}).json()["frames"][-1]["frame"]
        wait_until(
            lambda: any(
                f.get("shot") and not f["shot"]["held"]
                for f in http.get(f"/v1/sessions/{session_id}", params={"after_frame": released_at}).json()["frames"]
            ),
            "the director never got the program back",
            timeout_s=30.0,
        )
        playwright.expect(page.locator("#release")).to_be_hidden()
        playwright.expect(page.locator("#program-shot")).to_contain_text("(the director's)")
    finally:
        context.close()
        http.close()
    assert not errors, f"the page raised: {errors}"
