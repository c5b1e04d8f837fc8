"""bridges/qtv.py: `cast qtv` (the library call) against a QTV source stand-in serving a real
recorded match (tests/bridges/qtv_source.py; the stand-in, not a live mvdsv + KTX built from
source, because this workplace allows no committed script that builds a fetched program, Debian
packages neither, and CI cannot reach GitHub) and a real `camdirector serve` with the match's map
added as `cast qtv --map` adds it: every player (with its name) and every frag of the slice
arrive, the program's poses come back; a source that drops mid-block or sends garbage is
reconnected in the same session; a source that refuses the stream is a clear error, exit status 2
from the CLI. QtvTracks alone: the players are timed by the stream's demo time, so segments that
arrive late or bunched leave the frames' demo times as evenly spaced as the driver's ticks."""

from __future__ import annotations

import dataclasses
import gzip
import logging
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import camdirector_client as cd
from camdirector.bridges import qtv
from camdirector.bridges.qtv import QtvRefused, QtvSettings, QtvTracks, cast_qtv, parse_qtv_url, request_bytes
from camdirector.bridges.qtv_auth import answer, md4
from camdirector.deploy.server_process import ServerProcess
from camdirector.geometry import quake_frame
from camdirector.matches.import_cli import add_map
from camdirector.matches.mvd_wire import MvdDeath, MvdPlayer, MvdStats, MvdTrack, MvdUpdate, parse_mvd
from tests.bridges.qtv_source import SVC_PLAYERINFO, QtvSource

DATA = Path(__file__).parents[1] / "data"
DEMO = DATA / "real_matches" / "2on2_sf_vs_red_frobodm2_220104-0915.mvd.gz"
ROOT = Path(__file__).parents[2]
SLICE_END_S = 28.0  # the first 28 s: four frags (18.7, 22.5, 22.6 and 24.8 s)
SPEED = 4.0


@pytest.fixture(scope="module")
def demo() -> bytes:
    return gzip.decompress(DEMO.read_bytes())


@pytest.fixture(scope="module")
def frobodm2_server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("qtv")
    bsp = folder / "frobodm2.bsp"
    bsp.write_bytes(gzip.decompress((DATA / "real_maps" / "frobodm2.bsp.gz").read_bytes()))
    add_map(bsp, "frobodm2", folder / "data")
    with ServerProcess("--workers", "1", "--data-dir", str(folder / "data"), transports=("grpc",)) as server:
        yield server


def _cast(server, source: QtvSource, until, timeout_s: float = 30.0, password: str = ""):
    """cast_qtv on a thread until until(counts, receiver, tracks) or timeout_s; the result, the
    sessions opened and every progress (frames, connections)."""
    stop = threading.Event()
    sessions, progress, done = [], [], {}

    def on_progress(c, r, tracks):
        progress.append((c.frames, r.connections))
        if until(c, r, tracks):
            stop.set()

    def run():
        with cd.connect(server.url("grpc")) as client:
            done["cast"] = cast_qtv(
                client,
                source.url,
                QtvSettings(delay_s=1.0, backoff_s=0.1, password=password),
                level="frobodm2",
                director="planned",
                stop=stop,
                on_session=lambda sid, roster: sessions.append((sid, roster)),
                on_progress=on_progress,
                progress_s=0.2,
            )

    thread = threading.Thread(target=run)
    thread.start()
    thread.join(timeout_s)
    stop.set()
    thread.join(10)
    return done["cast"], sessions, progress


def _update(source_s: np.ndarray, died: bool = False) -> MvdUpdate:
    """One segment's samples of a player running along x at 300 units a second; died: it dies at
    its last sample (an obituary and its health at 0 then)."""
    origin = np.column_stack([300.0 * source_s, np.zeros_like(source_s), np.zeros_like(source_s)])
    track = MvdTrack(
        time_s=source_s,
        origin_units=origin,
        angles_deg=np.zeros((len(source_s), 3)),
        jump=np.zeros(len(source_s), dtype=bool),
        dead=np.zeros(len(source_s), dtype=bool),
    )
    end_s = float(source_s[-1])
    stats = {0: MvdStats(time_s=np.array([end_s]), values=np.array([[0, 0, 0, -1]]))} if died else {}
    deaths = [MvdDeath(end_s, -1, 0, "died")] if died else []
    return MvdUpdate(end_s, 0, [MvdPlayer(0, "runner", "")], {0: track}, stats, deaths)


