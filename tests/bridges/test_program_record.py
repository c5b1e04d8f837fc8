"""bridges/program_record.py and `eval-match --program`: the program a cast received, measured with
eval-match's measures on the match file of the same demo (issue 42: the program measured
afterwards on the recorded demo of the same match). End to end: the QTV source stand-in serves the
frobodm2 demo's first 28 s (tests/bridges/qtv_source.py), `cast qtv --program-out` writes the
program a real server sent back, `eval-match MATCH --program` measures it on the match imported
from the same demo; and how a recorded program is placed on a match."""

from __future__ import annotations

import gzip
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import camdirector_client as cd
from camdirector.bridges.program_record import ProgramRecorder, RecordedProgram, program_on_match, read_program
from camdirector.deploy.server_process import ServerProcess
from camdirector.evaluation.match.match_file import save_match
from camdirector.evaluation.match.measure import shot_lengths_s
from camdirector.matches.import_cli import add_map
from camdirector.matches.quakeworld_mvd import import_mvd
from tests.bridges.qtv_source import QtvSource
from tests.bridges.test_qtv import DATA, ROOT, SLICE_END_S, SPEED, demo

__all__ = ["demo"]  # the fixture this module uses from test_qtv

FRAGS = 4  # the slice's frags, every one a kill of another player (test_qtv)


@pytest.fixture(scope="module")
def registry(tmp_path_factory):
    """A registry folder holding frobodm2, as `cast qtv --map` adds it."""
    folder = tmp_path_factory.mktemp("program")
    bsp = folder / "frobodm2.bsp"
    bsp.write_bytes(gzip.decompress((DATA / "real_maps" / "frobodm2.bsp.gz").read_bytes()))
    add_map(bsp, "frobodm2", folder / "data")
    return folder / "data"


@pytest.fixture(scope="module")
def match(demo):
    return import_mvd(demo, level="frobodm2", rate_hz=30.0)


STREAM_BEGAN_S = 7.0  # the match's time when the cast joined: the stream's clock begins there


def _moment(match, frame: int, row: float, cut: bool = False, subjects=("p00",)) -> dict:
    """A program moment showing the match at `row` (a fraction: between rows), its source time on
    the stream's clock, its players' feet the match's there."""
    feet = match.positions_world[int(round(row))]
    return {
        "frame": frame,
        "time_s": frame / 30.0,
        "source_time_s": float(match.time_s[0] + row / match.rate_hz - STREAM_BEGAN_S),
        "players": {p.id: feet[k].tolist() for k, p in enumerate(match.players)},
        "position": [0.0, 1.0, float(frame)],
        "rotation": [0.0, 0.0, 0.0, 1.0],
        "vertical_fov_deg": 50.0,
        "cut": cut,
        "shot_id": frame,
        "kind": "FOLLOW",
        "subjects": list(subjects),
        "compute_ms": 1.0,
    }


def test_a_recorded_program_is_aligned_on_the_match_by_its_players_and_lands_on_its_rows(match):
    first_kill_s = min(e.time_s for e in match.events if e.kind == "kill")
    row = int(np.rint((first_kill_s - match.time_s[0]) * match.rate_hz))
    moments = [
        {**_moment(match, 1, row - 40), "source_time_s": None},  # no clock: left out
        *[_moment(match, 2 + k, row - 30 + k) for k in range(20)],  # frames 2..21: rows row-30..row-11
        _moment(match, 22, row + 0.2, cut=True),
        _moment(match, 23, row + 0.3),  # the same row: this one stays, cutting
        _moment(match, 24, row - 5),  # older than the one before: dropped
        _moment(match, 25, row + 2),
    ]
    placed = program_on_match(RecordedProgram({"program_of": "qtv://x:1"}, moments, None), match)
    assert placed.shift_s == pytest.approx(STREAM_BEGAN_S, abs=0.5 / match.rate_hz) and placed.align_m < 0.01
    assert placed.program.index.tolist() == [*range(row - 30, row - 10), row, row + 2]
    assert placed.program.cut.tolist()[-2:] == [True, False]
    assert placed.program.position[-2:, 2].tolist() == [23.0, 25.0]
    assert placed.program.time_s.tolist() == match.time_s[placed.program.index].tolist()  # the match's clock
    assert placed.left_out == 1
    # the match cut to the program's span: no kill before its first moment, none after its last
    assert [e.time_s for e in placed.match.events if e.kind == "kill"] == [first_kill_s]

    # the same moments with other players' feet: not this match
    elsewhere = [{**m, "players": {pid: [x + 5.0, y, z] for pid, (x, y, z) in m["players"].items()}} for m in moments[1:]]
    with pytest.raises(ValueError, match="not of this match"):
        program_on_match(RecordedProgram({}, elsewhere, None), match)
    with pytest.raises(ValueError, match="players the match does not have: p09"):
        program_on_match(RecordedProgram({}, [_moment(match, 1, 0, subjects=("p09",))], None), match)


