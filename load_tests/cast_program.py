"""A live cast's program against the broadcast program's bars (issue 42: the program measured on
the same match meets the program bars of issue 41).

    python -m load_tests.cast_program [--json FILE] [--end-s 200] [--casts 1] [--no-baselines]

The match: the 2on2 frobodm2 development demo (tests/data/real_matches), served by the QTV source
stand-in (tests/bridges/qtv_source.py: why a stand-in is there) at its recorded pace up to
`end_s` of demo time. Each cast runs `camdirector cast qtv URL --level frobodm2 --delay-s 10
--program-out P` into its own `camdirector serve --workers 1`, in real time (a cast of 200 s takes
about 4 minutes), and the program it received is measured with `camdirector eval-match MATCH
--program P` on the match imported from the same demo at 30 Hz. The phase at which a cast samples
the stream against the demo's frames is not chosen, so two casts of the same code give two
programs: `--casts N` runs N and reports each.

The bars (issue 41's "Done when", those a cast's program can be measured on), each with its value,
its limit and whether it is met, per cast:
- frames of nobody outside overviews <= 0.02; no frame with a player over 0.6 of its height (first
  person aside); median shown height >= 0.15; program visibility >= 0.85;
- median shot 3-8 s, none under 2 s (on the match's clock and on air), none over 20 s while a kill
  happens outside it;
- replays: at least half of the kills that leave room for one, no live kill missed for one;
- no program pose outside the level, in solid, or sweeping through a wall;
- compute p99 <= 5 ms (the server's per frame, as the cast's replies carry it: absolute, as the
  bar is). Beside it, not judged, each cast's floor from the same server right after its stream
  (`compute_floor`): the compute of the cheapest real frame it answers (the built-in demo scene's
  FRAMING_ONLY session, FLOOR_FRAMES frames unpaced, the replies' compute_ms as the cast's) and a
  health check's round trip, so that a cast on a slow day reads as one;
- kill coverage (first person counted) >= 0.85 of the greedy 2-s bound and >= the better baseline
  + 0.15: the bound and the baselines (HLTV, autotrack) measured by `eval-match` on the match's span
  that the first cast's program covers (its kills), unpaced, in the same run (`--no-baselines`
  leaves these two bars out).
Not measured: the candidates' bar (a cast's program file keeps no candidates).
Prints one JSON object: per cast its figures and bars, and whether every bar held in every cast.
"""

from __future__ import annotations

import argparse
import gzip
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import camdirector_client as cd
from camdirector.bridges.program_record import program_on_match, read_program
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.server_process import ServerProcess
from camdirector.evaluation.match.evaluate import evaluate_match
from camdirector.evaluation.match.match_file import load_match, save_match
from camdirector.geometry.camera import Lens
from camdirector.matches.quakeworld_mvd import import_mvd
from camdirector.v1 import director_pb2 as pb
from load_tests.failover import _health_floor_ms
from load_tests.qtv_bridge import DEMO, RATE_HZ, map_data_dir
from load_tests.report import emit
from tests.bridges.qtv_source import QtvSource

DELAY_S = 10.0  # the broadcast delay of issue 41's bars, s
TAIL_S = 12.0  # after the stream's end: the delay's last program moments come back, s
BASELINES = ("hltv", "autotrack")
FLOOR_FRAMES = 300  # the floor session's frames measured, streamed unpaced, 60 Hz of scene time (5 s)
FLOOR_WARMUP = 30  # its frames before those, not measured: a session's start (its scene, its first solves) is no floor
ROOT = Path(__file__).resolve().parents[1]


def compute_floor(server_grpc: str, frames: int = FLOOR_FRAMES) -> dict:
    """The server at host:port `server_grpc`'s floor (module docstring): the compute_ms of the
    built-in demo scene's FRAMING_ONLY frames, `frames` after FLOOR_WARMUP, median and p99, and a
    health check's round trip median, ms."""
    scene = build_demo_scene(seed=7, duration_s=(frames + FLOOR_WARMUP) / 60.0 + 1.0)
    request = session_request(scene, Lens(), pb.FRAMING_ONLY)
    updates = list(frame_updates(scene, frames + FLOOR_WARMUP, 60.0))
    with cd.connect(f"grpc://{server_grpc}") as client, client.create_session(request) as session:
        answers = list(session.stream(updates))
    compute_ms = np.array([a.compute_ms for a in answers[FLOOR_WARMUP:]])
    return {
        "frames": len(compute_ms),
        "compute_ms": {"median": round(float(np.median(compute_ms)), 3), "p99": round(float(np.percentile(compute_ms, 99)), 3)},
        "health_rtt_ms_median": round(_health_floor_ms(server_grpc, None), 3),
    }