def _drive(segments: list[tuple[float, MvdUpdate]], ticks_s: np.ndarray) -> list:
    """QtvTracks (playout 0.15 s) sampled at the driver's ticks, each segment (arrival local time,
    update) offered once its time comes: the samples."""
    tracks = QtvTracks(interp_delay_s=0.15, hold_s=2.0)
    pending = iter(segments)
    segment = next(pending, None)
    samples = []
    for now_s in ticks_s:
        while segment is not None and segment[0] <= now_s:
            tracks.offer(segment[1], float(segment[0]))
            segment = next(pending, None)
        samples.append(tracks.sample(float(now_s)))
    return samples


def test_late_and_bunched_segments_leave_the_frames_evenly_spaced_in_demo_time():
    frames_s = np.arange(0.0, 4.0, 0.013)  # the server's frames, demo time, one a segment
    arrival_s = frames_s + 5.0  # on time: 5 s after the demo's clock
    late = (frames_s > 1.0) & (frames_s < 1.6)
    arrival_s[late] += 0.12 * np.abs(np.sin(40.0 * frames_s[late]))  # late, each by its own amount
    bunched = (frames_s > 2.0) & (frames_s < 2.1)
    arrival_s[bunched] = 2.1 + 5.0 + 0.02  # a stall, then 0.1 s of frames at once
    segments = [(float(a), _update(np.array([t]))) for a, t in zip(arrival_s, frames_s)]
    samples = _drive(segments, np.arange(5.5, 8.9, 1.0 / 30.0))
    shown_s = np.array([s.source_time_s for s in samples])
    assert np.diff(shown_s) == pytest.approx(np.full(len(shown_s) - 1, 1.0 / 30.0), abs=1e-6)
    expected = quake_frame.feet_world(np.column_stack([300.0 * shown_s, np.zeros((len(shown_s), 2))]))
    assert np.array([s.positions_world[0] for s in samples]) == pytest.approx(expected, abs=1e-6)


def test_the_frames_begin_where_the_first_sample_is_due_not_holding_it_over_the_playout_delay():
    frames_s = np.arange(0.0, 2.0, 0.013)
    segments = [(float(t) + 5.0, _update(np.array([t]))) for t in frames_s]  # the first arrives at local 5.0
    samples = _drive(segments, np.arange(5.0, 6.5, 1.0 / 30.0))
    waiting = [s for s in samples if not s.started]
    assert len(waiting) == 5  # the ticks before 5.0 + 0.15
    assert all(s.ids == [] and s.events == [] and not s.stale for s in waiting)
    assert all(s.started for s in samples[len(waiting) :])  # once due, for good
    shown_s = np.array([s.source_time_s for s in samples[len(waiting) :]])
    assert 0.0 < shown_s[0] < 1.0 / 30.0
    assert np.diff(shown_s) == pytest.approx(np.full(len(shown_s) - 1, 1.0 / 30.0), abs=1e-6)  # no demo time held twice


def test_a_death_goes_out_with_the_frame_that_shows_its_moment():
    frames_s = np.arange(0.0, 3.0, 0.013)
    death_s = float(frames_s[150])
    segments = [(death_s + 5.0, _update(frames_s[:151], died=True))]  # a catch-up burst up to the death
    segments += [(float(t) + 5.0, _update(np.array([t]))) for t in frames_s[151:]]
    samples = _drive(segments, np.arange(death_s + 5.0, 7.8, 1.0 / 30.0))
    sent = next(k for k, s in enumerate(samples) if s.events)
    assert [(e.kind, e.actor_id) for e in samples[sent].events] == [("death", "p00")]
    assert samples[sent].stats == [("p00", 0, 0, 0, -1)]
    assert samples[sent - 1].source_time_s < death_s <= samples[sent].source_time_s
    assert sum(len(s.events) for s in samples) == 1