def test_a_program_over_reconnects_is_placed_piece_by_piece(match):
    # three connections: the second's stream clock starts anew (a reconnect: its demo time begins
    # again), the third's feet are another match's; each piece is aligned on its own
    row = int(np.rint((min(e.time_s for e in match.events if e.kind == "kill") - match.time_s[0]) * match.rate_hz))
    first = [_moment(match, 1 + k, row - 60 + k) for k in range(40)]
    again = [
        {**_moment(match, 41 + k, row + 30 + k), "source_time_s": 0.4 + k / match.rate_hz} for k in range(40)
    ]  # 30 rows later on the match, 2 s of drop and reconnect later on the session's clock
    for m in again:
        m["time_s"] += 2.0
    other = [
        {**m, "frame": m["frame"] + 40, "time_s": m["time_s"] + 3.0, "source_time_s": 9.0 + k / match.rate_hz}
        for k, m in enumerate(again)
    ]
    for m in other:
        m["players"] = {pid: [x + 5.0, y, z] for pid, (x, y, z) in m["players"].items()}
    placed = program_on_match(RecordedProgram({"program_of": "qtv://x:1"}, first + again + other, None), match)
    assert placed.pieces == (2, 3) and placed.left_out == len(other)
    assert placed.program.index.tolist() == [*range(row - 60, row - 20), *range(row + 30, row + 70)]
    assert placed.shift_s == pytest.approx(STREAM_BEGAN_S, abs=0.5 / match.rate_hz) and placed.align_m < 0.01


def test_a_program_whose_clock_runs_half_a_row_off_the_files_lands_on_the_rows_its_players_were_at(match):
    """A stream clock half a row off the file's grid: every source time at k + 0.5 rows, where
    rounding goes either way (to the even row), each moment carrying the feet of the row after.
    Each lands on the row its players' feet are: no two on one row, none a row off."""
    row = int(np.rint((min(e.time_s for e in match.events if e.kind == "kill") - match.time_s[0]) * match.rate_hz))
    moments = []
    for k in range(60):
        moment = _moment(match, 1 + k, row - 40 + k + 1)  # the feet of the row after
        moment["source_time_s"] = round(float(match.time_s[0] + (row - 40 + k + 0.5) / match.rate_hz - STREAM_BEGAN_S), 4)
        moments.append(moment)
    placed = program_on_match(RecordedProgram({"program_of": "qtv://x:1"}, moments, None), match)
    assert placed.program.index.tolist() == list(range(row - 39, row + 21))
    assert placed.program.position[:, 2].tolist() == [float(1 + k) for k in range(60)]  # every moment kept


def test_each_live_moment_carries_the_feet_its_director_saw_and_a_replays_none(match):
    """Program.feet_world: a live moment's feet as it carried them, in the match's columns (a player
    it lacks NaN); a REPLAY's moment NaN throughout (its picture is of another moment)."""
    row = int(np.rint((min(e.time_s for e in match.events if e.kind == "kill") - match.time_s[0]) * match.rate_hz))
    moments = [_moment(match, 1 + k, row - 40 + k) for k in range(40)]
    moments[5]["players"]["p01"] = [1.0, 2.0, 3.0]  # p01 a teleport ahead of the match's row
    del moments[6]["players"]["p02"]
    moments[7] = {**moments[7], "kind": "REPLAY", "replay_time_s": moments[7]["time_s"] - 1.0}
    feet = program_on_match(RecordedProgram({"program_of": "qtv://x:1"}, moments, None), match).program.feet_world
    column = match.player_index()
    assert feet.shape == (40, len(column), 3)
    np.testing.assert_array_equal(feet[0], match.positions_world[row - 40])
    assert feet[5, column["p01"]].tolist() == [1.0, 2.0, 3.0]
    assert np.isnan(feet[6, column["p02"]]).all() and np.isfinite(feet[6, column["p00"]]).all()
    assert np.isnan(feet[7]).all()


