"""bridges/gsi_server.py and gsi_cast.py: the endpoint refuses what it must (401 logged, 413, 411,
400) and never falls over; the recorded payloads, posted at their pace, drive a RIG_MATCH session
of a real `camdirector serve`, whose program comes out as spec_goto lines to a stand-in console;
the printed cfg is Valve's KeyValues."""

from __future__ import annotations

import json
import logging
import re
import threading
import time

import httpx
import pytest

import camdirector_client as cd
from camdirector.bridges.gsi_cast import cast_gsi
from camdirector.bridges.gsi_server import GsiEndpoint, gamestate_config
from camdirector.bridges.gsi_settings import GsiDriverSettings, GsiEndpointSettings, NetconSettings
from camdirector.bridges.gsi_tracks import GsiTracks
from camdirector.bridges.netcon import NetconSender
from camdirector.deploy.server_process import ServerProcess
from tests.bridges.gsi_payloads import mirage_sequence
from tests.bridges.test_netcon import Console
from tests.precompute.tracks.tiny_levels import boxes
from tests.service.tracks_sessions import cli_add_level, obj_text

TOKEN = "s3cret-token"


@pytest.fixture
def endpoint():
    tracks = GsiTracks(interp_delay_s=0.1, hold_s=2.0)
    with GsiEndpoint(GsiEndpointSettings(port=0, token=TOKEN, max_body_bytes=64 * 1024), tracks) as e:
        yield e, tracks, f"http://127.0.0.1:{e.port}/"


def test_a_wrong_token_is_refused_and_logged(endpoint, caplog):
    e, tracks, url = endpoint
    wrong = mirage_sequence("not-the-token")[1]
    with caplog.at_level(logging.WARNING, logger="camdirector.bridges.gsi"):
        r = httpx.post(url, content=json.dumps(wrong))
    assert r.status_code == 401 and e.refused == 1 and tracks.counts.accepted == 0
    assert [m for m in caplog.messages if "wrong token" in m and "127.0.0.1" in m]
    assert httpx.post(url, content=json.dumps(mirage_sequence(TOKEN)[1])).status_code == 200


def test_oversized_and_bad_bodies_are_refused_and_the_endpoint_runs_on(endpoint):
    e, tracks, url = endpoint
    assert httpx.post(url, content=b"x" * (65 * 1024)).status_code == 413
    assert httpx.post(url, content=b"{not json").status_code == 400
    assert httpx.post(url, content=b'{"allplayers": {"1": {"team": "X"}}}').status_code == 400
    with httpx.Client() as c:
        chunked = c.post(url, content=iter([b"{}"]))  # no Content-Length
    assert chunked.status_code == 411
    assert httpx.post(url, content=json.dumps(mirage_sequence(TOKEN)[0])).text.strip() == "accepted"
    assert httpx.post(url, content=json.dumps(mirage_sequence(TOKEN)[0])).text.strip() == "duplicate"


def keyvalues(text: str):
    """Valve's KeyValues text (quoted keys and values, braces) as nested dicts; raises on anything else."""
    tokens = re.findall(r'"([^"]*)"|([{}])|(\S)', text)
    assert not [t for t in tokens if t[2]], "a bare token"
    items = [t[0] if t[1] == "" else t[1] for t in tokens]

    def block(i):
        out = {}
        while i < len(items) and items[i] != "}":
            key, i = items[i], i + 1
            if items[i] == "{":
                out[key], i = block(i + 1)
                i += 1
            else:
                out[key], i = items[i], i + 1
        return out, i

    tree, end = block(0)
    assert end == len(items)
    return tree


def test_the_printed_config_is_keyvalues_with_what_the_bridge_needs():
    cfg = keyvalues(gamestate_config(GsiEndpointSettings(host="127.0.0.1", port=3000, token=TOKEN)))
    body = cfg["camdirector"]
    assert body["uri"] == "http://127.0.0.1:3000/" and body["auth"] == {"token": TOKEN}
    assert float(body["throttle"]) <= float(body["heartbeat"]) and float(body["timeout"]) > 0
    assert {"provider", "allplayers_id", "allplayers_state", "allplayers_match_stats", "allplayers_position"} <= set(body["data"])
    assert set(body["data"].values()) == {"1"}


@pytest.fixture(scope="module")
def mirage_server(tmp_path_factory):
    """A server holding a flat floor under the recorded players (de_mirage's middle, 9.4 m down)."""
    folder = tmp_path_factory.mktemp("gsi")
    (folder / "floor.obj").write_text(obj_text(boxes(((-30, -9.6, -8), (10, -9.4, 62)))))
    cli_add_level(folder / "data", "mirage_floor", folder / "floor.obj")
    with ServerProcess("--workers", "1", "--data-dir", str(folder / "data"), transports=("grpc",)) as server:
        yield server


