"""`camdirector play-match` (matches/playback.py, play_cli.py) against a real server: a 20-second bot
match from `camdirector match-sim` on the tiny walled arena of tests/evaluation/match/test_sim.py,
played faster than real time; looped and stopped with Ctrl-C; every bad input refused with exit 2
and one line."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time

import httpx
import numpy as np
import pytest

import camdirector_client as cd
from camdirector.__main__ import main
from camdirector.deploy.server_process import ServerProcess
from camdirector.evaluation.match.match_file import load_match, save_match
from camdirector.evaluation.match.session_feed import Feed, frame_updates, match_session_fields
from camdirector.geometry.transforms import quat_rotate
from camdirector.matches.playback import lap_feeds
from tests.evaluation.match.test_match_file import save_views
from tests.evaluation.match.test_sim import arena
from tests.service.tracks_sessions import ROOT, cli_add_level, obj_text

RATE_HZ = 30.0


@pytest.fixture(scope="module")
def registry(tmp_path_factory):
    """A folder holding the arena's level registry (data/) and a 20 s match of 6 bots on it (m.npz)."""
    folder = tmp_path_factory.mktemp("play-match")
    (folder / "arena.obj").write_text(obj_text(arena()))
    cli_add_level(folder / "data", "arena", folder / "arena.obj")
    made = subprocess.run(
        [
            sys.executable,
            "-m",
            "camdirector",
            "match-sim",
            "--level",
            "arena",
            "--data-dir",
            str(folder / "data"),
            "--players",
            "6",
            "--minutes",
            str(20 / 60),
            "--seed",
            "1",
            "--rate-hz",
            str(RATE_HZ),
            "--out",
            str(folder / "m.npz"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert made.returncode == 0, made.stderr
    return folder


@pytest.fixture(scope="module")
def arena_server(registry):
    with ServerProcess("--workers", "1", "--data-dir", str(registry / "data"), transports=("grpc", "http")) as server:
        yield server


def play(*args: str, env: dict | None = None, timeout_s: float = 180.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "camdirector", "play-match", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=timeout_s,
        env={**os.environ, **(env or {})},
    )


def json_lines(stdout: str) -> list[dict]:
    return [json.loads(line) for line in stdout.splitlines()]


def test_a_match_played_fast_has_every_frame_answered_and_its_cuts_printed(registry, arena_server, tmp_path):
    match = load_match(registry / "m.npz")
    speed, delay_s = 4.0, 2.0
    done = play(
        str(registry / "m.npz"),
        "--server",
        arena_server.url("grpc"),
        "--speed",
        str(speed),
        "--delay-s",
        str(delay_s),
        "--session-id-file",
        str(tmp_path / "sid"),
    )
    assert done.returncode == 0, done.stderr
    lines = json_lines(done.stdout)
    head, cuts, summary = lines[0], [line["cut"] for line in lines[1:-1]], lines[-1]["summary"]
    session_id = (tmp_path / "sid").read_text().strip()
    assert head["session_id"] == session_id and head["level"] == "arena" and head["players"] == 6
    assert head["roster"] == [{"id": p.id, "name": "", "team": p.team, "team_name": ""} for p in match.players]  # bots

    feed = Feed.of(match, RATE_HZ, delay_s)
    assert head["frames_per_lap"] == len(feed.rows)
    assert summary["frames_sent"] == summary["answered"] == len(feed.rows)
    assert summary["laps"] == 1 and not summary["interrupted"]
    # The delay buffers the first delay_s of game; the tail that follows the match brings every one
    # of its moments on the program.
    assert len(match.time_s) <= summary["program_frames"] < summary["answered"]
    assert summary["wall_s"] >= (feed.times_s[-1] - feed.times_s[0]) / speed  # paced, not sent at once

    # The session's shot changes: the first cut opens the program at the match's first moment, and
    # the next ones go to other shots.
    assert summary["cuts"] == len(cuts) >= 3
    compute = summary["compute_ms"]  # the server's time per program frame, as it reported it
    assert 0.0 < compute["median"] <= compute["p99"] <= compute["max"]
    assert cuts[0]["frame"] == 1 and cuts[0]["time_s"] == 0.0
    assert [c["frame"] for c in cuts] == sorted({c["frame"] for c in cuts})
    assert [c["shot_id"] for c in cuts] == sorted({c["shot_id"] for c in cuts})
    assert len({tuple(c["subjects"]) for c in cuts}) >= 3
    assert all(c["subject_names"] == c["subjects"] for c in cuts)  # bots have no names: their ids stand in
    ids = {p.id for p in match.players}
    assert all(
        set(c["subjects"]) <= ids and c["kind"] in ("DUEL", "FOLLOW", "GROUP", "OVERVIEW") and c["reason"] and not c["held"]
        for c in cuts
    )
    assert httpx.get(f"http://{arena_server.http}/v1/sessions/{session_id}").status_code == 404  # closed at the end


def test_a_looped_match_goes_on_until_ctrl_c_closes_the_session(registry, arena_server, tmp_path):
    match = load_match(registry / "m.npz")
    out = tmp_path / "out.jsonl"
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
                "--speed",
                "6",
                "--delay-s",
                "1",
                "--loop",
            ],
            stdout=stdout,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
    try:
        deadline = time.monotonic() + 120.0
        while not any("cut" in line and line["cut"]["frame"] > len(match.time_s) for line in json_lines(out.read_text())):
            assert proc.poll() is None and time.monotonic() < deadline, "no cut in the second lap"
            time.sleep(0.2)
        session_id = json_lines(out.read_text())[0]["session_id"]
        assert httpx.get(f"http://{arena_server.http}/v1/sessions/{session_id}").status_code == 200
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130 and "Traceback" not in stderr, stderr
    lines = json_lines(out.read_text())
    summary = lines[-1]["summary"]
    # the first Ctrl-C stops the sending: the server answers every frame sent, then the stream ends
    assert summary["interrupted"] and summary["laps"] >= 2 and summary["answered"] == summary["frames_sent"]
    frames = [line["cut"]["frame"] for line in lines[1:-1]]
    assert frames == sorted(set(frames))  # frame numbers go on increasing across laps
    assert httpx.get(f"http://{arena_server.http}/v1/sessions/{session_id}").status_code == 404  # closed


def test_laps_follow_each_other_one_step_apart(registry):
    match = load_match(registry / "m.npz")
    laps = lap_feeds(match, RATE_HZ, 10.0, loop=True)
    first, second = next(laps), next(laps)
    step_s = 1.0 / RATE_HZ  # the file is at 30 Hz: every row is sent
    assert np.array_equal(first.rows, np.arange(len(match.time_s))) and np.array_equal(second.rows, first.rows)
    assert second.frames[0] == first.frames[-1] + 1
    assert second.times_s[0] == pytest.approx(first.times_s[-1] + step_s)
    once = next(lap_feeds(match, RATE_HZ, 10.0, loop=False))
    assert np.array_equal(once.frames, Feed.of(match, RATE_HZ, 10.0).frames)  # with the delay's tail


def test_a_match_with_stats_sends_every_players_values_then_their_changes(registry, arena_server):
    """The first frame carries every player's scoreboard values, later ones only the players whose
    values changed since the last frame sent (a skipped row's change rides on the next sent one);
    the server takes them."""
    match = load_match(registry / "m.npz")
    stats = np.zeros((len(match.time_s), len(match.players), 4), dtype=np.int32)  # health, armor, items, frags
    stats[:, :, 0] = 100
    stats[100:, 0, 3] = 1  # p00 scores at row 100
    stats[200:, 1, 0] = 40  # p01 is hurt at row 200
    stats[301:, 2, 2] = -(2**31) | 32  # p02's item bits 31 and 5 at row 301 (int32 in the file)
    match = dataclasses.replace(match, stats=stats)
    full = [(p.id, 100, 0, 0, 0) for p in match.players]
    with (
        cd.connect(arena_server.url("grpc")) as client,
        client.create_session(**match_session_fields(match, "planned", 1.0, 0)) as session,
    ):
        for rate_hz, expected in (
            (
                RATE_HZ,
                {0: full, 100: [("p00", 100, 0, 0, 1)], 200: [("p01", 40, 0, 0, 0)], 301: [("p02", 100, 0, 2**31 + 32, 0)]},
            ),
            (10.0, {0: full, 102: [("p00", 100, 0, 0, 1)], 201: [("p01", 40, 0, 0, 0)], 303: [("p02", 100, 0, 2**31 + 32, 0)]}),
        ):
            updates = list(frame_updates(session, match, Feed.of(match, rate_hz, 1.0), list(range(6)), events=True))
            sent = {
                u.frame - 1: [(s.id, s.health, s.armor, s.items, s.frags) for s in u.player_stats]
                for u in updates
                if u.player_stats
            }
            assert sent == expected, rate_hz
        replies = list(session.stream(updates))  # the last: frames 1 to ... at 10 Hz
        assert len(replies) == len(updates) and not any(r.stale for r in replies)


def test_the_key_comes_from_the_environment_and_a_refused_one_is_said(registry, monkeypatch, capsys):
    with ServerProcess("--workers", "1", "--data-dir", str(registry / "data"), transports=("grpc",), auth=True) as server:
        args = ["play-match", str(registry / "m.npz"), "--server", server.url("grpc"), "--speed", "4", "--delay-s", "0"]
        assert main([*args, "--key", "cd_not-a-key"]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and "refused the key: UNAUTHENTICATED" in err, err
        monkeypatch.setenv("CAMDIRECTOR_KEY", server.admin_key)
        assert main(args) == 0
        summary = json_lines(capsys.readouterr().out)[-1]["summary"]
        assert summary["answered"] == summary["frames_sent"] > 0
        monkeypatch.delenv("CAMDIRECTOR_KEY")  # the key from a file: never in the process's arguments
        (registry / "engine.key").write_text(server.admin_key + "\n")
        assert main([*args, "--key-file", str(registry / "engine.key")]) == 0
        assert json_lines(capsys.readouterr().out)[-1]["summary"]["answered"] > 0
        (registry / "empty.key").write_text("")
        assert main([*args, "--key-file", str(registry / "empty.key")]) == 2
        assert "does not hold a key" in capsys.readouterr().err


def _unreadable(folder):
    np.savez(folder / "x.npz", time_s=np.zeros(3))
    return folder / "x.npz"


def _elsewhere(folder):
    match = load_match(folder.parent / "m.npz")
    save_match(dataclasses.replace(match, level="nowhere"), folder / "nowhere.npz")
    return folder / "nowhere.npz"


@pytest.mark.parametrize(
    "make_file, server, message",
    [
        (lambda folder: folder / "absent.npz", None, "cannot read match file"),
        (_unreadable, None, "not a match file (missing"),
        (None, "grpc://127.0.0.1:1", "cannot reach the server at grpc://127.0.0.1:1: UNAVAILABLE"),
        (None, "tcp://127.0.0.1:5555", "give grpc://HOST:PORT"),
        (_elsewhere, None, "refused the session: NOT_FOUND: level_id 'nowhere' is not in this server's level registry"),
    ],
    ids=["missing-file", "not-a-match", "unreachable-server", "not-grpc", "unknown-level"],
)
def test_bad_input_exits_2_with_one_line(registry, arena_server, make_file, server, message, capsys):
    """In this process (the command's own `main`): an exception escaping it would fail the test."""
    folder = registry / "bad"
    folder.mkdir(exist_ok=True)
    path = make_file(folder) if make_file else registry / "m.npz"
    assert main(["play-match", str(path), "--server", server or arena_server.url("grpc")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and err.startswith("camdirector play-match: ") and message in err, err


@pytest.mark.parametrize(
    "args, message",
    [
        (("--speed", "0"), "--speed and --rate-hz must be positive"),
        (("--delay-s", "400"), "--delay-s must be in [0, 300] s"),
        (("--rate-hz", "60"), "--rate-hz 60 is above the file's 30 Hz"),
    ],
)
def test_bad_arguments_exit_2(registry, args, message, capsys):
    assert main(["play-match", str(registry / "m.npz"), "--server", "grpc://127.0.0.1:1", *args]) == 2
    assert message in capsys.readouterr().err


def test_a_demo_is_refused_in_one_line_naming_it_and_what_was_expected(tmp_path, capsys):
    """A demo is no match file: say so and how to make one, not numpy's advice to load it unsafely."""
    demo = tmp_path / "duel.mvd.gz"
    demo.write_bytes((ROOT / "tests" / "data" / "real_matches" / "1on1_milton_vs_mushi_tron_20240616-1719.mvd.gz").read_bytes())
    assert main(["play-match", str(demo), "--server", "grpc://127.0.0.1:1"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert err.startswith(f"camdirector play-match: {demo}: not a match file") and "import-match" in err, err
    assert "pickle" not in err


def test_a_match_file_of_views_is_played_with_upright_bodies(tmp_path):
    """A file imported before bodies stood holds the views as the bodies: the server's targets stand."""
    save_views(tmp_path / "old.npz")
    match = load_match(tmp_path / "old.npz")
    targets = match_session_fields(match, "planned", 2.0, 0)["targets"]
    for target in targets:
        rotation = target.transform.rotation
        up = quat_rotate([rotation.x, rotation.y, rotation.z, rotation.w], [0.0, 1.0, 0.0])
        np.testing.assert_allclose(up, [0.0, 1.0, 0.0], rtol=0.0, atol=1e-9)
    assert len(targets) == 2
