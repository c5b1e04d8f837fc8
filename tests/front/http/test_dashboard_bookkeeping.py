"""The dashboard's bookkeeping in a real browser (Chromium driven by Playwright, as test_dashboard.py)
against the session's timeline as the REST API gives it (issue 41, item 7): the shots and cuts the
summary counts, the cuts "why the camera moved" lists, the game events logged and the last cut's
caption are those of GET /v1/sessions/{id}, each cut and event once, however the page's asks for
frames overlap; and the session's first pose, a cut with nothing before it, is not called "no cut
yet" while the summary counts it.

The server is made slow as a loaded one is (a real level, the monitors rendering, two cores): in
the page, each answer of the session's frames arrives SLOW_ANSWER_MS late, longer than the poll's
period, so asks made before an answer came back overlap with it.

Where Chromium is absent the test skips with the reason (test_dashboard.py's `browser` fixture)."""

from __future__ import annotations

import re
import time

import httpx

from camdirector.v1 import director_pb2 as pb
from tests.front.http.test_dashboard import TIMEOUT_MS, browser, page, playwright
from tests.service.test_match_sessions import frames as match_frames
from tests.service.test_match_sessions import match_request
from tests.service.wire_client import GrpcRaw

__all__ = ["browser", "page"]  # the fixtures this module uses from test_dashboard.py

SLOW_ANSWER_MS = 1200  # the session's frames answered this late: over twice the dashboard's 500 ms poll
SLOW_ANSWERS = f"""
(() => {{
  const fetchNow = window.fetch;
  window.fetch = async (...args) => {{
    const reply = await fetchNow(...args);
    if (/^\\/v1\\/sessions\\/[^/?]+(\\?|$)/.test(String(args[0]))) {{
      await new Promise((done) => setTimeout(done, {SLOW_ANSWER_MS}));
    }}
    return reply;
  }};
}})();
"""
DELAY_S = 1.0  # the broadcast delay: the page is watching while it fills
KILLS = {60: ("a0", "b0"), 120: ("a1", "b1"), 180: ("b0", "a0"), 240: ("b1", "a1")}  # input frame -> (attacker, victim)


def shown(page, selector: str) -> list[str]:
    return page.eval_on_selector_all(selector, "items => items.map((i) => i.textContent)")


def wait_for_equal(read, expected, what: str):
    """Asks read() until it gives `expected`; fails with the last value otherwise."""
    deadline = time.monotonic() + TIMEOUT_MS / 1000
    while (value := read()) != expected:
        assert time.monotonic() < deadline, f"{what}: the page shows {value}, the timeline says {expected}"
        time.sleep(0.2)


def assert_bookkeeping_matches_the_timeline(page, http: httpx.Client, session_id: str) -> list[dict]:
    """The page's counts, cut list, event log and last cut's caption, once it shows the newest frame,
    against those of the session's timeline (the whole of it: fewer frames than the server keeps);
    the timeline's frames."""
    frames = http.get(f"/v1/sessions/{session_id}").json()["frames"]
    cuts = [f for f in frames if f["cut"]]
    assert cuts and not frames[0]["buffering"]
    playwright.expect(page.locator("#shot-summary")).to_contain_text(
        f"frames {frames[0]['frame']}–{frames[-1]['frame']}: {len({f['shot_id'] for f in frames})} shots, {len(cuts)} cuts, "
    )
    playwright.expect(page.locator("#shot-summary")).to_contain_text(f"shot {frames[-1]['shot_id']} now")

    listed = [f"cut at frame {c['frame']} to shot {c['shot_id']}" for c in reversed(cuts)]
    wait_for_equal(
        lambda: [re.sub(r":.*", "", text) for text in shown(page, "#why li")[1:]], listed, "the cuts listed, newest first"
    )
    events = [e for f in frames for e in f["events"]]
    # match.js's words for a kill: time, kind, attacker → victim
    logged = [f"{e['time_s']:.2f} s kill {e['actor_id']} → {e['other_actor_id']}" for e in reversed(events)]
    wait_for_equal(lambda: shown(page, "#event-log li"), logged, "the events logged, newest first")

    last = cuts[-1]
    if last["shot_id"] == 1:  # the session's first pose: pipeline/session.py counts it as a cut
        caption = f"Frame {last['frame']} began the first shot: the session's first pose, with no frame before it to cut from."
    else:
        why = ", ".join(filter(None, [last["shot"]["reason"], *last["flags"]]))
        caption = f"Cut at frame {last['frame']} (from frame {last['frame'] - 1}) to shot {last['shot_id']}: {why}."
    playwright.expect(page.locator("#cut-caption")).to_have_text(caption)
    return frames


def test_the_dashboard_counts_shots_and_cuts_as_the_timeline_has_them(server, page):
    page.add_init_script(SLOW_ANSWERS)
    page.reload()
    raw = GrpcRaw(server.grpc)
    http = httpx.Client(base_url=f"http://{server.http}", timeout=30.0)
    session_id = raw.call("CreateSession", match_request(delay_s=DELAY_S, min_shot_s=0.5)).session_id
    raw.stream(list(match_frames(session_id, 20)))  # less than the delay: buffering
    try:
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        playwright.expect(page.locator("#program-shot")).to_contain_text("buffering")

        raw.stream(list(match_frames(session_id, 40, start=20)))  # the program starts: its first shot only
        frames = assert_bookkeeping_matches_the_timeline(page, http, session_id)
        assert [f["frame"] for f in frames if f["cut"]] == [frames[0]["frame"]]

        for start in range(60, 330, 15):  # kills, and the director's cuts for them, while the page polls
            kills = {k: pair for k, pair in KILLS.items() if start <= k < start + 15}
            raw.stream(list(match_frames(session_id, 15, start=start, kill_at=kills)))
            time.sleep(0.25)
        frames = assert_bookkeeping_matches_the_timeline(page, http, session_id)
        assert sum(f["cut"] for f in frames) >= 4  # the first shot and the director's cuts to the kills
        assert sum(len(f["events"]) for f in frames) == len(KILLS)
    finally:
        raw.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        raw.close()
        http.close()
