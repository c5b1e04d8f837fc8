"""`camdirector eval-match`: a match file through a real server, our director against the baselines.

    camdirector eval-match FILE --delay D --json OUT [--director NAME]... [--plugin MODULE]...
                           [--plot P.png] [--video V.mp4] [--video-seconds 20]
                           [--data-dir DIR] [--rate-hz 30] [--minutes M] [--seed 0]
        starts a server on the registry DIR (default: the per-user one) that holds the match's
        level, with the plugins (camdirector serve --plugin), streams the match (its first M
        minutes with --minutes) through a RIG_MATCH session of each director named (default:
        every registered one, pipeline/match/director_registry.py, the plugins' too) with the
        broadcast delay D s, and a one-actor RIG_TRACKS session as the cost reference
        (evaluation/match/evaluate.py); measures kill coverage, lead, shots, jump cuts,
        visibility and the program's and candidates' poses outside the level or inside solid
        from the returned cameras (measure.py); prints the result as JSON and writes
        it to OUT. --plot draws coverage, lead and shot lengths; --video renders our director's
        program (the first director's without ours) for its first S seconds (EGL; skipped with a
        message when unavailable).
        Exit status: 0 ok, 1 the run failed, 2 bad arguments, match file, level, director or plugin.
    camdirector eval-match FILE --program P.jsonl --json OUT [--delay D] [--plot P.png]
                           [--video V.mp4] [--video-seconds 20] [--data-dir DIR] [--seed 0]
        measures a program recorded elsewhere (`camdirector cast qtv --program-out P.jsonl`: the
        program a live cast received) against the match file imported from the same demo, with
        no server: each moment on the match row of the demo time it shows, the match cut to the
        program's span (bridges/program_record.py), then the same figures as above
        (evaluate.py's measure_program; the candidates are not recorded, so theirs are empty),
        and the shots as they went on air, on the session's clock (program.shots_on_air).
        The delay is the recorded one; --delay, if given, must be it. Exit status: 0 ok, 2 bad
        arguments, match file, program file or level.

Kept light at import, as evaluation/cli.py: numpy, the client and the server load when it runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def add_parser(subparsers) -> None:
    """Registers `eval-match` on an argparse subparsers object; args.handler(args) runs it."""
    p = subparsers.add_parser(
        "eval-match",
        help="stream a match file through our match director and the baselines, and measure them",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        add_help=False,
    )
    p.add_argument("-h", "--help", action=_HelpWithDirectors, help="show this help message, with the directors, and exit")
    p.add_argument("file", type=Path, help="match file (camdirector match-sim --out)")
    p.add_argument("--delay", type=float, help="broadcast delay, s, 0 to 300 (required without --program)")
    p.add_argument(
        "--program", type=Path, metavar="P.jsonl", help="measure this recorded program (cast qtv --program-out) instead"
    )
    p.add_argument("--json", type=Path, required=True, help="write the result here")
    p.add_argument(
        "--director",
        dest="directors",
        action="append",
        metavar="NAME",
        help="a registered match director to run (repeatable; default: every registered one, listed below)",
    )
    p.add_argument(
        "--plugin",
        dest="plugins",
        action="append",
        default=[],
        metavar="MODULE",
        help="a Python module to import here and in the server first (a director that registers itself; repeatable)",
    )
    p.add_argument("--plot", type=Path, help="draw coverage, lead and shot lengths here (PNG)")
    p.add_argument("--video", type=Path, help="render our director's program here (MP4, 480x270)")
    p.add_argument(
        "--video-seconds", dest="video_seconds", type=float, default=20.0, help="seconds of program in the video (default 20)"
    )
    p.add_argument(
        "--data-dir", dest="data_dir", type=Path, help="registry holding the match's level (default: per-user data dir)"
    )
    p.add_argument(
        "--rate-hz",
        dest="rate_hz",
        type=float,
        default=30.0,
        help="frames per second sent, a divisor of the file's rate (default 30)",
    )
    p.add_argument("--minutes", type=float, help="only the match's first minutes (default: all of it)")
    p.add_argument("--seed", type=int, default=0, help="seed of the sessions and the body sample points (default 0)")
    p.add_argument(
        "--paced",
        action="store_true",
        help="send the frames in real time at --rate-hz, as a game would (default: as fast as the server answers; "
        "the program is the same, the compute times are a live session's)",
    )
    p.set_defaults(handler=run_eval_match)


class _HelpWithDirectors(argparse.Action):
    """-h/--help, ending with every registered match director (name: label), the plugins' that are
    imported too: read from the registry when help is asked, since importing it imports every
    director, which this module leaves until the command runs (module docstring)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from camdirector.pipeline.match.director_registry import registered

        lines = [f"  {entry.name}: {entry.label}" for entry in registered()]
        parser.epilog = "\n".join(["registered match directors (--director NAME; default: all of them):", *lines])
        parser.print_help()
        parser.exit()


def _progress(text: str) -> None:
    print(f"eval-match: {text}", file=sys.stderr, flush=True)