def test_each_moment_keeps_its_replys_flags_and_a_file_written_before_them_gives_none(match, tmp_path):
    """The recorder writes each reply's Diagnostics.flags; placed on the match, each kept moment's
    (of two on one row, the later's: the one kept, as eval-match keeps one row's replies); a file
    written before flags were kept gives none (eval-match's lists then name times and subjects
    alone)."""
    path = tmp_path / "program.jsonl"
    recorder = ProgramRecorder(path)
    recorder.begin({"program_of": "qtv://x:1"})
    update = cd.pb.CameraUpdate(frame=1, time_s=0.5, cut=True, shot_id=3)
    update.pose.rotation.w, update.pose.vertical_fov_deg = 1.0, 50.0
    update.diagnostics.flags.extend(["held_before_wall", "cut_through_wall"])
    recorder.reply(update)
    recorder.close()
    assert read_program(path).moments[0]["flags"] == ["held_before_wall", "cut_through_wall"]

    row = int(np.rint((min(e.time_s for e in match.events if e.kind == "kill") - match.time_s[0]) * match.rate_hz))
    rows = [0, 1, 2, 3, 4, 5, 5, 6, 7, 8]  # the fifth and sixth moments on one row
    moments = [{**_moment(match, 1 + k, row + r), "flags": [f"f{k}"]} for k, r in enumerate(rows)]
    placed = program_on_match(RecordedProgram({"program_of": "qtv://x:1"}, moments, None), match)
    assert placed.flags == [(f"f{k}",) for k in (0, 1, 2, 3, 4, 6, 7, 8, 9)]
    older = [{key: v for key, v in m.items() if key != "flags"} for m in moments]
    assert program_on_match(RecordedProgram({"program_of": "qtv://x:1"}, older, None), match).flags == []


def test_the_shots_on_air_are_timed_by_the_sessions_clock(match):
    """The stream clock holds the demo's first sample over the cast's first 4 frames, then plays
    the match at its pace: the first shot is 60 frames on air (2.0 s), 57 rows of the match
    (1.9 s); the last shot, cut short by the program's end, is not counted."""
    row = int(np.rint((min(e.time_s for e in match.events if e.kind == "kill") - match.time_s[0]) * match.rate_hz))
    moments = [_moment(match, 1 + k, row + max(0, k - 3), cut=k in (60, 150)) for k in range(170)]
    placed = program_on_match(RecordedProgram({"program_of": "qtv://x:1"}, moments, None), match)
    assert placed.on_air_lengths_s.tolist() == pytest.approx([2.0, 3.0])
    assert shot_lengths_s(placed.program).tolist() == pytest.approx([57 / match.rate_hz, 3.0])


def test_a_file_that_is_no_program_is_refused(tmp_path):
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"frame": 1}\n')
    with pytest.raises(ValueError, match="not a program file"):
        read_program(bad)
    bad.write_text('{"program_of": "qtv://x:1"}\n{"end": {"frames": 3, "buffering": 3}}\n')
    with pytest.raises(ValueError, match="no moment"):
        read_program(bad)


def _program_held(path, moments: int = 15) -> bool:
    """Whether the last `moments` whole lines of a program file being written show one moment of
    the stream (the players held once it ended)."""
    lines = path.read_text().split("\n")[1:-1] if path.exists() else []  # whole lines past the header
    times = {json.loads(line).get("source_time_s") for line in lines[-moments:]}
    return len(lines) > moments and len(times) == 1


def _camdirector(*args: str, timeout_s: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "camdirector", *args], capture_output=True, text=True, cwd=ROOT, timeout=timeout_s, env=os.environ
    )