def cast(demo: bytes, end_s: float, data_dir: Path, program: Path, log: Path) -> tuple[dict, dict]:
    """One cast of the demo to end_s into a fresh server: its summary line (`cast`'s last stdout
    line) and the server's floor measured after it (`compute_floor`)."""
    source = QtvSource(demo, end_s=end_s)
    with ServerProcess("--workers", "1", "--data-dir", str(data_dir), transports=("grpc",)) as server:
        server_url = server.url("grpc")
        assert server_url is not None  # a gRPC server was asked for
        with open(log.with_suffix(".out"), "w") as stdout, open(log, "w") as stderr:
            proc = subprocess.Popen(
                [sys.executable, "-m", "camdirector", "cast", "qtv", source.url, "--level", "frobodm2"]
                + ["--server", server_url, "--delay-s", f"{DELAY_S:g}", "--program-out", str(program)],
                stdout=stdout,
                stderr=stderr,
                text=True,
                cwd=ROOT,
            )
            try:
                with source:
                    deadline = time.monotonic() + end_s + 120.0
                    while "closed the stream" not in log.read_text():
                        if proc.poll() is not None or time.monotonic() > deadline:
                            raise RuntimeError(f"the cast ended before the stream did: {log.read_text()[-2000:]}")
                        time.sleep(0.5)
                    time.sleep(TAIL_S)
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=60)
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
        if proc.returncode != 0:
            raise RuntimeError(f"cast exited {proc.returncode}: {log.read_text()[-2000:]}")
        assert server.grpc is not None
        floor = compute_floor(server.grpc)
    return json.loads(log.with_suffix(".out").read_text().splitlines()[-1])["summary"], floor