def test_recorded_payloads_drive_a_session_and_its_program_reaches_the_console(mirage_server):
    tracks = GsiTracks(interp_delay_s=0.1, hold_s=2.0)
    console = Console()
    netcon = NetconSender(NetconSettings(port=console.port, rate_hz=5.0))
    driver = GsiDriverSettings(rate_hz=30.0, delay_s=0.5, hold_s=2.0)
    stop = threading.Event()
    done: dict = {}
    sessions: list[str] = []
    with cd.connect(mirage_server.url("grpc")) as client, GsiEndpoint(GsiEndpointSettings(port=0, token=TOKEN), tracks) as e:
        url = f"http://127.0.0.1:{e.port}/"

        def run():
            done["counts"] = cast_gsi(
                client,
                tracks,
                driver,
                level="mirage_floor",
                director="planned",
                stop=stop,
                netcon=netcon,
                on_session=sessions.append,
            )

        runner = threading.Thread(target=run)
        runner.start()
        before, now = mirage_sequence(TOKEN)
        # Both carry provider.timestamp 1596015822: the game sent them within that second, at the
        # throttle (0.1 s) of the cfg apart. Then its heartbeat: the same state again each second
        # (a heartbeat's body differs from a resend's only by its timestamp, which is whole seconds).
        assert httpx.post(url, content=json.dumps(before)).status_code == 200
        time.sleep(0.1)
        assert httpx.post(url, content=json.dumps(now)).status_code == 200
        for beat in range(1, 4):
            time.sleep(1.0)
            now = {**now, "provider": {**now["provider"], "timestamp": now["provider"]["timestamp"] + beat}}
            assert httpx.post(url, content=json.dumps(now)).status_code == 200
        # an out-of-order payload (a second older) and a resend change nothing
        late = {**before, "provider": {**before["provider"], "timestamp": 1596015821}}
        assert httpx.post(url, content=json.dumps(late)).text.strip() == "out_of_order"
        assert httpx.post(url, content=json.dumps(now)).text.strip() == "duplicate"
        window_start = time.monotonic()
        time.sleep(1.0)
        window_lines = sum(t >= window_start for t, _ in list(console.lines))
        stop.set()
        runner.join(timeout=30)
    console.close()
    counts = done["counts"]
    assert sessions and counts.frames > 60 and counts.answered == counts.frames and counts.program > 0
    assert [m.name for m in tracks.roster][:3] == ["Epistaxis", "Muminek", "Pesukarhu"]  # observer slots 0, 1, 2
    assert len(tracks.roster) == 10 and tracks.counts.out_of_order == 1 and tracks.counts.duplicate == 1
    assert console.lines and all(line.startswith("spec_goto ") and len(line.split()) == 6 for _, line in console.lines)
    assert window_lines <= 5.0 * 1.0 + 1
    assert netcon.sent <= 5.0 * (counts.frames / driver.rate_hz + 1.0) + 1


def test_a_player_first_seen_later_opens_the_next_session_with_him(mirage_server, caplog):
    tracks = GsiTracks(interp_delay_s=0.1, hold_s=2.0)
    driver = GsiDriverSettings(rate_hz=30.0, delay_s=0.5, hold_s=2.0)
    stop = threading.Event()
    done: dict = {}
    sessions: list[str] = []
    before, now = mirage_sequence(TOKEN)
    late_id = max(now["allplayers"], key=lambda steamid: now["allplayers"][steamid]["observer_slot"])
    before = {**before, "allplayers": {k: v for k, v in before["allplayers"].items() if k != late_id}}
    with (
        caplog.at_level(logging.WARNING, logger="camdirector.bridges.live_session"),
        cd.connect(mirage_server.url("grpc")) as client,
        GsiEndpoint(GsiEndpointSettings(port=0, token=TOKEN), tracks) as e,
    ):
        url = f"http://127.0.0.1:{e.port}/"

        def run():
            done["counts"] = cast_gsi(
                client, tracks, driver, level="mirage_floor", director="planned", stop=stop, on_session=sessions.append
            )

        runner = threading.Thread(target=run)
        runner.start()
        assert httpx.post(url, content=json.dumps(before)).status_code == 200  # nine players: the first session's
        time.sleep(1.0)
        assert httpx.post(url, content=json.dumps(now)).status_code == 200  # the tenth connects
        for beat in range(1, 3):
            time.sleep(1.0)
            now = {**now, "provider": {**now["provider"], "timestamp": now["provider"]["timestamp"] + beat}}
            assert httpx.post(url, content=json.dumps(now)).status_code == 200
        stop.set()
        runner.join(timeout=30)
    counts = done["counts"]
    assert counts.sessions == len(sessions) == 2 and counts.program > 0
    assert len(tracks.roster) == 10 and tracks.roster[-1].id == "p09"
    assert tracks.roster[-1].name == now["allplayers"][late_id]["name"] and tracks.counts.unknown == 0
    assert any("a new session with 10 players" in m for m in caplog.messages)
