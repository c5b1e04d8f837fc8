"""Names end to end (issue 41, item 5): a bot match whose players are given names (one of them
HTML, `<b>x</b>`) and team names is streamed by `camdirector play-match` into a real server while
the dashboard, in a real browser (Playwright, as test_dashboard.py), watches it. The players'
names, never their ids, show in the players' list (with their teams), the program, the
candidates, the event log and the monitors' labels (said under the cut monitors, from the
pictures' X-Camdirector-Labels), every one as text: no element of the names' markup is made.
play-match's cut lines name their subjects too.

Where Chromium is absent the test skips with the reason (test_dashboard.py's `browser` fixture)."""

from __future__ import annotations

import dataclasses
import json
import re
import signal
import subprocess
import sys

import httpx
import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.evaluation.match.match_file import load_match, save_match
from tests.front.http.test_dashboard import TIMEOUT_MS, browser, playwright
from tests.front.http.test_play_match_dashboard import wait_until
from tests.matches.test_playback import registry
from tests.service.tracks_sessions import ROOT

__all__ = ["browser", "registry"]  # the fixtures this module uses from the others

NAMES = ["<b>x</b>", "Ålice", "bob & <i>co</i>", "Zoë", "d'Artagnan", '"q"']  # the 6 bots of the match, in order
TEAM_NAMES = ["Red <u>team</u>", "Blue"]  # by team index
ID = re.compile(r"\bp0\d\b")  # a player id where a name belongs


@pytest.fixture(scope="module")
def arena_server(registry):
    with ServerProcess("--workers", "1", "--data-dir", str(registry / "data"), transports=("grpc", "http")) as server:
        yield server


@pytest.fixture
def named_playing(registry, arena_server, tmp_path):
    """play-match looping the match with named players at real time, 2 s delay: (session id, stdout file)."""
    match = load_match(registry / "m.npz")
    assert len(match.players) == len(NAMES)
    players = [dataclasses.replace(p, name=name, team_name=TEAM_NAMES[p.team % 2]) for p, name in zip(match.players, NAMES)]
    save_match(dataclasses.replace(match, players=players), tmp_path / "named.npz")
    out, id_file = tmp_path / "out.jsonl", tmp_path / "sid"
    with open(out, "w") as stdout:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "camdirector",
                "play-match",
                str(tmp_path / "named.npz"),
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
        yield session_id, out, players
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
        assert proc.returncode == 130, stderr
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_names_show_as_text_in_program_candidates_events_and_monitor_labels(arena_server, browser, named_playing):
    session_id, out, players = named_playing
    name_of = {p.id: p.name for p in players}
    http = httpx.Client(base_url=f"http://{arena_server.http}", timeout=30.0)
    context = browser.new_context()
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        roster = http.get(f"/v1/sessions/{session_id}", params={"last": 1}).json()["roster"]
        assert [(p["id"], p["display_name"], p["team_name"]) for p in roster] == [
            (p.id, p.name, p.team_name) for p in players
        ]  # as the match file has them, through the wire

        page.goto(f"http://{arena_server.http}/")
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        playwright.expect(page.locator("#match-view")).to_be_visible()
        listed = page.locator("#players li")
        playwright.expect(listed).to_have_text([f"{p.name} ({p.team_name})" for p in players])

        # The program names its players (an overview shows "the map": wait for a shot of players).
        program = page.locator("#program-shot")
        wait_until(lambda: any(name in program.text_content() for name in NAMES), "the program never named a player")
        assert not ID.search(program.text_content()), program.text_content()

        # The candidates: each one's players by name, in the subjects' order.
        rows = page.locator("#candidates tbody tr")

        def offered():  # (subject ids, players cell) of each candidate of players, read at once
            pairs = rows.evaluate_all(
                "rows => rows.map(r => [r.dataset.subjects, r.querySelector('.candidate-players').textContent])"
            )
            return [(ids, text) for ids, text in pairs if ids]

        pairs = wait_until(offered, "no candidate of players offered", timeout_s=30.0)
        assert all(text == ", ".join(name_of[pid] for pid in ids.split(",")) for ids, text in pairs), pairs

        # The event log: a kill names its attacker and victim.
        log = page.locator("#event-log li")
        wait_until(lambda: log.count() > 0, "no game event listed", timeout_s=45.0)
        text = log.first.text_content()
        assert any(name in text for name in NAMES) and not ID.search(text), text

        # The monitors label the players they show with their names; the line under the cut's says which.
        caption = page.locator("#cut-labels")
        wait_until(lambda: caption.text_content(), "no cut monitor labelled a player", timeout_s=45.0)
        labelled = caption.text_content().removeprefix("Labelled: ").removesuffix(".")
        assert set(labelled.split(", ")) <= set(NAMES), labelled

        # The pictures say what they labelled: the candidates' ones by name too.
        def candidate_labels():
            candidates = offered()
            if not candidates:
                return None
            reply = http.get(f"/v1/sessions/{session_id}/view", params={"shot": "candidate", "subjects": candidates[0][0]})
            return json.loads(reply.headers.get("X-Camdirector-Labels", "[]"))

        labels = wait_until(candidate_labels, "no candidate monitor labelled a player", timeout_s=30.0)
        assert set(labels) <= set(NAMES), labels

        # Every name is text: no element of the names' markup exists on the page.
        assert page.locator("#match-view b, #match-view i, #match-view u, #cut-labels b").count() == 0
        assert "<b>x</b>" in page.locator("#players").text_content()

        cuts = wait_until(
            lambda: [json.loads(line)["cut"] for line in out.read_text().splitlines() if '"cut"' in line],
            "play-match printed no cut",
        )
        assert all(c["subject_names"] == [name_of[pid] for pid in c["subjects"]] for c in cuts), cuts
    finally:
        context.close()
        http.close()
    assert not errors, f"the page raised: {errors}"