@pytest.mark.parametrize("k", [1, 777, 3000, 9000])
def test_the_stand_in_tells_a_stream_that_joins_late_every_players_whole_state(demo, k):
    """As mvdsv's SV_MVD_SendInitialGamestate does: a join after k blocks reads, from the opening
    and the state alone, every player where the whole stream up to there leaves it (origin, angles,
    dead, stats and frags; a demo's playerinfo sends only what changed)."""
    source = QtvSource(demo, end_s=200.0)
    whole = parse_mvd(source.opening + b"".join(block for _, block in source.frames[:k]))
    joined = parse_mvd(source.opening + source.state_at(k))
    assert [p.slot for p in joined.players] == [p.slot for p in whole.players] and len(whole.players) == 4
    for player in whole.players:
        track, told = whole.tracks[player.slot], joined.tracks[player.slot]
        np.testing.assert_array_equal(told.origin_units[-1], track.origin_units[-1])
        np.testing.assert_array_equal(told.angles_deg[-1, :2], track.angles_deg[-1, :2])  # mvdsv sends no roll
        assert told.dead[-1] == track.dead[-1]
        np.testing.assert_array_equal(joined.stats[player.slot].values[-1], whole.stats[player.slot].values[-1])
    # so the test can fail: a join told nothing misplaces a player in its first frame (a coordinate it never sends)
    first = next(j for j in range(k, len(source.frames)) if source.frames[j][1][6] == SVC_PLAYERINFO)
    after = b"".join(block for _, block in source.frames[k : first + 1])
    truth = parse_mvd(source.opening + b"".join(block for _, block in source.frames[: first + 1])).tracks

    def where(demo: bytes) -> list[bool]:  # per player: its origin in the first frame after the join is the truth's
        tracks = parse_mvd(demo).tracks
        return [np.array_equal(tracks[p.slot].origin_units[-1], truth[p.slot].origin_units[-1]) for p in whole.players]

    assert all(where(source.opening + source.state_at(k) + after))
    if k > 1:
        assert not all(where(source.opening + after))


def test_request_is_the_clients():
    assert request_bytes(parse_qtv_url("qtv://h:28000"), "cd") == b"QTV\nVERSION: 1\nRECEIVE\nUSERINFO: \\name\\cd\n\n"
    assert b"SOURCE: 3@h:27500\n" in request_bytes(parse_qtv_url("qtv://proxy:27599/3@h:27500"), "cd")
    with pytest.raises(ValueError, match="qtv://"):
        parse_qtv_url("http://h:1")


def test_a_real_match_reaches_the_session_with_every_player_and_frag(frobodm2_server, demo):
    kills = {}

    def until(c, r, tracks):
        kills["seen"] = list(tracks.kills)
        return len(tracks.kills) >= 4 and c.program > 0 and r.bytes > 0 and c.kills >= 4

    with QtvSource(demo, end_s=SLICE_END_S, speed=SPEED) as source:
        cast, sessions, _ = _cast(frobodm2_server, source, until)
    assert source.requests[0].split("\n")[:3] == ["QTV", "VERSION: 1", "RECEIVE"]
    assert len(sessions) == 1
    roster = sessions[0][1]
    assert [(p.id, p.name, p.team_name) for p in roster] == [
        ("p00", "Final", "=SF="),
        ("p01", ": Timber", "red"),
        ("p02", "> MrJustice", "=SF="),
        ("p03", ": Sujoy", "red"),
    ]
    # slots 0, 1, 3, 4: Timber killed Final twice, Final Timber, Timber MrJustice (parse_mvd's deaths)
    assert kills["seen"] == [("p01", "p00"), ("p01", "p00"), ("p00", "p01"), ("p01", "p02")]
    assert cast.session.kills == 4
    assert cast.session.program > 0 and cast.session.answered >= cast.session.program
    assert cast.receiver.bad_streams == 0


@pytest.mark.parametrize("knob, error", [("drop_after_s", "closed the stream, cut"), ("garbage_after_s", "bad stream from")])
def test_a_source_that_fails_mid_match_is_reconnected_in_the_same_session(frobodm2_server, demo, caplog, knob, error):
    with caplog.at_level(logging.WARNING, logger="camdirector.bridges.qtv"):
        with QtvSource(demo, end_s=SLICE_END_S, speed=SPEED, **{knob: 1.5}) as source:
            cast, sessions, progress = _cast(frobodm2_server, source, lambda c, r, t: r.connections >= 2 and c.frames > 150)
    assert len(sessions) == 1
    assert cast.receiver.connections >= 2 and cast.receiver.drops >= 1
    assert cast.receiver.bad_streams == (1 if knob == "garbage_after_s" else 0)
    assert any(error in m for m in caplog.messages)
    before = max(f for f, n in progress if n == 1)
    assert max(f for f, n in progress if n >= 2) > before  # frames went on after the reconnect