def measure(match_file: Path, program: Path, data_dir: Path, out: Path) -> dict:
    """`eval-match MATCH --program P`'s result."""
    done = subprocess.run(
        [sys.executable, "-m", "camdirector", "eval-match", str(match_file), "--program", str(program)]
        + ["--json", str(out), "--data-dir", str(data_dir)],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    if done.returncode != 0:
        raise RuntimeError(f"eval-match exited {done.returncode}: {done.stderr[-2000:]}")
    return json.loads(out.read_text())


def baselines(match_file: Path, program: Path, data_dir: Path) -> dict:
    """The ceilings and the baselines' first-person kill coverage on the match up to the program's
    last moment, its kills those from its first (program_on_match's cut)."""
    placed = program_on_match(read_program(program), load_match(match_file))
    result, _ = evaluate_match(placed.match, DELAY_S, directors=BASELINES, data_dir=data_dir, rate_hz=RATE_HZ)
    return against_of(result)


def against_of(result: dict) -> dict:
    """The kill coverage bars' references in an eval-match result that ran the BASELINES: its kills,
    the greedy 2-s bound and the baselines' first-person kill coverage."""
    return {
        "kills": result["match"]["kills"],
        "greedy_2s_kill_coverage": result["ceilings"]["greedy_2s_kill_coverage"],
        "first_person": {name: result["directors"][name]["kill_coverage_first_person"] for name in BASELINES},
    }


def bars(result: dict, against: dict | None, director: str = "planned") -> list[dict]:
    """Issue 41's program bars on one cast's eval-match result (module docstring), or on a match's
    through eval-match (no `program` in it: its director's, whose shots are on the match's clock
    alone): each {"bar", "value", "limit", "met"}."""
    program = result.get("program")
    f = result["directors"][director if program is None else program["director"]]
    nobody, height, visibility = f["nobody_shown"]["other"], f["shown_height"], f["program_visibility"]
    median_s, under = f["shots"]["median"], [f["shots"]["under_2s"]]
    if program is not None:
        under.append(program["shots_on_air"]["under_2s"])
    under_name = "shots under 2 s (match clock, on air)" if program is not None else "shots under 2 s"
    long_missing, p99_ms = f["long_shots_missing_kills"], f["compute_ms"]["p99"]
    replays, places = f["replays"], f["places"]["program"]
    replayed, room = replays["kills_with_room_replayed"], replays["kills_with_room"]
    missed = replays["live_kills_missed_for_replay"]
    wrong_places = [places["outside"], places["solid"], places["swept_through_walls"]]
    rows = [
        ("frames of nobody outside overviews", nobody, "<= 0.02", nobody <= 0.02),
        ("frames with a player over 0.6 of the height", height["over_60pc"], "== 0", height["over_60pc"] == 0),
        ("median shown height", height["median"], ">= 0.15", height["median"] >= 0.15),
        ("program visibility", visibility, ">= 0.85", visibility >= 0.85),
        ("median shot, s", median_s, "3-8", 3.0 <= median_s <= 8.0),
        (under_name, under, ", ".join("0" * len(under)), not any(under)),
        ("shots over 20 s while a kill happens outside", long_missing, "0", long_missing == 0),
        ("kills with room replayed", [replayed, room], ">= half", 2 * replayed >= room),
        ("live kills missed for a replay", missed, "0", missed == 0),
        ("program poses outside, in solid, swept through walls", wrong_places, "0, 0, 0", wrong_places == [0, 0, 0]),
        ("compute p99, ms", p99_ms, "<= 5", p99_ms <= 5.0),
    ]
    if against is not None:
        cover = f["kill_coverage_first_person"]
        bound, better = against["greedy_2s_kill_coverage"], max(against["first_person"].values())
        over = "kill coverage (first person) over the"
        rows.append((f"{over} greedy 2-s bound", cover, f">= 0.85 * {bound}", cover >= 0.85 * bound))
        rows.append((f"{over} better baseline", cover, f">= {better} + 0.15", cover >= better + 0.15))
    return [{"bar": name, "value": value, "limit": limit, "met": bool(met)} for name, value, limit, met in rows]


def run(end_s: float, casts: int, with_baselines: bool, folder: Path) -> dict:
    demo = gzip.decompress(DEMO.read_bytes())
    data_dir = map_data_dir(folder)
    match_file = folder / "match.npz"
    save_match(import_mvd(demo, level="frobodm2", rate_hz=RATE_HZ), match_file)
    runs, against = [], None
    for k in range(casts):
        program = folder / f"program{k}.jsonl"
        summary, floor = cast(demo, end_s, data_dir, program, folder / f"cast{k}.err")
        result = measure(match_file, program, data_dir, folder / f"eval{k}.json")
        if with_baselines and against is None:
            against = baselines(match_file, program, data_dir)
        runs.append({"cast": summary, "eval_match": result, "floor": floor})
    per_cast = []
    for r in runs:
        checked = bars(r["eval_match"], against)
        per_cast.append(
            {
                "frames_sent": r["cast"]["frames"],
                "kills": r["cast"]["kills"],
                "program": r["eval_match"]["program"],
                "figures": r["eval_match"]["directors"][r["eval_match"]["program"]["director"]],
                "bars": checked,
                "bars_met": all(b["met"] for b in checked),
                "floor": r["floor"],
            }
        )
    return {
        "demo": DEMO.name,
        "end_s": end_s,
        "delay_s": DELAY_S,
        "rate_hz": RATE_HZ,
        "baselines": against,
        "casts": per_cast,
        "every_bar_in_every_cast": all(c["bars_met"] for c in per_cast),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--end-s", type=float, default=200.0, help="the demo time the source serves to, s (default 200)")
    parser.add_argument("--casts", type=int, default=1, help="casts of the same code, each measured (default 1)")
    parser.add_argument("--no-baselines", dest="baselines", action="store_false", help="leave out the kill coverage bars")
    parser.add_argument("--keep", type=Path, help="keep the programs, logs and eval-match results in this folder")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    if args.casts < 1 or not args.end_s > 0:
        parser.error("--casts must be at least 1 and --end-s positive")
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        emit(run(args.end_s, args.casts, args.baselines, args.keep), args.json)
    else:
        with tempfile.TemporaryDirectory() as folder:
            emit(run(args.end_s, args.casts, args.baselines, Path(folder)), args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