def run_eval_match(args: argparse.Namespace) -> int:
    """Runs `camdirector eval-match` from parsed arguments; returns the exit status."""
    from camdirector.evaluation.match.evaluate import evaluate_match
    from camdirector.evaluation.match.match_file import load_match
    from camdirector_client import DirectorError

    if args.program is not None:
        return _run_recorded(args)
    try:
        if args.delay is None:
            raise ValueError("--delay is required (unless --program)")
        if not 0.0 <= args.delay <= 300.0:
            raise ValueError("--delay must be in [0, 300] s")
        if not args.rate_hz > 0 or not args.video_seconds > 0:
            raise ValueError("--rate-hz and --video-seconds must be positive")
        match = load_match(args.file)
        if args.minutes is not None:
            if not args.minutes > 0:
                raise ValueError("--minutes must be positive")
            match = match.until(match.time_s[0] + 60.0 * args.minutes)
        if args.rate_hz > match.rate_hz:
            raise ValueError(f"--rate-hz {args.rate_hz:g} is above the file's {match.rate_hz:g} Hz")
        result, runs = evaluate_match(
            match,
            args.delay,
            directors=args.directors,
            plugins=args.plugins,
            data_dir=args.data_dir,
            rate_hz=args.rate_hz,
            seed=args.seed,
            paced=args.paced,
            progress=_progress,
        )
    except KeyError as exc:
        print(f"camdirector eval-match: {exc.args[0]}", file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"camdirector eval-match: {exc}", file=sys.stderr)
        return 2
    except (RuntimeError, DirectorError) as exc:  # the server failed a session: the run has no result
        print(f"camdirector eval-match: {exc}", file=sys.stderr)
        return 1
    result["match"]["file"] = str(args.file)
    return _emit(args, match, result, runs)


def _run_recorded(args: argparse.Namespace) -> int:
    """eval-match FILE --program P (module docstring): the recorded program's figures."""
    import numpy as np

    from camdirector.bridges.program_record import program_on_match, read_program
    from camdirector.evaluation.match.evaluate import DirectorRun, measure_program, shot_figures
    from camdirector.evaluation.match.match_file import load_match
    from camdirector.evaluation.match.measure import Offered

    if args.directors or args.plugins or args.minutes is not None:
        print(
            "camdirector eval-match: --program measures the recorded program: no --director, --plugin or --minutes",
            file=sys.stderr,
        )
        return 2
    try:
        recorded = read_program(args.program)
        header = recorded.header
        if args.delay is not None and args.delay != header["delay_s"]:
            raise ValueError(f"--delay {args.delay:g}: the program was cast with a {header['delay_s']:g} s delay")
        if not args.video_seconds > 0:
            raise ValueError("--video-seconds must be positive")
        placed = program_on_match(recorded, load_match(args.file))
        match, program = placed.match, placed.program
        no_candidates = Offered(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0), [])
        run = DirectorRun(
            program,
            placed.compute_ms,
            no_candidates,
            buffering=0 if recorded.end is None else recorded.end["buffering"],
            wall_s=recorded.moments[-1]["time_s"] - recorded.moments[0]["time_s"],
            flags=placed.flags,
        )
        _progress(f"measuring the {len(program)} program moments of {args.program}")
        figures = measure_program(match, run, data_dir=args.data_dir, seed=args.seed)
    except KeyError as exc:
        print(f"camdirector eval-match: {exc.args[0]}", file=sys.stderr)
        return 2
    except (OSError, ValueError) as exc:
        print(f"camdirector eval-match: {exc}", file=sys.stderr)
        return 2
    director = header["director"]
    result = {
        "match": {
            "file": str(args.file),
            "level": match.level,
            "seed": match.seed,
            "players": len(match.players),
            "kills": sum(e.kind == "kill" for e in match.events),
            "minutes": round(float(program.time_s[-1] - program.time_s[0]) / 60.0, 2),
        },
        "delay_s": header["delay_s"],
        "rate_hz": header["rate_hz"],
        "program": {
            "file": str(args.program),
            "of": header["program_of"],
            "director": director,
            "moments_recorded": len(recorded.moments),
            "moments_left_out": placed.left_out,
            "shift_s": round(placed.shift_s, 3),
            "align_m": round(placed.align_m, 3),
            "pieces": {"placed": placed.pieces[0], "of": placed.pieces[1]},
            "ended": recorded.end is not None,
            "frames_sent": None if recorded.end is None else recorded.end["frames"],
            # the shots as they went on air, on the session's clock (the director's figures time them on the match's)
            "shots_on_air": shot_figures(placed.on_air_lengths_s),
        },
        "directors": {director: figures},
    }
    return _emit(args, match, result, {director: run})


def _emit(args: argparse.Namespace, match, result: dict, runs: dict) -> int:
    """The plot and the video where asked, then the result printed and written to --json."""
    from camdirector.evaluation.match.evaluate import plot_result
    from camdirector.evaluation.match.program_video import VideoUnavailable, render_program

    if args.plot:
        plot_result(result, args.plot)
    if args.video:
        try:
            _progress(f"rendering {args.video_seconds:g} s of program to {args.video}")
            shown = runs["planned"] if "planned" in runs else next(iter(runs.values()))
            result["video"] = render_program(match, shown.program, args.video, args.video_seconds, data_dir=args.data_dir)
        except VideoUnavailable as exc:
            _progress(f"no video: {exc}")
            result["video"] = {"skipped": str(exc)}
    text = json.dumps(result, indent=1)  # as load_tests/report.py's emit writes it
    print(text)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(text)
    return 0
