"""The dashboard following a cast (issue 42, "Done when": the dashboard shows names and takes work):
`camdirector cast qtv` streams the QTV source stand-in's real demo (tests/bridges/qtv_source.py,
at its recorded pace) into a real server while the dashboard, in a real browser (Debian's
Chromium driven by Playwright, as tests/front/http/test_play_match_dashboard.py), watches the
session: the players are listed by name with their teams, the program monitor follows the match,
and a candidate taken from the page goes to air (the session's shot becomes the taken players,
held) until released.

Where Chromium is absent the test skips with the reason (test_dashboard.py's `browser` fixture)."""

from __future__ import annotations

import gzip
import json
import signal
import subprocess
import sys

import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.matches.import_cli import add_map
from tests.bridges.qtv_source import QtvSource
from tests.bridges.test_qtv import DATA, ROOT, demo
from tests.front.http.test_dashboard import SAME_PICTURE, TIMEOUT_MS, browser, difference, playwright, shown_pixels
from tests.front.http.test_play_match_dashboard import wait_until

__all__ = ["browser", "demo"]  # the fixtures this module uses from the others

SLICE_END_S = 150.0  # more of the match than the test lasts: the source never runs dry
PLAYERS = [("Final", "=SF="), (": Timber", "red"), ("> MrJustice", "=SF="), (": Sujoy", "red")]  # the demo's, slot order


@pytest.fixture(scope="module")
def frobodm2_web_server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("qtv-dashboard")
    bsp = folder / "frobodm2.bsp"
    bsp.write_bytes(gzip.decompress((DATA / "real_maps" / "frobodm2.bsp.gz").read_bytes()))
    add_map(bsp, "frobodm2", folder / "data")
    with ServerProcess("--workers", "1", "--data-dir", str(folder / "data"), transports=("grpc", "http")) as server:
        yield server


@pytest.fixture
def casting(frobodm2_web_server, demo, tmp_path):
    """`cast qtv` of the stand-in at the demo's pace with a 2 s delay: (its session id, its stdout file)."""
    out = tmp_path / "out.jsonl"
    with QtvSource(demo, end_s=SLICE_END_S) as source, open(out, "w") as stdout:
        proc = subprocess.Popen(
            [sys.executable, "-m", "camdirector", "cast", "qtv", source.url, "--level", "frobodm2"]
            + ["--server", frobodm2_web_server.url("grpc"), "--delay-s", "2"],
            stdout=stdout,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        try:
            opened = wait_until(
                lambda: [json.loads(line) for line in out.read_text().splitlines() if '"session_id"' in line],
                "cast opened no session",
            )
            yield opened[0]["session_id"], out
            proc.send_signal(signal.SIGINT)
            _, stderr = proc.communicate(timeout=60)
            assert proc.returncode == 0, stderr
            summary = json.loads(out.read_text().splitlines()[-1])["summary"]
            assert summary["program_frames"] > 0 and summary["connections"] == 1 and summary["bad_streams"] == 0
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()


def test_a_cast_drives_the_dashboard_with_names_and_takes_go_to_air(frobodm2_web_server, browser, casting):
    session_id, out = casting
    server = frobodm2_web_server
    http = httpx.Client(base_url=f"http://{server.http}", timeout=30.0)
    context = browser.new_context()
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        page.goto(f"http://{server.http}/")
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        playwright.expect(page.locator("#match-view")).to_be_visible()
        # The players by name with their teams, as the QTV stream's userinfo has them.
        playwright.expect(page.locator("#players li")).to_have_text([f"{name} ({team})" for name, team in PLAYERS])
        playwright.expect(page.locator("#program-shot")).to_contain_text("(the director's)", timeout=30_000)

        # The program monitor follows the match as the stream brings it.
        program = page.locator("#program-view")
        first = shown_pixels(program)
        wait_until(lambda: difference(shown_pixels(program), first) > SAME_PICTURE, "the program monitor never changed")

        # A candidate of players, taken from the page, goes to air and is held.
        row = page.locator('#candidates tbody tr:not([data-subjects=""])').first
        wait_until(row.count, "no candidate of players offered")
        taken_at = http.get(f"/v1/sessions/{session_id}", params={"last": 1}).json()["frames"][-1]["frame"]
        row.locator("button").click()
        result = page.locator("#take-result")
        playwright.expect(result).to_contain_text("held until released")
        kind_and_subjects = result.text_content().removeprefix("taken: ").removesuffix(", held until released")
        taken_names = kind_and_subjects.split(" ", 1)[1].split(", ")
        assert set(taken_names) <= {name for name, _ in PLAYERS}, taken_names

        def aired():
            frames = http.get(f"/v1/sessions/{session_id}", params={"after_frame": taken_at}).json()["frames"]
            return [f for f in frames if f.get("shot") and f["shot"]["held"]]

        held = wait_until(aired, "the take never went to air", timeout_s=30.0)
        ids = {f"p{k:02d}": name for k, (name, _) in enumerate(PLAYERS)}
        assert [ids[i] for i in held[0]["shot"]["subject_ids"]] == taken_names and held[0]["cut"]
        playwright.expect(page.locator("#program-shot")).to_contain_text("(held): take: a human's choice")
        # cast's progress line says the program's shot: the taken players
        wait_until(
            lambda: any(
                json.loads(line)["shot"].endswith(" " + ", ".join(taken_names))
                for line in out.read_text().splitlines()
                if '"shot"' in line
            ),
            "cast never printed the taken shot",
            timeout_s=30.0,
        )

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
        playwright.expect(page.locator("#program-shot")).to_contain_text("(the director's)")
    finally:
        context.close()
        http.close()
    assert not errors, f"the page raised: {errors}"