@pytest.mark.parametrize("drop_after_s", [None, 1.5])  # 1.5 s: 6 s into the match, before its first frag
def test_the_cast_program_is_measured_on_the_match_of_the_same_demo(registry, demo, match, tmp_path, drop_after_s):
    program_file, out, err = tmp_path / "program.jsonl", tmp_path / "cast.jsonl", tmp_path / "cast.err"
    # listening; its match starts when entered
    source = QtvSource(demo, end_s=SLICE_END_S, speed=SPEED, drop_after_s=drop_after_s)
    closes = 1 if drop_after_s is None else 2  # the drop mid-block, then the slice's end
    with (
        ServerProcess("--workers", "1", "--data-dir", str(registry), transports=("grpc",)) as server,
        open(out, "w") as stdout,
        open(err, "w") as stderr,
    ):
        proc = subprocess.Popen(
            [sys.executable, "-m", "camdirector", "cast", "qtv", source.url, "--level", "frobodm2"]
            + ["--server", server.url("grpc"), "--delay-s", "1", "--program-out", str(program_file)],
            stdout=stdout,
            stderr=stderr,
            text=True,
            cwd=ROOT,
        )
        try:
            with source:  # the cast waits in the backlog: it sees the match from its start
                # the slice played out (the source closed the stream at its end) and the program
                # reached the players held at the last sample
                deadline = time.monotonic() + 60.0
                while err.read_text().count("closed the stream") < closes or not _program_held(program_file):
                    assert proc.poll() is None and time.monotonic() < deadline, err.read_text()
                    time.sleep(0.2)
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
            assert proc.returncode == 0, err.read_text()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    summary = json.loads(out.read_text().splitlines()[-1])["summary"]
    assert summary["program_out"] == str(program_file) and summary["kills"] == FRAGS

    recorded = read_program(program_file)
    assert recorded.header["program_of"] == source.url and recorded.header["delay_s"] == 1.0
    assert [p["name"] for p in recorded.header["roster"]] == [p.name for p in match.players]
    assert recorded.end is not None and len(recorded.moments) == summary["program_frames"]
    assert recorded.end["frames"] == summary["frames"]

    match_file = tmp_path / "match.npz"
    save_match(match, match_file)
    wrong = _camdirector(
        "eval-match", str(match_file), "--program", str(program_file), "--json", str(tmp_path / "x.json"), "--delay", "10"
    )
    assert wrong.returncode == 2 and "the program was cast with a 1 s delay" in wrong.stderr, wrong.stderr

    no_delay = _camdirector("eval-match", str(match_file), "--json", str(tmp_path / "x.json"))
    assert no_delay.returncode == 2 and "--delay is required (unless --program)" in no_delay.stderr, no_delay.stderr

    result_file = tmp_path / "measured.json"
    done = _camdirector(
        "eval-match", str(match_file), "--program", str(program_file), "--json", str(result_file), "--data-dir", str(registry)
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(result_file.read_text())
    figures = result["directors"]["planned"]
    assert result["program"]["moments_left_out"] == 0 and result["program"]["ended"]
    assert result["program"]["align_m"] < 0.5  # the stream's clock found on the match by the players' feet
    # each connection's stream starts its demo time anew: one piece each, every one placed
    pieces = result["program"]["pieces"]
    assert pieces["placed"] == pieces["of"] and pieces["of"] >= closes, pieces
    # every frag of the slice is a kill the program reached, and each is counted
    assert result["match"]["kills"] == FRAGS and figures["kills"] == FRAGS
    assert figures["kills_covered"] == round(figures["kill_coverage"] * FRAGS)
    for name in ("kill_coverage", "kill_coverage_first_person", "framed_visibility", "program_visibility"):
        assert 0.0 <= figures[name] <= 1.0, (name, figures[name])
    # the replies' flags (why the camera is where it is) kept, and what eval-match's lists name of them
    kept = {flag for m in recorded.moments for flag in m["flags"]}
    named = {flag for run in figures["nobody_runs"] for flag in run["flags"]}
    named |= {flag for short in figures["short_shots"] for flag in short["flags_at_cut"] + short["flags_at_end"]}
    assert kept and named <= kept, (kept, named)
    assert figures["program_moments"] > 100 and figures["compute_ms"]["n"] == figures["program_moments"]
    assert figures["candidates_showing_half"]["offered"] == 0  # candidates are not recorded
    # the shots on air, timed by the session's clock: one a cut, at least a frame each, and together
    # the session's time from the program's first moment to its last cut (the stand-in's SPEED and the stream clock's
    # catch-ups part them from the match's clock, so no ratio holds between the two)
    on_air = result["program"]["shots_on_air"]
    cuts_s = [m["time_s"] for m in recorded.moments[1:] if m["cut"]]
    assert on_air["count"] == len(cuts_s) and min(on_air["values"]) >= 1.0 / 30.0 - 0.01
    assert sum(on_air["values"]) == pytest.approx(cuts_s[-1] - recorded.moments[0]["time_s"], abs=0.01 * len(cuts_s))
    assert on_air["under_2s"] == sum(v < 2.0 - 1e-6 for v in on_air["values"])