def test_a_refused_stream_is_an_error(frobodm2_server, demo):
    with QtvSource(demo, end_s=SLICE_END_S, refuse="no stream selected") as source:
        with pytest.raises(QtvRefused, match="refused the stream: PERROR: no stream selected"):
            _cast_raising(frobodm2_server, source)
        done = _cast_cli(frobodm2_server, source)
    assert done.returncode == 2, done.stderr
    assert f"camdirector cast qtv: {source.url} refused the stream: PERROR: no stream selected" in done.stderr
    assert "Traceback" not in done.stderr


def _cast_cli(server, source, *flags: str) -> subprocess.CompletedProcess:
    """`camdirector cast qtv` of the source on the frobodm2 level, run to its end."""
    return subprocess.run(
        [sys.executable, "-m", "camdirector.__main__", "cast", "qtv", source.url, "--level", "frobodm2"]
        + ["--server", server.url("grpc"), *flags],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
        env=os.environ,
    )


def _cast_raising(server, source):
    with cd.connect(server.url("grpc")) as client:
        cast_qtv(client, source.url, QtvSettings(), level="frobodm2", director="planned", stop=threading.Event())


def test_the_password_answers_are_ezquakes():
    # RFC 1320's test suite; Quake's CRC is CRC-16/CCITT-FALSE, whose check value is 0x29B1
    assert md4(b"").hex() == "31d6cfe0d16ae931b73c59d7e0c089c0"
    assert md4(b"message digest").hex() == "d9130a8164549fe818874806e1c7014b"
    assert md4(b"1234567890" * 8).hex() == "e33b4ddc9c38f2199c3e7b164fcc0536"
    # MD4 of "abc" (a448017a af21d852 5fc10ae8 7aa6729d) as four little-endian words, "%X" each
    assert answer("MD4", "ab", "c") == "7A0148A452D821AFE80AC15F9D72A67A"
    assert answer("CCITT", "1234", "56789") == "0x29B1"
    assert answer("PLAIN", "x", "secret") == "secret"
    with pytest.raises(ValueError, match="SHA3_512"):
        answer("SHA3_512", "x", "secret")


@pytest.mark.parametrize("methods, method", [(("PLAIN", "CCITT", "MD4"), "MD4"), (("PLAIN", "CCITT"), "CCITT")])
def test_a_passworded_source_is_answered(frobodm2_server, demo, methods, method):
    with QtvSource(demo, end_s=SLICE_END_S, speed=SPEED, password="hunter2", methods=methods) as source:
        cast, sessions, _ = _cast(frobodm2_server, source, lambda c, r, t: c.program > 0, password="hunter2")
    assert len(sessions) == 1 and cast.session.program > 0
    first, second = source.requests[0].split("\n"), source.requests[1].split("\n")
    assert [line for line in first if line.startswith("AUTH")] == ["AUTH: MD4", "AUTH: CCITT", "AUTH: PLAIN"]
    assert f"AUTH: {method}" in second
    assert f'PASSWORD: "{answer(method, source.challenge, "hunter2")}"' in second


@pytest.mark.parametrize(
    "flags, said",
    [
        (["--password", "wrong"], "refused the stream: PERROR: Bad password."),
        # mvdsv's words to a request that offers no AUTH method, then ours
        (
            [],
            "refused the stream: PERROR: You need to provide a common auth method."
            " (it asks for a password: give it with --password)",
        ),
    ],
)
def test_a_wrong_or_missing_password_is_a_clear_error(frobodm2_server, demo, flags, said):
    with QtvSource(demo, end_s=SLICE_END_S, password="hunter2") as source:
        done = _cast_cli(frobodm2_server, source, *flags)
    assert done.returncode == 2, done.stderr
    assert f"camdirector cast qtv: {source.url} {said}" in done.stderr
    assert "Traceback" not in done.stderr


JOIN_SLOT, JOIN_AT_S = 4, 6.0  # Sujoy's slot, and when the stream below first shows him (before any frag)


class _JoinsLater(qtv.MvdStream):
    """The real stream as a source shows it when JOIN_SLOT starts playing only at JOIN_AT_S of
    demo time (a player joining during the warm-up or the match): before then, nothing of the slot."""

    def feed(self, chunk: bytes) -> MvdUpdate:
        update = super().feed(chunk)
        if update.time_s >= JOIN_AT_S:
            return update
        assert not any(JOIN_SLOT in (d.killer, d.victim) for d in update.deaths)
        return dataclasses.replace(
            update,
            players=[p for p in update.players if p.slot != JOIN_SLOT],
            tracks={s: t for s, t in update.tracks.items() if s != JOIN_SLOT},
            stats={s: v for s, v in update.stats.items() if s != JOIN_SLOT},
        )


