"""The broadcast program's bars at every phase a live feed may sample the game at, offline and
deterministic (issue 42: a cast's program meets the program bars of issue 41).

    python -m load_tests.program_phases [--json FILE] [--phases 0,0.25,0.5,0.75] [--rates 30]
                                        [--end-s 200] [--baselines] [--keep DIR]

A cast samples the live stream at a phase against the demo's frames that nobody chooses, so two
casts of the same code give two programs (load_tests/cast_program.py runs real casts, in real time,
about 5 minutes each). Here the same 2on2 frobodm2 development demo is imported on grids shifted by
each of `--phases` of a row (matches/quakeworld_mvd.py `phase_rows`) at each of `--rates`, and each
match goes through `camdirector eval-match --director planned --delay 10` (the director in a real
server, unpaced) up to `end_s` of the match, about a minute each. The same code gives the same
programs, so a change to the director can be compared phase by phase, without the casts' spread.

Each program is judged by cast_program.py's bars (issue 41's, those a program can be measured on;
the shots on the match's clock alone, which is the program's here; not the compute bar: unpaced, a
frame carries the work a live session does in its idle moments). `--baselines` runs the HLTV
and autotrack baselines beside it for the two kill coverage bars (about twice as long). Not a
cast: the stream clock's slew and catch-ups, and a cast's late moments, are not in these programs.
Prints one JSON object: per run its figures and bars, and per bar the runs it failed in.
"""

from __future__ import annotations

import argparse
import gzip
import json
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from camdirector.evaluation.match.match_file import save_match
from camdirector.matches.quakeworld_mvd import import_mvd
from load_tests.cast_program import BASELINES, DELAY_S, ROOT, against_of, bars
from load_tests.qtv_bridge import DEMO, map_data_dir
from load_tests.report import emit

DIRECTOR = "planned"
# not judged here: unpaced, a frame carries the work a live session does in its idle moments (the edit window's repairs,
# the drawn plans), so its p99 is not a live session's (cast_program.py judges a cast's)
UNPACED_BAR = "compute p99, ms"


def judged(
    demo: bytes, rate_hz: float, phase_rows: float, end_s: float, with_baselines: bool, folder: Path, data_dir: Path
) -> dict:
    """One program: the demo at rate_hz on a grid phase_rows of a row late, through eval-match to end_s
    (the level from data_dir)."""
    tag = f"{rate_hz:g}hz_{phase_rows:g}"
    match_file = folder / f"match_{tag}.npz"
    save_match(import_mvd(demo, level="frobodm2", rate_hz=rate_hz, phase_rows=phase_rows), match_file)
    out = folder / f"eval_{tag}.json"
    directors = [DIRECTOR, *(BASELINES if with_baselines else ())]
    started = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "camdirector", "eval-match", str(match_file), "--delay", f"{DELAY_S:g}"]
        + [arg for name in directors for arg in ("--director", name)]
        + ["--rate-hz", f"{rate_hz:g}", "--minutes", f"{end_s / 60.0:.6f}", "--json", str(out)]
        + ["--data-dir", str(data_dir)],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    if done.returncode != 0:
        raise RuntimeError(f"eval-match exited {done.returncode}: {done.stderr[-2000:]}")
    result = json.loads(out.read_text())
    against = against_of(result) if with_baselines else None
    checked = [b for b in bars(result, against, DIRECTOR) if b["bar"] != UNPACED_BAR]
    return {
        "rate_hz": rate_hz,
        "phase_rows": phase_rows,
        "wall_s": round(time.monotonic() - started, 1),
        "baselines": against,
        "figures": result["directors"][DIRECTOR],
        "bars": checked,
        "bars_met": all(b["met"] for b in checked),
    }


def run(phases: list[float], rates: list[float], end_s: float, with_baselines: bool, folder: Path) -> dict:
    demo = gzip.decompress(DEMO.read_bytes())
    data_dir = map_data_dir(folder)
    runs = [judged(demo, rate, phase, end_s, with_baselines, folder, data_dir) for rate in rates for phase in phases]
    failed = Counter(b["bar"] for r in runs for b in r["bars"] if not b["met"])
    return {
        "demo": DEMO.name,
        "end_s": end_s,
        "delay_s": DELAY_S,
        "director": DIRECTOR,
        "runs": runs,
        "runs_meeting_every_bar": sum(r["bars_met"] for r in runs),
        "bars_failed": dict(failed),
    }


def _numbers(text: str) -> list[float]:
    return [float(x) for x in text.split(",") if x.strip()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--phases", type=_numbers, default=[0.0, 0.25, 0.5, 0.75], help="shares of a row, in [0, 1)")
    parser.add_argument("--rates", type=_numbers, default=[30.0], help="frames per second the match is imported at and sent")
    parser.add_argument("--end-s", type=float, default=200.0, help="the match time measured to, s (default 200)")
    parser.add_argument(
        "--baselines", action="store_true", help="run the HLTV and autotrack baselines for the kill coverage bars"
    )
    parser.add_argument("--keep", type=Path, help="keep the match files and eval-match results in this folder")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    if not args.phases or not all(0.0 <= p < 1.0 for p in args.phases):
        parser.error("--phases: shares of a row in [0, 1)")
    if not args.rates or not all(r > 0 for r in args.rates) or not args.end_s > 0:
        parser.error("--rates and --end-s must be positive")
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        emit(run(args.phases, args.rates, args.end_s, args.baselines, args.keep), args.json)
    else:
        with tempfile.TemporaryDirectory() as folder:
            emit(run(args.phases, args.rates, args.end_s, args.baselines, Path(folder)), args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