def test_a_player_who_joins_later_opens_the_next_session_with_every_player(frobodm2_server, demo, monkeypatch, caplog):
    monkeypatch.setattr(qtv, "MvdStream", _JoinsLater)
    with caplog.at_level(logging.WARNING, logger="camdirector.bridges.live_session"):
        with QtvSource(demo, end_s=SLICE_END_S, speed=SPEED) as source:
            cast, sessions, _ = _cast(frobodm2_server, source, lambda c, r, t: c.kills >= 4 and len(t.roster) == 4, 45.0)
    assert cast.session.sessions == len(sessions) == 2
    assert [(p.id, p.name) for p in sessions[0][1]] == [("p00", "Final"), ("p01", ": Timber"), ("p02", "> MrJustice")]
    assert [(p.id, p.name, p.team, p.team_name) for p in sessions[1][1]] == [
        ("p00", "Final", 0, "=SF="),
        ("p01", ": Timber", 1, "red"),
        ("p02", "> MrJustice", 0, "=SF="),
        ("p03", ": Sujoy", 1, "red"),
    ]
    assert any("the roster changed (p03 : Sujoy): a new session with 4 players" in m for m in caplog.messages)
    assert cast.session.kills == 4  # every frag reached a session: all four come after the new one opened
    assert cast.receiver.connections == 1


def test_the_roster_changes_when_a_slot_joins_or_is_taken_by_another_name():
    tracks = QtvTracks(interp_delay_s=0.0, hold_s=2.0)
    ones = _update(np.array([0.0, 0.1]))
    tracks.offer(ones, 0.1)
    assert [p.id for p in tracks.roster] == ["p00"] and not tracks.roster_changed.is_set()
    joined = dataclasses.replace(
        ones,
        time_s=0.3,
        players=[MvdPlayer(0, "runner", ""), MvdPlayer(5, "late", "")],
        tracks={0: _update(np.array([0.2, 0.3])).tracks[0], 5: _update(np.array([0.2, 0.3])).tracks[0]},
        deaths=[MvdDeath(0.3, 5, 0, "rocket")],
    )
    tracks.offer(joined, 0.3)
    assert tracks.roster_changed.is_set()
    before = tracks.sample(0.5)
    assert before.ids == ["p00"] and before.events == []  # the session open knows no p01: its kill waits out
    assert [(p.id, p.name, p.team) for p in tracks.reopen()] == [("p01", "late", 1)]
    assert not tracks.roster_changed.is_set() and [p.id for p in tracks.roster] == ["p00", "p01"]
    assert tracks.sample(0.6).ids == ["p00", "p01"]
    renamed = dataclasses.replace(joined, time_s=0.4, players=[MvdPlayer(0, "other", ""), MvdPlayer(5, "late", "")], deaths=[])
    tracks.offer(renamed, 0.4)
    assert tracks.roster_changed.is_set()
    assert [(p.id, p.name, p.team) for p in tracks.reopen()] == [("p00", "other", 0)]


def test_a_reconnect_is_reached_as_a_jump_with_its_demo_time_held_until_then():
    tracks = QtvTracks(interp_delay_s=0.15, hold_s=5.0)
    tracks.offer(_update(np.arange(0.0, 0.51, 0.1)), 1.0)  # the runner at 150 units when the stream drops
    held = tracks.sample(1.2)
    tracks.new_stream()
    tracks.offer(_update(np.array([0.0, 0.1])), 2.0)  # the new stream: its demo time anew, the runner back at 0
    between = tracks.sample(1.95)  # shows local 1.8, before the new stream's first sample
    assert between.positions_world.tolist() == held.positions_world.tolist()  # held, not swept toward it
    assert between.source_time_s == held.source_time_s == pytest.approx(0.5)
    after = tracks.sample(2.3)
    assert after.positions_world[0, 0] == pytest.approx(quake_frame.feet_world(np.array([[30.0, 0.0, 0.0]]))[0, 0])
    assert after.source_time_s == pytest.approx(0.1)
